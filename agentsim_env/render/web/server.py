"""The viewer's web server: the page, its static files and one WebSocket, on a background thread.

With ``http_pages``, the only importer of ``websockets`` (the ``viewer`` extra). One asyncio loop on a daemon thread
serves:

* ``GET /``: the page the server was made for (``viewer.html``, or a page of another folder: the UAV zone
  designer's ``designer.html``);
* ``GET /static/NAME`` and ``/static/vendor/NAME``: the files of the server's static folder (the package's own
  by default), looked up by exact name in a table built at start-up; any other path (``..``, encoded slashes,
  absolute paths) is a 404, so nothing outside that folder can be read; other methods, request bodies and pipelined
  requests get one 4xx
  (``http_pages``);
* ``/ws``: a WebSocket per page. JSON texts from the page are commands, dispatched to handlers; the server sends
  JSON texts (scene, log, status, replies) and binary frames (the packed state, ``frames.pack_frame``).

**Latest state wins.** The simulation thread calls ``publish_frame`` with the newest frame; each page gets a frame
only after acknowledging the one before (at most ``MAX_IN_FLIGHT`` unacknowledged), so a slow page simply skips
frames and nothing ever waits on a page. ``wants_frame`` tells the simulation whether any page is ready, so a step
packs a frame only when someone will receive it. Log lines go into a bounded buffer; a page that falls more than
its length behind is told how many it missed.

**One send at a time per page.** Everything for a page (replies, broadcasts, log lines, frames) goes out through
that page's one sender task, so a page that does not read holds at most one message in flight. A broadcast not
yet sent to a page is replaced by a newer one of the same ``type``; a page that stops reading for
``SEND_TIMEOUT_S`` is dropped, and so is one whose replies back up (it stops being read first).

**Slow handlers run off the loop.** A handler wrapped in ``Background`` (the designer's preview) runs on a worker
thread, one at a time per page; requests that arrive meanwhile wait, and only the newest waiting one runs.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any

from agentsim_env.render.web.http_pages import STATIC_DIR, answer, guarded_connection, static_files

MAX_IN_FLIGHT = 2  # frames a page may have unacknowledged; more are skipped for it (latest state wins)
MAX_MESSAGE_BYTES = 1 << 20  # the largest message a page may send (a zone file of 1,000 zones fits)
TICK_S = 0.05  # period of on_tick
LOG_BUFFER = 5000  # log lines kept for pages that are behind
SEND_TIMEOUT_S = 10.0  # a page whose socket takes no message for this long is dropped
MAX_QUEUED = 64  # messages waiting for one page; a page further behind is dropped
REPLY_BACKLOG = 8  # a page's commands are not read while this many messages wait for it
WORKERS = 2  # threads for Background handlers (shared by all pages; each page has at most one job at a time)
INSTALL_HINT = 'the web viewer needs the "viewer" extra: pip install "agentsim-env[viewer]" (websockets)'

Handler = Callable[[dict[str, Any]], "dict[str, Any] | None"]
"""A command handler: the page's JSON object in, a JSON object for that page (or None) out."""


class ClientError(ValueError):
    """A page's message that is refused; the text is sent to that page as ``{"type": "error"}``."""


class Background:
    """A handler that runs on a worker thread, one request at a time per page, the newest waiting request next.

    For handlers too slow for the server's loop (tenths of a second): other pages' messages are answered
    meanwhile. A request that arrives while an older one of the same page still waits replaces it (that one gets
    no reply). Called directly, it is the plain handler.

    Args:
        handler: The handler; it must be safe to run on a thread other than the server's.
    """

    def __init__(self, handler: Handler) -> None:
        self.handler = handler

    def __call__(self, msg: dict[str, Any]) -> dict[str, Any] | None:
        """Run the handler here and now."""
        return self.handler(msg)


