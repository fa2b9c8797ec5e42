"""The viewer's web server: the page, its static files and one WebSocket, on a background thread.

The only importer of ``websockets`` (the ``viewer`` extra). One asyncio loop on a daemon thread serves:

* ``GET /``: the page the server was made for (``viewer.html`` or ``designer.html``);
* ``GET /static/NAME`` and ``/static/vendor/NAME``: the package's own files, looked up by exact name in a table
  built at start-up; any other path (``..``, encoded slashes, absolute paths) is a 404, so nothing outside the
  package's ``static`` folder can be read;
* ``/ws``: a WebSocket per page. JSON texts from the page are commands, dispatched to handlers; the server sends
  JSON texts (scene, log, status, replies) and binary frames (the packed state, ``frames.pack_frame``).

**Latest state wins.** The simulation thread calls ``publish_frame`` with the newest frame; each page gets a frame
only after acknowledging the one before (at most ``MAX_IN_FLIGHT`` unacknowledged), so a slow page simply skips
frames and nothing ever waits on a page. ``wants_frame`` tells the simulation whether any page is ready, so a step
packs a frame only when someone will receive it. Log lines go into a bounded buffer; a page that falls more than
its length behind is told how many it missed.
"""

from __future__ import annotations

import asyncio
import json
import mimetypes
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from itertools import islice
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

STATIC_DIR = Path(__file__).resolve().parent / "static"
MAX_IN_FLIGHT = 2  # frames a page may have unacknowledged; more are skipped for it (latest state wins)
MAX_MESSAGE_BYTES = 1 << 20  # the largest message a page may send (a zone file of 1,000 zones fits)
TICK_S = 0.05  # period of on_tick
LOG_BUFFER = 5000  # log lines kept for pages that are behind
INSTALL_HINT = 'the web viewer needs the "viewer" extra: pip install "agentsim-env[viewer]" (websockets)'

Handler = Callable[[dict[str, Any]], "dict[str, Any] | None"]
"""A command handler: the page's JSON object in, a JSON object for that page (or None) out."""


class ClientError(ValueError):
    """A page's message that is refused; the text is sent to that page as ``{"type": "error"}``."""


def _websockets() -> Any:
    """The ``websockets`` package, or an ImportError with the install hint."""
    try:
        import websockets.asyncio.server as ws_server
    except ImportError as exc:  # pragma: no cover - the test venv has the extra
        raise ImportError(INSTALL_HINT) from exc
    return ws_server


def static_files(folder: Path = STATIC_DIR) -> dict[str, Path]:
    """The files the server may send: URL path -> file, for ``folder`` and its ``vendor`` sub-folder only."""
    table: dict[str, Path] = {}
    for sub, prefix in ((folder, "/static/"), (folder / "vendor", "/static/vendor/")):
        if sub.is_dir():
            for f in sorted(sub.iterdir()):
                if f.is_file() and not f.name.startswith("."):
                    table[prefix + f.name] = f
    return table


@dataclass(slots=True, eq=False)
class _Client:
    """One connected page."""

    ws: Any
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    in_flight: int = 0
    sent_seq: int = -1
    log_pos: int = 0


