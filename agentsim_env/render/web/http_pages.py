"""The plain HTTP side of the viewer's server: its static files, its answers, and checks on a request's head.

``answer`` serves ``GET /`` (the page the server was made for) and ``GET /static/NAME`` by exact name from a table
built at start-up (``static_files``), so nothing outside the package's ``static`` folder can be read; ``/ws`` goes
on to the WebSocket when its ``Origin`` (if any) is one of this server's.

The server answers ``GET`` and ``HEAD`` only, one request per connection, without a body. The ``websockets``
library closes the connection without an answer on a request with a body, and fails with an ``AssertionError`` on
the terminal when more bytes follow a request before its answer (a pipelined request, a frame sent too early), so
the server's connections (``guarded_connection``) read the request's head themselves first and answer such a
request with one 4xx (``check_head``); only a request that passes reaches the library.
"""

from __future__ import annotations

import mimetypes
from functools import cache
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

STATIC_DIR = Path(__file__).resolve().parent / "static"
MAX_HEAD_BYTES = 64 * 1024  # a request line and headers longer than this get a 431
ALLOWED_METHODS = "GET, HEAD"


def check_head(head: bytes, trailing: bool) -> tuple[int, str] | None:
    """Whether the server serves a request, from its head (request line and header lines, without the blank line).

    Args:
        head: The bytes up to, not including, the ``\\r\\n\\r\\n`` that ends the headers.
        trailing: Whether more bytes came after the head before the answer (a body, a pipelined request).

    Returns:
        None when the request may go on, else the status and the text of the answer: 405 for a method other
        than GET and HEAD, 400 for a body (``Content-Length`` other than 0, ``Transfer-Encoding``), for bytes
        after the head, and for more than one ``Origin`` header. A malformed request line is left to the
        WebSocket library (which closes the connection).
    """
    lines = head.split(b"\r\n")
    parts = lines[0].split(b" ")
    if len(parts) != 3:
        return None
    method = parts[0]
    fields = [(name.strip().lower(), value.strip()) for name, _, value in (ln.partition(b":") for ln in lines[1:])]
    if method not in (b"GET", b"HEAD"):
        shown = method[:20].decode("ascii", "replace")
        return 405, f"method {shown!r} is not allowed: this server answers {ALLOWED_METHODS} only\n"
    if any(n == b"transfer-encoding" or (n == b"content-length" and v != b"0") for n, v in fields):
        return 400, "a request body is not accepted: send the request without one\n"
    if trailing:
        return 400, "one request per connection: nothing may follow a request before its answer\n"
    if sum(n == b"origin" for n, _ in fields) > 1:
        return 400, "more than one Origin header: send one, or none\n"
    return None


def static_files(folder: Path = STATIC_DIR) -> dict[str, Path]:
    """The files the server may send: URL path -> file, for ``folder`` and its ``vendor`` sub-folder only."""
    table: dict[str, Path] = {}
    for sub, prefix in ((folder, "/static/"), (folder / "vendor", "/static/vendor/")):
        if sub.is_dir():
            for f in sorted(sub.iterdir()):
                if f.is_file() and not f.name.startswith("."):
                    table[prefix + f.name] = f
    return table


def origins(host: str, port: int) -> set[str]:
    """The ``host:port`` forms under which a page of a server at ``host``, ``port`` is served."""
    names = {"127.0.0.1", "localhost", "[::1]", host if ":" not in host else f"[{host}]"}
    if host in ("0.0.0.0", "::"):  # all interfaces: any name this machine answers to
        import socket

        names |= {socket.gethostname(), socket.getfqdn()}
        try:
            names |= set(socket.gethostbyname_ex(socket.gethostname())[2])
        except OSError:
            pass
    return {f"{n}:{port}" for n in names}


