"""The exchange's data path for Ray shards: one TCP connection per shard to the exchange actor, framed pickles.

A step of shards meets at five or six barriers (``distributed.exchange``). Through Ray actor calls each barrier cost
~5 ms of latency and ~8 ms of CPU per step across the processes (task submission, gRPC, the object store for
payloads over 100 KB), measured with no simulation at all (``benchmarks/bench_distributed.py``, "exchange
floor"). Here a shard keeps one TCP connection to the exchange actor, which serves it on its own asyncio loop
(``ExchangeActor.serve``), and a barrier is one frame each way. The control calls (drop, revive, owners, byte
counts) stay Ray calls.

Frame: a 16-byte header (``b"ASXF"``, the number of out-of-band buffers, the pickle's length), one 8-byte length per
buffer, the pickle (protocol 5), then the buffers (numpy arrays travel as raw bytes, not copied into the pickle).

Security: the server binds one address (127.0.0.1 for the local cluster; the driver node's address on a cluster,
where Ray's own ports already are) and serves only peers that send the exchange's 32-byte token (made by the driver
with ``secrets``, given to the shards through Ray) and a shard index within range, within ``AUTH_TIMEOUT_S``;
anything else is closed unanswered, and at most ``MAX_PENDING_AUTH`` connections may wait to authenticate. Frames
are unpickled only from authenticated shards (the same trust Ray gives them: they run the simulation's code), a
shard may post only under its own index, and a frame whose header announces more than ``max_frame_bytes`` or
``MAX_BUFFERS`` buffers closes the connection before anything is allocated.
"""

from __future__ import annotations

import asyncio
import hmac
import pickle
import socket
import struct
from collections.abc import Awaitable, Callable
from typing import Any

MAGIC = b"ASXF"
AUTH_MAGIC = b"ASXA"
AUTH_OK = b"ASOK"
TOKEN_BYTES = 32
AUTH_TIMEOUT_S = 5.0
"""Seconds a new connection has to send its token."""
MAX_PENDING_AUTH = 64
"""Connections that may wait to authenticate at once (more are closed at once)."""
MAX_BUFFERS = 4096
"""Out-of-band buffers one frame may announce."""
MAX_FRAME_BYTES = 1 << 33
"""Default bound of one frame (8 GiB: the largest a step of a large world posts is far below)."""
_HEAD = struct.Struct("!4sIQ")
_LEN = struct.Struct("!Q")
_AUTH = struct.Struct(f"!4s{TOKEN_BYTES}sI")


class FrameError(ConnectionError):
    """A frame broke the protocol (bad magic, too large, too many buffers): the connection is closed."""


def encode(obj: Any) -> list[Any]:
    """The frame of ``obj`` as a list of byte chunks (header, lengths, pickle, buffers; not joined: no copy)."""
    bufs: list[pickle.PickleBuffer] = []
    body = pickle.dumps(obj, protocol=5, buffer_callback=bufs.append)
    raws = [b.raw() for b in bufs]
    head = _HEAD.pack(MAGIC, len(raws), len(body)) + b"".join(_LEN.pack(r.nbytes) for r in raws)
    return [head, body, *raws]


def check_head(head: bytes, max_frame_bytes: int) -> tuple[int, int]:
    """``(n_buffers, pickle_length)`` of a frame header, checked.

    Raises:
        FrameError: Bad magic, more than ``MAX_BUFFERS`` buffers, or a pickle over ``max_frame_bytes``.
    """
    magic, n_buf, n_body = _HEAD.unpack(head)
    if magic != MAGIC:
        raise FrameError(f"not an exchange frame (magic {magic!r})")
    if n_buf > MAX_BUFFERS:
        raise FrameError(f"a frame announced {n_buf} buffers (at most {MAX_BUFFERS})")
    if n_body > max_frame_bytes:
        raise FrameError(f"a frame announced {n_body} bytes (at most {max_frame_bytes})")
    return n_buf, n_body


def check_lengths(raw: bytes, n_buf: int, n_body: int, max_frame_bytes: int) -> list[int]:
    """The buffer lengths of a frame, checked against ``max_frame_bytes`` (with the pickle's length).

    Raises:
        FrameError: When the frame would exceed the bound.
    """
    sizes = [_LEN.unpack_from(raw, 8 * i)[0] for i in range(n_buf)]
    if n_body + sum(sizes) > max_frame_bytes:
        raise FrameError(f"a frame announced {n_body + sum(sizes)} bytes (at most {max_frame_bytes})")
    return sizes


# ---------------------------------------------------------------------------------------------------- client
def _recv_exact(sock: socket.socket, n: int) -> bytearray:
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        k = sock.recv_into(view[got:], n - got)
        if k == 0:
            raise ConnectionError("the exchange closed the connection")
        got += k
    return buf


def send_frame(sock: socket.socket, obj: Any) -> None:
    """Send ``obj`` as one frame (blocking)."""
    for chunk in encode(obj):
        sock.sendall(chunk)


def recv_frame(sock: socket.socket, max_frame_bytes: int = MAX_FRAME_BYTES) -> Any:
    """Receive one frame (blocking); its object (arrays backed by writable buffers)."""
    n_buf, n_body = check_head(bytes(_recv_exact(sock, _HEAD.size)), max_frame_bytes)
    sizes = check_lengths(bytes(_recv_exact(sock, 8 * n_buf)), n_buf, n_body, max_frame_bytes)
    body = _recv_exact(sock, n_body)
    return pickle.loads(body, buffers=[_recv_exact(sock, s) for s in sizes])


