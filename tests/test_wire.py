"""The exchange's TCP data path (``distributed.wire``): frames, barriers over it, and what it refuses.

The server runs on an asyncio loop in a thread of the test (as on the exchange actor's loop); the clients are the
blocking ones the shards use.
"""

from __future__ import annotations

import asyncio
import socket
import struct
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from agentsim_env.distributed import wire
from agentsim_env.distributed.wire import TOKEN_BYTES, FrameError, WireClient, WireServer

TOKEN = bytes(range(TOKEN_BYTES))


class Loop:
    """A server on an event loop in a background thread, with a barrier of ``n`` shards behind it."""

    def __init__(self, n: int, wait_s: float = 5.0, max_frame_bytes: int = wire.MAX_FRAME_BYTES) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.posts: dict[tuple[int, str], dict[int, Any]] = {}
        self.events: dict[tuple[int, str], asyncio.Event] = {}
        self.n, self.wait_s = n, wait_s

        async def swap(key: tuple[int, str], k: int, payload: dict[str, Any]) -> dict[str, Any]:
            # every shard gets the posts of all, in shard order
            self.posts.setdefault(key, {})[k] = payload
            ev = self.events.setdefault(key, asyncio.Event())
            if len(self.posts[key]) == self.n:
                ev.set()
            try:
                await asyncio.wait_for(ev.wait(), self.wait_s)
            except asyncio.TimeoutError:
                raise TimeoutError(f"barrier {key} incomplete") from None
            return {"all": [self.posts[key][i] for i in range(self.n)]}

        self.server = WireServer(swap, TOKEN, n, max_frame_bytes)
        self.port = self.run(self.server.start("127.0.0.1"))

    def run(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(10)

    def close(self) -> None:
        self.run(self.server.close())
        self.run(_cancel_others())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
        self.loop.close()


async def _cancel_others() -> None:
    """Cancel the connection handlers still running (then the loop can stop cleanly)."""
    me = asyncio.current_task()
    tasks = [t for t in asyncio.all_tasks() if t is not me]
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)


@pytest.fixture
def two() -> Iterator[Loop]:
    lp = Loop(2)
    yield lp
    lp.close()


def _closed_unanswered(sock: socket.socket, timeout: float = 10.0) -> bool:
    """Whether the server closes ``sock`` without sending a byte."""
    sock.settimeout(timeout)
    try:
        return sock.recv(16) == b""
    except ConnectionResetError:
        return True


