"""The viewer's server against pages and clients that misbehave: a page that never reads, and HTTP requests the
server does not serve (other methods, a body, pipelining, two Origin headers). Raw sockets stand in for them."""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import os
import socket
import time
from collections.abc import Iterator
from typing import Any

import pytest

from agentsim_env.render.web import server
from agentsim_env.render.web.server import WebServer

pytest.importorskip("websockets")
from websockets.asyncio.client import connect  # noqa: E402


@pytest.fixture
def srv() -> Iterator[WebServer]:
    """A viewer page's server on a free port."""
    s = WebServer("viewer.html")
    s.start()
    try:
        yield s
    finally:
        s.stop()


def _exchange(port: int, data: bytes, wait: float = 3.0) -> bytes:
    """Send ``data`` on a new connection and read until the server closes it (or ``wait`` seconds)."""
    with socket.create_connection(("127.0.0.1", port), timeout=wait) as s:
        s.sendall(data)
        out = b""
        try:
            while chunk := s.recv(65536):
                out += chunk
        except (TimeoutError, ConnectionResetError):
            pass
    return out


def _status(response: bytes) -> int:
    assert response.startswith(b"HTTP/1.1 "), response[:80]
    return int(response[9:12])


def _upgrade(path: str = "/ws", extra: str = "") -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    return (
        f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n{extra}\r\n"
    ).encode()


def _loop_tasks(s: WebServer) -> int:
    """Tasks alive on the server's event loop."""
    assert s._loop is not None

    async def count() -> int:
        return len(asyncio.all_tasks())

    return asyncio.run_coroutine_threadsafe(count(), s._loop).result(5)