def _websockets() -> Any:
    """The ``websockets`` package, or an ImportError with the install hint."""
    try:
        import websockets.asyncio.server as ws_server
    except ImportError as exc:  # pragma: no cover - the test venv has the extra
        raise ImportError(INSTALL_HINT) from exc
    return ws_server


class _Gone(Exception):
    """The page's connection is closed or was dropped: its sender stops."""


@dataclass(slots=True, eq=False)
class _Client:
    """One connected page."""

    ws: Any
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    in_flight: int = 0
    sent_seq: int = -1
    log_pos: int = 0
    outbox: deque[tuple[str | None, str]] = field(default_factory=deque)  # (broadcast type or None, JSON text)
    drained: asyncio.Event = field(default_factory=asyncio.Event)  # set while the outbox is empty
    jobs: dict[str, dict[str, Any] | None] = field(default_factory=dict)  # Background command -> newest waiting
    gone: bool = False


class WebServer:
    """A local web server for one page, with a WebSocket for state frames, logs and commands.

    Args:
        page: The page served at ``/`` (a file of ``static_dir``).
        host: Address to bind; ``127.0.0.1`` (default) is reachable from this machine only.
        port: Port; 0 picks a free one.
        title: Shown in the terminal message.
        handlers: Command name -> handler, run on the server's thread (see ``Handler``); one wrapped in
            ``Background`` runs on a worker thread.
        on_connect: Messages (JSON objects) sent to each page when it connects.
        max_fps: Most frames a second offered to the simulation (``wants_frame``); pages get at most this many.
        on_tick: Called on the server's thread every ``TICK_S`` seconds (the live viewer sends the last step of
            a burst that the frame-rate cap held back); exceptions are ignored.
        static_dir: The folder whose files (and whose ``vendor`` sub-folder's) are served under ``/static/``:
            the package's own ``static`` folder, or a page's own (the UAV zone designer's).
    """

    def __init__(
        self,
        page: str,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        title: str = "agentsim",
        handlers: Mapping[str, Handler] | None = None,
        on_connect: Callable[[], list[dict[str, Any]]] | None = None,
        max_fps: float = 60.0,
        on_tick: Callable[[], None] | None = None,
        static_dir: Path = STATIC_DIR,
    ) -> None:
        self._files = static_files(static_dir)
        if f"/static/{page}" not in self._files:
            raise ValueError(f"page {page!r} is not a file of {static_dir}")
        if not isinstance(port, int) or isinstance(port, bool) or not 0 <= port <= 65535:
            raise ValueError(f"port must be an integer in 0..65535, got {port!r}")
        self.page = page
        self.host = host
        self.port = port
        self.title = title
        self.handlers: dict[str, Handler] = dict(handlers or {})
        self.on_connect = on_connect
        self.on_tick = on_tick
        self.min_interval = 1.0 / max_fps if max_fps > 0 else 0.0
        self.url = ""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: Any = None
        self._stopped: asyncio.Event | None = None
        self._clients: set[_Client] = set()
        self._frame: tuple[int, bytes] | None = None
        self._last_frame_time = 0.0
        self._log: deque[dict[str, Any]] = deque(maxlen=LOG_BUFFER)
        self._log_total = 0  # lines ever appended; a page's log_pos counts in the same numbers
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self.ready_pages = 0  # pages that can take a frame now (read by the simulation thread)
        self.frames_sent = 0
        self.errors: list[str] = []  # internal handler failures (a page got an error message for each)

    # ------------------------------------------------------------------------------------------ lifecycle
    def start(self) -> str:
        """Start serving on a daemon thread; return the page's URL."""
        if self._thread is not None:
            return self.url
        ws_server = _websockets()
        started = threading.Event()
        failure: list[BaseException] = []

        async def main() -> None:
            self._stopped = asyncio.Event()
            try:
                self._server = await ws_server.serve(
                    self._session,
                    self.host,
                    self.port,
                    process_request=self._http,
                    max_size=MAX_MESSAGE_BYTES,
                    ping_interval=None,
                    compression=None,
                    create_connection=guarded_connection(),
                )
            except OSError as exc:
                failure.append(exc)
                started.set()
                return
            port = self._server.sockets[0].getsockname()[1]
            shown = self.host if ":" not in self.host else f"[{self.host}]"
            self.url = f"http://{shown}:{port}/"
            self.port = port
            started.set()
            ticker = asyncio.ensure_future(self._ticker())
            await self._stopped.wait()
            ticker.cancel()
            self._server.close()
            await self._server.wait_closed()

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                loop.run_until_complete(main())
            finally:
                loop.close()

        self._pool = ThreadPoolExecutor(WORKERS, thread_name_prefix="agentsim-web-job")
        self._thread = threading.Thread(target=run, name="agentsim-web", daemon=True)
        self._thread.start()
        started.wait(10.0)
        if failure:
            self._thread = None
            raise ValueError(f"cannot serve on {self.host}:{self.port}: {failure[0]}") from None
        if not self.url:
            raise RuntimeError("the web server did not start within 10 s")
        return self.url

    def stop(self) -> None:
        """Close every page's socket and the server; returns when the thread has ended."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        if self._stopped is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._stopped.set)
        thread.join(10.0)
        self._thread = None
        self._loop = None
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None

    # ------------------------------------------------------------------------------ simulation side API
    def wants_frame(self) -> bool:
        """True when some page can take a frame now and the frame-rate cap allows one (cheap; any thread)."""
        return self.ready_pages > 0 and time.perf_counter() - self._last_frame_time >= self.min_interval

    def publish_frame(self, seq: int, frame: bytes) -> None:
        """Offer the newest frame (replacing any not yet sent: latest state wins). Thread-safe, never blocks."""
        self._frame = (seq, frame)
        self._last_frame_time = time.perf_counter()
        self._wake_all()

    def publish_log(self, lines: list[dict[str, Any]]) -> None:
        """Append log lines for every page (bounded buffer). Thread-safe, never blocks."""
        if not lines:
            return
        with self._lock:
            self._log.extend(lines)
            self._log_total += len(lines)
        self._wake_all()

    def broadcast(self, message: dict[str, Any]) -> None:
        """Send a JSON message to every connected page. Thread-safe, never blocks.

        A page that has not yet been sent an earlier broadcast of the same ``type`` gets only this one.
        """
        loop = self._loop
        if loop is None or loop.is_closed() or not self._clients:
            return
        text = json.dumps(message, separators=(",", ":"))
        kind = message.get("type")
        try:
            loop.call_soon_threadsafe(self._broadcast_now, text, kind if isinstance(kind, str) else None)
        except RuntimeError:  # the loop closed meanwhile
            pass

    @property
    def n_pages(self) -> int:
        """Pages connected now."""
        return len(self._clients)

    def _wake_all(self) -> None:
        loop = self._loop
        if loop is None or not self._clients:
            return
        try:
            loop.call_soon_threadsafe(self._set_wakes)
        except RuntimeError:  # the loop closed meanwhile
            pass

    # ---------------------------------------------------------------------------------- server thread
    def _set_wakes(self) -> None:
        for c in self._clients:
            c.wake.set()

    def _broadcast_now(self, text: str, kind: str | None) -> None:
        for c in list(self._clients):
            self._queue(c, text, kind if kind is not None else "")

    def _queue(self, client: _Client, text: str, kind: str | None = None) -> None:
        """Put a JSON text in the page's outbox (its sender sends it); a broadcast replaces an unsent one of its
        ``kind`` (None: a reply, always kept; "": a broadcast without a type, kept too)."""
        if client.gone:
            return
        if kind:
            for i, (k, _) in enumerate(client.outbox):
                if k == kind:
                    del client.outbox[i]
                    break
        if len(client.outbox) >= MAX_QUEUED:
            self._drop(client)
            return
        client.outbox.append((kind, text))
        client.drained.clear()
        client.wake.set()

    def _drop(self, client: _Client) -> None:
        """Give up on a page that does not read: close its connection at once (its session then ends)."""
        client.gone = True
        client.outbox.clear()
        client.drained.set()
        client.wake.set()
        transport = getattr(client.ws, "transport", None)
        if transport is not None:
            transport.abort()

    def _update_ready(self) -> None:
        self.ready_pages = sum(c.in_flight < MAX_IN_FLIGHT for c in self._clients)

    def _http(self, connection: Any, request: Any) -> Any:
        """Plain HTTP (``http_pages.answer``); ``/ws`` goes on to the WebSocket."""
        return answer(connection, request, files=self._files, page=self.page, host=self.host, port=self.port)

    async def _session(self, ws: Any) -> None:
        """One page: greet it, then run its sender while reading its commands."""
        client = _Client(ws)
        with self._lock:
            client.log_pos = self._log_total  # a new page starts with the lines that come from now on
        sender: asyncio.Future[None] | None = None
        try:
            for msg in self.on_connect() if self.on_connect else []:
                self._queue(client, json.dumps(msg, separators=(",", ":")))
            self._clients.add(client)
            self._update_ready()
            sender = asyncio.ensure_future(self._sender(client))
            client.wake.set()  # the newest frame and any greeting go out now
            async for raw in ws:
                if client.gone:
                    break
                self._receive(client, raw)
                if len(client.outbox) >= REPLY_BACKLOG:  # the page is not reading its replies: stop reading it
                    await client.drained.wait()
        except Exception:  # a page that vanishes mid-message ends its session, nothing more
            pass
        finally:
            client.gone = True
            if sender is not None:
                sender.cancel()
            self._clients.discard(client)
            self._update_ready()

    def _receive(self, client: _Client, raw: Any) -> None:
        """One message from a page: its reply is queued, or its Background handler started."""
        decoded = self._command(client, raw)
        if isinstance(decoded, dict):
            self._queue(client, json.dumps(decoded, separators=(",", ":")))
            return
        if decoded is None:
            return
        cmd, msg = decoded
        fn = self.handlers[cmd]
        if not isinstance(fn, Background):
            reply = self._call(cmd, fn, msg)
            if reply is not None:
                self._queue(client, reply)
            return
        if cmd in client.jobs:  # one running for this page: this request waits, replacing any older waiting one
            client.jobs[cmd] = msg
            return
        client.jobs[cmd] = None
        self._start_job(client, cmd, msg)

    def _start_job(self, client: _Client, cmd: str, msg: dict[str, Any]) -> None:
        loop, pool = self._loop, self._pool
        if loop is None or pool is None:  # the server is stopping: no more jobs
            client.jobs.pop(cmd, None)
            return

        def done(job: Future[str | None]) -> None:
            try:
                loop.call_soon_threadsafe(self._job_done, client, cmd, job)
            except RuntimeError:  # the server stopped meanwhile
                pass

        try:
            pool.submit(self._call, cmd, self.handlers[cmd], msg).add_done_callback(done)
        except RuntimeError:  # the pool has shut down (the server is stopping)
            client.jobs.pop(cmd, None)

    def _job_done(self, client: _Client, cmd: str, job: Future[str | None]) -> None:
        """A Background job ended (server thread): queue its reply, then start the newest waiting request."""
        reply = None if job.cancelled() else job.result()
        if reply is not None:
            self._queue(client, reply)
        waiting = client.jobs.pop(cmd, None)
        if waiting is not None and not client.gone and self._pool is not None:
            client.jobs[cmd] = None
            self._start_job(client, cmd, waiting)

    def _call(self, cmd: str, handler: Handler, msg: dict[str, Any]) -> str | None:
        """Run a handler; its reply as JSON text, a refusal or a failure as an ``error`` message (any thread)."""
        try:
            reply = handler(msg)
        except ClientError as exc:
            reply = {"type": "error", "message": str(exc)}
        except Exception as exc:  # a bug in a handler: report it to the page and keep serving
            text = f"internal error in {cmd!r}: {type(exc).__name__}: {exc}"
            self.errors.append(text)
            reply = {"type": "error", "message": text}
        return None if reply is None else json.dumps(reply, separators=(",", ":"))

    def _command(self, client: _Client, raw: Any) -> dict[str, Any] | tuple[str, dict[str, Any]] | None:
        """Decode one message: ``(cmd, msg)`` to run, None when done here (an ack), or an ``error`` reply."""
        try:
            if not isinstance(raw, str):
                raise ClientError("binary messages are not accepted; send JSON text")
            try:
                msg = json.loads(raw)
            except ValueError:
                raise ClientError(f"not JSON: {raw[:80]!r}") from None
            if not isinstance(msg, dict):
                raise ClientError(f"a message must be a JSON object, got {type(msg).__name__}")
            cmd = msg.get("cmd")
            if cmd == "ack":
                seq = msg.get("seq")
                if isinstance(seq, bool) or not isinstance(seq, int):
                    raise ClientError(f"ack: 'seq' must be an integer, got {seq!r}")
                client.in_flight = max(0, client.in_flight - 1)
                self._update_ready()
                client.wake.set()
                return None
            if not isinstance(cmd, str) or cmd not in self.handlers:
                known = sorted(["ack", *self.handlers])
                raise ClientError(f"unknown command {str(cmd)[:40]!r}; commands are {known}")
            return cmd, msg
        except ClientError as exc:
            return {"type": "error", "message": str(exc)}

    async def _ticker(self) -> None:
        while self.on_tick is not None:
            await asyncio.sleep(TICK_S)
            if self._clients:
                try:
                    self.on_tick()
                except Exception:  # a torn read of a state that is being reset: the next tick tries again
                    pass

    async def _send(self, client: _Client, data: str | bytes) -> None:
        """Send one message; a page whose socket takes none for ``SEND_TIMEOUT_S`` is dropped (raises ``_Gone``)."""
        try:
            await asyncio.wait_for(client.ws.send(data), SEND_TIMEOUT_S)
        except asyncio.TimeoutError:
            self._drop(client)
            raise _Gone from None
        except Exception:  # closed: the session's loop ends and removes the client
            raise _Gone from None

    async def _sender(self, client: _Client) -> None:
        """The page's one sender: queued messages, new log lines and, when the page has room, the newest frame."""
        try:
            await self._send_all(client)
        except _Gone:
            pass
        finally:  # nothing more goes out: a session waiting for the outbox to drain goes on (and ends)
            client.gone = True
            client.drained.set()

    async def _send_all(self, client: _Client) -> None:
        while not client.gone:
            await client.wake.wait()
            client.wake.clear()
            while client.outbox:
                await self._send(client, client.outbox.popleft()[1])
            client.drained.set()
            with self._lock:
                behind = self._log_total - client.log_pos
                kept = len(self._log)
                # only the lines this page has not had (the buffer may hold thousands it has)
                lines = list(islice(reversed(self._log), min(behind, kept)))[::-1]
                dropped = max(0, behind - kept)
                client.log_pos = self._log_total
            if behind > 0:
                await self._send(
                    client,
                    json.dumps({"type": "log", "lines": lines, "dropped": dropped}, separators=(",", ":")),
                )
            frame = self._frame
            if frame is not None and frame[0] > client.sent_seq and client.in_flight < MAX_IN_FLIGHT:
                client.sent_seq = frame[0]
                client.in_flight += 1
                self._update_ready()
                self.frames_sent += 1
                await self._send(client, frame[1])


__all__ = ["INSTALL_HINT", "Background", "ClientError", "Handler", "STATIC_DIR", "WebServer", "static_files"]