def test_a_barrier_over_the_wire_gives_every_shard_every_post(two: Loop) -> None:
    a = {"slots": np.arange(5, dtype=np.int64), "pos": np.random.default_rng(0).random((5, 3)), "n": 3}
    b = {"slots": np.zeros(0, dtype=np.int64), "pos": np.zeros((0, 3)), "n": 4}
    clients = [WireClient("127.0.0.1", two.port, TOKEN, k, 10.0) for k in (0, 1)]
    out: dict[int, Any] = {}
    threads = [
        threading.Thread(target=lambda k=k, p=p: out.__setitem__(k, clients[k].swap((1, "x"), k, p)))
        for k, p in ((0, a), (1, b))
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    for k in (0, 1):
        got = out[k]["all"]
        assert np.array_equal(got[0]["slots"], a["slots"]) and np.array_equal(got[0]["pos"], a["pos"])
        assert got[0]["n"] == 3 and got[1]["n"] == 4 and got[1]["pos"].shape == (0, 3)
    for c in clients:
        c.close()


def test_frames_round_trip_arrays_of_every_dtype_without_copying_them_into_the_pickle() -> None:
    obj = {
        "f32": np.arange(6, dtype=np.float32).reshape(2, 3),
        "i8": np.array([-1, 2], np.int8),
        "b": np.array([True, False]),
        "big": np.arange(1 << 16, dtype=np.int64),
        "s": "text",
    }
    chunks = wire.encode(obj)
    assert len(chunks[1]) < 2000  # the arrays are buffers of their own, not inside the pickle
    left, right = socket.socketpair()
    try:
        t = threading.Thread(target=lambda: [left.sendall(c) for c in chunks])
        t.start()
        got = wire.recv_frame(right)
        t.join()
    finally:
        left.close()
        right.close()
    for k, v in obj.items():
        assert np.array_equal(got[k], v) if isinstance(v, np.ndarray) else got[k] == v


def test_a_wrong_token_is_closed_unanswered(two: Loop) -> None:
    with socket.create_connection(("127.0.0.1", two.port)) as s:
        s.sendall(struct.pack(f"!4s{TOKEN_BYTES}sI", wire.AUTH_MAGIC, b"x" * TOKEN_BYTES, 0))
        assert _closed_unanswered(s)
    with pytest.raises(ConnectionError):
        WireClient("127.0.0.1", two.port, b"y" * TOKEN_BYTES, 0, 5.0).swap((0, "x"), 0, {})
    assert two.run(_refused(two)) >= 2


async def _refused(lp: Loop) -> int:
    return lp.server.refused


def test_a_shard_index_out_of_range_is_refused(two: Loop) -> None:
    with pytest.raises(ConnectionError):
        WireClient("127.0.0.1", two.port, TOKEN, 2, 5.0).swap((0, "x"), 2, {})


def test_a_silent_peer_is_closed_after_the_auth_timeout(two: Loop, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(wire, "AUTH_TIMEOUT_S", 0.3)
    with socket.create_connection(("127.0.0.1", two.port)) as s:
        s.sendall(b"ASX")  # a few bytes, then nothing
        t0 = time.monotonic()
        assert _closed_unanswered(s)
        assert time.monotonic() - t0 < 5.0


def test_posting_under_another_shards_index_closes_the_connection(two: Loop) -> None:
    c = WireClient("127.0.0.1", two.port, TOKEN, 0, 5.0)
    with pytest.raises(ConnectionError):
        c.swap((0, "x"), 1, {"a": 1})


@pytest.mark.parametrize(
    "head",
    [
        struct.pack("!4sIQ", b"NOPE", 0, 10),  # bad magic
        struct.pack("!4sIQ", wire.MAGIC, wire.MAX_BUFFERS + 1, 10),  # too many buffers
        struct.pack("!4sIQ", wire.MAGIC, 0, 1 << 40),  # a pickle over the bound
        struct.pack("!4sIQ", wire.MAGIC, 1, 10) + struct.pack("!Q", 1 << 40),  # a buffer over the bound
    ],
)
def test_a_frame_over_the_bounds_closes_the_connection_before_any_allocation(two: Loop, head: bytes) -> None:
    with socket.create_connection(("127.0.0.1", two.port)) as s:
        s.sendall(struct.pack(f"!4s{TOKEN_BYTES}sI", wire.AUTH_MAGIC, TOKEN, 0))
        assert s.recv(4) == wire.AUTH_OK
        s.sendall(head)
        assert _closed_unanswered(s)


def test_a_frame_that_is_not_a_post_closes_the_connection(two: Loop) -> None:
    with socket.create_connection(("127.0.0.1", two.port)) as s:
        s.sendall(struct.pack(f"!4s{TOKEN_BYTES}sI", wire.AUTH_MAGIC, TOKEN, 0))
        assert s.recv(4) == wire.AUTH_OK
        for chunk in wire.encode(["not", "a", "post", "tuple"]):
            s.sendall(chunk)
        assert _closed_unanswered(s)


def test_too_many_peers_waiting_to_authenticate_are_closed_at_once(two: Loop, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(wire, "MAX_PENDING_AUTH", 2)
    idle = [socket.create_connection(("127.0.0.1", two.port)) for _ in range(2)]
    try:
        time.sleep(0.2)  # both are waiting to authenticate now
        with socket.create_connection(("127.0.0.1", two.port)) as s:
            assert _closed_unanswered(s, timeout=2.0)
    finally:
        for s in idle:
            s.close()


def test_a_barrier_that_gives_up_answers_a_timeout_error() -> None:
    lp = Loop(2, wait_s=0.2)
    try:
        with pytest.raises(TimeoutError, match="incomplete"):
            WireClient("127.0.0.1", lp.port, TOKEN, 0, 5.0).swap((0, "x"), 0, {})
    finally:
        lp.close()


def test_a_silent_exchange_times_out_the_shard() -> None:
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    try:

        def accept() -> None:
            conn, _ = srv.accept()
            conn.recv(64)
            conn.sendall(wire.AUTH_OK)
            time.sleep(2.0)  # then never answers a post
            conn.close()

        threading.Thread(target=accept, daemon=True).start()
        with pytest.raises((TimeoutError, ConnectionError)):
            WireClient("127.0.0.1", srv.getsockname()[1], TOKEN, 0, 0.3).swap((0, "x"), 0, {})
    finally:
        srv.close()


def test_bad_tokens_are_refused_at_construction() -> None:
    with pytest.raises(ValueError, match="token"):
        WireClient("127.0.0.1", 1, b"short", 0, 1.0)
    with pytest.raises(ValueError, match="token"):
        WireServer(_never, b"short", 2)
    with pytest.raises(FrameError):
        wire.check_head(struct.pack("!4sIQ", b"ASXF", 0, 100), 10)


async def _never(key: tuple[int, str], k: int, payload: dict[str, Any]) -> dict[str, Any]:
    raise AssertionError("not called")