def answer(connection: Any, request: Any, *, files: dict[str, Path], page: str, host: str, port: int) -> Any:
    """The answer to a plain HTTP request (the server's ``process_request``): a file, or an error.

    Args:
        connection: The ``websockets`` connection (its ``respond`` builds error answers).
        request: The parsed request.
        files: ``static_files()``.
        page: The file served at ``/``.
        host: The address the server listens on (with ``port``: the origins a page of it may have).
        port: Its port.

    Returns:
        A ``websockets`` response (405 for a method other than GET and HEAD, GET only on ``/ws``), or None for
        a WebSocket request that may go on.
    """
    from websockets.datastructures import Headers
    from websockets.http11 import Response

    path = urlsplit(request.path).path
    method = getattr(request, "method", "GET")  # websockets < 17 passes GET requests only
    allowed = "GET" if path == "/ws" else ALLOWED_METHODS
    if method not in allowed.split(", "):
        response = connection.respond(405, f"method not allowed: {path[:40]} answers {allowed}\n")
        response.headers["Allow"] = allowed
        return response
    if path == "/ws":
        # a page from another site must not drive this one (a browser sends its Origin; other clients none)
        sent = request.headers.get_all("Origin")
        if len(sent) > 1:
            return connection.respond(400, "more than one Origin header: send one, or none\n")
        if sent and urlsplit(sent[0]).netloc not in origins(host, port):
            return connection.respond(403, "this page's origin may not connect\n")
        return None
    file: Path | None = None
    if path in ("/", "/index.html"):
        file = files[f"/static/{page}"]
    elif path.startswith("/static/"):
        file = files.get(unquote(path))
    if file is None:
        response = connection.respond(404, "not found\n")
        if method == "HEAD":
            response.body = b""
        return response
    body = file.read_bytes()
    ctype = (
        {".js": "text/javascript", ".mjs": "text/javascript", ".css": "text/css", ".html": "text/html"}.get(file.suffix)
        or mimetypes.guess_type(file.name)[0]
        or "text/plain"
    )
    if ctype.startswith("text/"):
        ctype += "; charset=utf-8"
    headers = Headers(
        [
            ("Content-Type", ctype),
            ("Content-Length", str(len(body))),
            ("Cache-Control", "no-cache"),
            ("X-Content-Type-Options", "nosniff"),
            ("Connection", "close"),
        ]
    )
    return Response(200, "OK", headers, b"" if method == "HEAD" else body)


@cache
def guarded_connection() -> type[Any]:
    """The ``websockets`` connection class whose ``data_received`` checks the request's head first.

    Imported and built on first use: ``websockets`` is the ``viewer`` extra.

    Returns:
        A subclass of ``websockets.asyncio.server.ServerConnection`` for ``serve(create_connection=...)``.
    """
    from websockets.asyncio.server import ServerConnection
    from websockets.protocol import State

    class GuardedConnection(ServerConnection):
        """A connection that holds the request's bytes until its head is complete and checked."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self._head: bytearray | None = bytearray()  # None once the head was passed on (or answered)

        def data_received(self, data: bytes) -> None:
            head = self._head
            if head is None:
                # while the answer to the request is pending, more bytes would derail the library's parser: a
                # client must wait for the answer (a WebSocket one too), so they are dropped
                if self.protocol.state is not State.CONNECTING:
                    super().data_received(data)
                return
            head += data
            end = head.find(b"\r\n\r\n")
            if end < 0:
                if b"\n\n" in head:  # lines without CR: not HTTP/1.1 as the library reads it, which closes it
                    self._head = None
                    super().data_received(bytes(head))
                elif len(head) > MAX_HEAD_BYTES:
                    self._refuse(431, f"the request's head is longer than {MAX_HEAD_BYTES} bytes\n")
                return
            refusal = check_head(bytes(head[:end]), trailing=len(head) > end + 4)
            if refusal is not None:
                self._refuse(*refusal)
                return
            self._head = None
            super().data_received(bytes(head))

        def _refuse(self, status: int, text: str) -> None:
            """Answer with ``status`` and ``text`` and close; the library never sees the request."""
            self._head = None
            response = self.protocol.reject(status, text)
            if status == 405:
                response.headers["Allow"] = ALLOWED_METHODS
            self.transport.write(response.serialize())
            self.transport.close()

    return GuardedConnection


__all__ = [
    "ALLOWED_METHODS",
    "MAX_HEAD_BYTES",
    "STATIC_DIR",
    "answer",
    "check_head",
    "guarded_connection",
    "origins",
    "static_files",
]