class WireClient:
    """A shard's side: ``swap`` over its connection to the exchange (connected at the first swap).

    Args:
        host: The exchange's address.
        port: Its port.
        token: The exchange's token (``TOKEN_BYTES`` bytes).
        index: This shard's index.
        wait_s: Longest wait for a barrier's answer (the exchange answers a barrier it gave up on with an error
            earlier: this is the bound for a silent exchange).
    """

    def __init__(self, host: str, port: int, token: bytes, index: int, wait_s: float) -> None:
        if len(token) != TOKEN_BYTES:
            raise ValueError(f"token must be {TOKEN_BYTES} bytes, got {len(token)}")
        self.host, self.port, self.token, self.index = str(host), int(port), bytes(token), int(index)
        self.wait_s = float(wait_s)
        self._sock: socket.socket | None = None

    def _connect(self) -> socket.socket:
        sock = socket.create_connection((self.host, self.port), timeout=AUTH_TIMEOUT_S)
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(_AUTH.pack(AUTH_MAGIC, self.token, self.index))
            if bytes(_recv_exact(sock, len(AUTH_OK))) != AUTH_OK:
                raise ConnectionError("the exchange refused this shard")
        except BaseException:
            sock.close()
            raise
        sock.settimeout(self.wait_s)
        return sock

    def swap(self, key: tuple[int, str], k: int, payload: dict[str, Any]) -> dict[str, Any]:
        """Post ``payload`` at barrier ``key`` as shard ``k``; shard ``k``'s part once the barrier completes.

        Raises:
            TimeoutError: The barrier did not complete in time (as ``LocalExchange.swap``).
            ConnectionError: The connection broke (the exchange is gone).
        """
        if self._sock is None:
            self._sock = self._connect()
        try:
            send_frame(self._sock, (key, int(k), payload))
            status, body = recv_frame(self._sock)
        except (OSError, FrameError):
            self.close()
            raise
        if status != "ok":
            raise TimeoutError(str(body))
        return body  # type: ignore[no-any-return]

    def close(self) -> None:
        """Close the connection (a later swap connects again)."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None


# ---------------------------------------------------------------------------------------------------- server
Swap = Callable[[tuple[int, str], int, dict[str, Any]], Awaitable[dict[str, Any]]]


class WireServer:
    """The exchange actor's side: serves ``swap`` to authenticated shards on its asyncio loop.

    Args:
        swap: The barrier (``ExchangeActor.swap``); raises ``TimeoutError`` when a barrier gives up.
        token: The token a shard must send (``TOKEN_BYTES`` bytes).
        n_shards: Shard indices accepted: ``[0, n_shards)``.
        max_frame_bytes: The bound of one frame.
    """

    def __init__(self, swap: Swap, token: bytes, n_shards: int, max_frame_bytes: int = MAX_FRAME_BYTES) -> None:
        if len(token) != TOKEN_BYTES:
            raise ValueError(f"token must be {TOKEN_BYTES} bytes, got {len(token)}")
        self._swap, self._token, self.n_shards = swap, bytes(token), int(n_shards)
        self.max_frame_bytes = int(max_frame_bytes)
        self._server: asyncio.AbstractServer | None = None
        self._pending = 0
        self.refused = 0
        """Connections closed unanswered (bad or missing token, too many waiting, a broken frame)."""

    async def start(self, host: str) -> int:
        """Listen on ``host`` (a free port); the port."""
        self._server = await asyncio.start_server(self._serve, host, 0, limit=1 << 24)
        return int(self._server.sockets[0].getsockname()[1])

    async def close(self) -> None:
        """Stop listening."""
        if self._server is not None:
            self._server.close()
            self._server = None

    async def _auth(self, reader: asyncio.StreamReader) -> int | None:
        try:
            raw = await asyncio.wait_for(reader.readexactly(_AUTH.size), AUTH_TIMEOUT_S)
        except (asyncio.TimeoutError, asyncio.IncompleteReadError, OSError):
            return None
        magic, token, index = _AUTH.unpack(raw)
        if magic != AUTH_MAGIC or not hmac.compare_digest(token, self._token) or index >= self.n_shards:
            return None
        return int(index)

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            if self._pending >= MAX_PENDING_AUTH:
                self.refused += 1
                return
            self._pending += 1
            try:
                index = await self._auth(reader)
            finally:
                self._pending -= 1
            if index is None:
                self.refused += 1
                return
            sock = writer.get_extra_info("socket")
            if sock is not None:
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            writer.write(AUTH_OK)
            await writer.drain()
            while True:
                key, k, payload = await self._read(reader)
                if k != index:
                    raise FrameError(f"shard {index} posted as shard {k}")
                try:
                    reply: tuple[str, Any] = ("ok", await self._swap(key, k, payload))
                except TimeoutError as e:
                    reply = ("error", str(e))
                writer.writelines(encode(reply))
                await writer.drain()
        except FrameError:
            self.refused += 1
        except (asyncio.IncompleteReadError, ConnectionError, OSError):
            pass  # the shard went away: the coordinator drops it from the barriers
        finally:
            writer.close()

    async def _read(self, reader: asyncio.StreamReader) -> tuple[tuple[int, str], int, dict[str, Any]]:
        n_buf, n_body = check_head(await reader.readexactly(_HEAD.size), self.max_frame_bytes)
        sizes = check_lengths(await reader.readexactly(8 * n_buf), n_buf, n_body, self.max_frame_bytes)
        body = await reader.readexactly(n_body)
        bufs = [await reader.readexactly(s) for s in sizes]  # read-only arrays: the routing only reads them
        try:
            key, k, payload = pickle.loads(body, buffers=bufs)
            if not isinstance(payload, dict):
                raise TypeError(type(payload).__name__)
            return (int(key[0]), str(key[1])), int(k), payload
        except (pickle.UnpicklingError, TypeError, ValueError, IndexError, EOFError) as e:
            raise FrameError(f"a frame is not (key, shard, payload): {e}") from None