# ------------------------------------------------------------------------------------- a page that never reads
def _deaf_page(port: int) -> socket.socket:
    """A WebSocket page that completes the handshake and then never reads (a small receive buffer)."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    s.sendall(_upgrade())
    head = b""
    while b"\r\n\r\n" not in head:
        head += s.recv(1)  # only the handshake's answer, byte by byte, so nothing after it is read
    assert head.startswith(b"HTTP/1.1 101"), head
    return s


def test_a_page_that_never_reads_holds_one_send_and_is_dropped(srv: WebServer, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(server, "SEND_TIMEOUT_S", 1.0)
    deaf = _deaf_page(srv.port)
    try:
        t0 = time.monotonic()
        while srv.n_pages == 0 and time.monotonic() - t0 < 5:
            time.sleep(0.01)
        base = _loop_tasks(srv)
        conn = next(iter(srv._clients)).ws
        pad = "x" * 100_000
        tasks, buffered = [], []
        t0 = time.monotonic()
        i = 0
        # status and agent updates of 100 kB, 200 a second, as long as the page is there (at most 6 s)
        while srv.n_pages and time.monotonic() - t0 < 6:
            srv.broadcast({"type": "status", "i": i, "pad": pad})
            srv.broadcast({"type": "agent", "i": i, "pad": pad})
            i += 1
            time.sleep(0.01)
            if i % 20 == 0 and srv.n_pages:
                tasks.append(_loop_tasks(srv))
                buffered.append(conn.transport.get_write_buffer_size())
        assert i > 50 and tasks, i
        assert max(tasks) <= base + 2, tasks  # nothing piles up per broadcast
        assert max(buffered) < 1_000_000, buffered  # at most one message waits beyond the socket's own buffers
        assert srv.n_pages == 0, "a page that stayed unwritable was not dropped"
        assert time.monotonic() - t0 < 5
    finally:
        deaf.close()


def test_a_reading_page_gets_the_newest_broadcast_while_another_page_is_deaf(srv: WebServer) -> None:
    deaf = _deaf_page(srv.port)
    got: list[dict[str, Any]] = []

    async def page() -> None:
        async with connect(srv.url.replace("http", "ws") + "ws", max_size=None) as ws:
            while srv.n_pages < 2:
                await asyncio.sleep(0.01)
            for i in range(200):
                srv.broadcast({"type": "status", "i": i, "pad": "y" * 50_000})
            end = time.monotonic() + 1.5
            while time.monotonic() < end:
                try:
                    got.append(json.loads(await asyncio.wait_for(ws.recv(), 0.2)))
                except asyncio.TimeoutError:
                    continue

    try:
        asyncio.run(page())
    finally:
        deaf.close()
    seen = [m["i"] for m in got if m["type"] == "status"]
    assert seen and seen[-1] == 199 and seen == sorted(seen), seen[-5:]


def test_a_page_that_floods_commands_without_reading_is_dropped(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(server, "SEND_TIMEOUT_S", 1.0)
    s = WebServer("viewer.html", handlers={"big": lambda m: {"type": "big", "pad": "z" * 100_000}})
    s.start()
    deaf = _deaf_page(s.port)
    try:
        frame = json.dumps({"cmd": "big"}).encode()
        masked = bytes([0x81, 0x80 | len(frame), 0, 0, 0, 0]) + frame  # a masked text frame, mask 0
        deaf.setblocking(False)
        for _ in range(2000):
            try:
                deaf.send(masked)
            except BlockingIOError:
                break
        time.sleep(0.5)
        assert _loop_tasks(s) < 12
        t0 = time.monotonic()
        while s.n_pages and time.monotonic() - t0 < 5:
            time.sleep(0.05)
        assert s.n_pages == 0
    finally:
        deaf.close()
        s.stop()


# ------------------------------------------------------------------------------------------ HTTP edge cases
@pytest.fixture
def quiet_terminal(caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> Iterator[None]:
    """Fail the test if the server logged a warning or error, or wrote anything to the terminal."""
    caplog.set_level(logging.INFO)
    yield
    loud = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert not loud, [f"{r.name}: {r.getMessage()}" for r in loud]
    out, err = capfd.readouterr()
    assert not err and not out, err or out


@pytest.mark.parametrize("method", ["POST", "PUT", "DELETE", "OPTIONS", "PATCH", "TRACE", "CONNECT", "BREW"])
def test_methods_other_than_get_and_head_are_refused(srv: WebServer, method: str, quiet_terminal: None) -> None:
    for path in ("/", "/static/viewer.js", "/ws", "/nope"):
        r = _exchange(srv.port, f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
        assert _status(r) == 405, (method, path, r[:120])
        assert b"\r\nAllow: GET, HEAD\r\n" in r and b"<html" not in r.lower()


def test_head_gives_the_headers_of_get_without_a_body(srv: WebServer, quiet_terminal: None) -> None:
    get = _exchange(srv.port, b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    head = _exchange(srv.port, b"HEAD / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    assert _status(get) == _status(head) == 200
    assert head.endswith(b"\r\n\r\n") and b"<html" in get.lower()
    length = next(ln for ln in head.split(b"\r\n") if ln.lower().startswith(b"content-length"))
    assert length in get


@pytest.mark.parametrize(
    "request_bytes",
    [
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 5\r\n\r\nhello",
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 5\r\n\r\n",  # the body follows later
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n\r\n5\r\nhello\r\n0\r\n\r\n",
        b"GET /ws HTTP/1.1\r\nHost: 127.0.0.1\r\ncontent-length: 2\r\n\r\nxx",
    ],
    ids=["body", "announced-body", "chunked", "ws-body"],
)
def test_a_request_with_a_body_gets_a_400(srv: WebServer, request_bytes: bytes, quiet_terminal: None) -> None:
    r = _exchange(srv.port, request_bytes)
    assert _status(r) == 400 and b"body" in r, r


@pytest.mark.parametrize(
    "request_bytes",
    [
        b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\nGET /static/viewer.js HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
        _upgrade() + b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
        _upgrade() + b"\x81\x82\x00\x00\x00\x00{}",  # a frame before the handshake's answer
    ],
    ids=["pipelined-get", "pipelined-after-upgrade", "frame-before-answer"],
)
def test_a_pipelined_request_gets_a_400(srv: WebServer, request_bytes: bytes, quiet_terminal: None) -> None:
    r = _exchange(srv.port, request_bytes)
    assert _status(r) == 400 and b"one request per connection" in r, r
    assert r.count(b"HTTP/1.1 ") == 1


def test_two_origin_headers_get_a_400(srv: WebServer, quiet_terminal: None) -> None:
    own = srv.url.rstrip("/")
    for origins in ([own, "http://evil.example"], [own, own]):
        extra = "".join(f"Origin: {o}\r\n" for o in origins)
        r = _exchange(srv.port, _upgrade(extra=extra))
        assert _status(r) == 400 and b"Origin" in r, r
    r = _exchange(srv.port, _upgrade(extra=f"Origin: {own}\r\n"), wait=0.5)
    assert _status(r) == 101  # one Origin of its own: a page


def test_the_server_still_serves_after_all_that(srv: WebServer, quiet_terminal: None) -> None:
    for bad in (
        b"DELETE / HTTP/1.1\r\n\r\n",
        b"GET / HTTP/1.1\r\nContent-Length: 9\r\n\r\n",
        b"GET / HTTP/1.1\r\n\r\nGET / HTTP/1.1\r\n\r\n",
        _upgrade(extra="Origin: a\r\nOrigin: b\r\n"),
    ):
        _exchange(srv.port, bad)
    r = _exchange(srv.port, b"GET /static/viewer.js HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    assert _status(r) == 200 and b"Connection: close" in r