class WebServer:
    """A local web server for one page, with a WebSocket for state frames, logs and commands.

    Args:
        page: The page served at ``/`` (a file of the package's ``static`` folder).
        host: Address to bind; ``127.0.0.1`` (default) is reachable from this machine only.
        port: Port; 0 picks a free one.
        title: Shown in the terminal message.
        handlers: Command name -> handler, run on the server's thread (see ``Handler``).
        on_connect: Messages (JSON objects) sent to each page when it connects.
        max_fps: Most frames a second offered to the simulation (``wants_frame``); pages get at most this many.
        on_tick: Called on the server's thread every ``TICK_S`` seconds (the live viewer sends the last step of
            a burst that the frame-rate cap held back); exceptions are ignored.
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
    ) -> None:
        self._files = static_files()
        if f"/static/{page}" not in self._files:
            raise ValueError(f"page {page!r} is not a file of {STATIC_DIR}")
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
                    self._session, self.host, self.port, process_request=self._http,
                    max_size=MAX_MESSAGE_BYTES, ping_interval=None, compression=None,
                )  # fmt: skip
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
        """Send a JSON message to every connected page. Thread-safe, never blocks."""
        loop = self._loop
        if loop is None or loop.is_closed() or not self._clients:
            return
        text = json.dumps(message, separators=(",", ":"))
        try:
            loop.call_soon_threadsafe(self._broadcast_now, text)
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

    def _broadcast_now(self, text: str) -> None:
        for c in list(self._clients):
            asyncio.ensure_future(self._safe_send(c, text))

    def _update_ready(self) -> None:
        self.ready_pages = sum(c.in_flight < MAX_IN_FLIGHT for c in self._clients)

    def _http(self, connection: Any, request: Any) -> Any:
        """Plain HTTP: the page and the static files (exact names only); ``/ws`` goes on to the WebSocket."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path = urlsplit(request.path).path
        if path == "/ws":
            # a page from another site must not drive this one (a browser sends its Origin; other clients none)
            origin = request.headers.get("Origin")
            if origin is not None and urlsplit(origin).netloc not in self._origins():
                return connection.respond(403, "this page's origin may not connect\n")
            return None
        file: Path | None = None
        if path in ("/", "/index.html"):
            file = self._files[f"/static/{self.page}"]
        elif path.startswith("/static/"):
            file = self._files.get(unquote(path))
        if file is None:
            return connection.respond(404, "not found\n")
        body = file.read_bytes()
        ctype = {".js": "text/javascript", ".mjs": "text/javascript", ".css": "text/css",
                 ".html": "text/html"}.get(file.suffix) or mimetypes.guess_type(file.name)[0] or "text/plain"  # fmt: skip
        if ctype.startswith("text/"):
            ctype += "; charset=utf-8"
        headers = Headers([("Content-Type", ctype), ("Content-Length", str(len(body))),
                           ("Cache-Control", "no-cache"), ("X-Content-Type-Options", "nosniff")])  # fmt: skip
        return Response(200, "OK", headers, body)

    def _origins(self) -> set[str]:
        """The ``host:port`` forms under which a page of this server is served."""
        names = {"127.0.0.1", "localhost", "[::1]", self.host if ":" not in self.host else f"[{self.host}]"}
        if self.host in ("0.0.0.0", "::"):  # all interfaces: any name this machine answers to
            import socket

            names |= {socket.gethostname(), socket.getfqdn()}
            try:
                names |= set(socket.gethostbyname_ex(socket.gethostname())[2])
            except OSError:
                pass
        return {f"{n}:{self.port}" for n in names}

    async def _session(self, ws: Any) -> None:
        """One page: greet it, then run its sender while reading its commands."""
        client = _Client(ws)
        with self._lock:
            client.log_pos = self._log_total  # a new page starts with the lines that come from now on
        self._clients.add(client)
        self._update_ready()
        sender = asyncio.ensure_future(self._sender(client))
        try:
            for msg in self.on_connect() if self.on_connect else []:
                await ws.send(json.dumps(msg, separators=(",", ":")))
            client.wake.set()
            async for raw in ws:
                reply = self._dispatch(client, raw)
                if reply is not None:
                    await self._safe_send(client, json.dumps(reply, separators=(",", ":")))
        except Exception:  # a page that vanishes mid-message ends its session, nothing more
            pass
        finally:
            sender.cancel()
            self._clients.discard(client)
            self._update_ready()

    def _dispatch(self, client: _Client, raw: Any) -> dict[str, Any] | None:
        """Decode and run one command; any problem becomes an ``error`` reply (the server goes on)."""
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
            return self.handlers[cmd](msg)
        except ClientError as exc:
            return {"type": "error", "message": str(exc)}
        except Exception as exc:  # a bug in a handler: report it to the page and keep serving
            text = f"internal error in {str(raw)[:40]!r}: {type(exc).__name__}: {exc}"
            self.errors.append(text)
            return {"type": "error", "message": text}

    async def _ticker(self) -> None:
        while self.on_tick is not None:
            await asyncio.sleep(TICK_S)
            if self._clients:
                try:
                    self.on_tick()
                except Exception:  # a torn read of a state that is being reset: the next tick tries again
                    pass

    async def _safe_send(self, client: _Client, data: str | bytes) -> None:
        try:
            await client.ws.send(data)
        except Exception:  # closed: the session's loop ends and removes the client
            pass

    async def _sender(self, client: _Client) -> None:
        """Send new log lines and, when the page has room, the newest frame; sleep until woken."""
        while True:
            await client.wake.wait()
            client.wake.clear()
            with self._lock:
                behind = self._log_total - client.log_pos
                kept = len(self._log)
                # only the lines this page has not had (the buffer may hold thousands it has)
                lines = list(islice(reversed(self._log), min(behind, kept)))[::-1]
                dropped = max(0, behind - kept)
                client.log_pos = self._log_total
            if behind > 0:
                await self._safe_send(client, json.dumps({"type": "log", "lines": lines, "dropped": dropped},
                                                         separators=(",", ":")))  # fmt: skip
            frame = self._frame
            if frame is not None and frame[0] > client.sent_seq and client.in_flight < MAX_IN_FLIGHT:
                client.sent_seq = frame[0]
                client.in_flight += 1
                self._update_ready()
                self.frames_sent += 1
                await self._safe_send(client, frame[1])


__all__ = ["INSTALL_HINT", "ClientError", "Handler", "STATIC_DIR", "WebServer", "static_files"]
