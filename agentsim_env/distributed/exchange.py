"""Where the shards' posts meet during a step: a barrier per (step, phase) that routes them with a ``Bridge``.

A shard calls ``swap(key, k, payload)`` and blocks until every live shard has posted for ``key`` (a ``(tick,
phase)`` pair); then ``Bridge.route`` runs once and every shard gets its part. ``drop(k)`` removes a shard that
died or missed its deadline: a barrier waiting for it completes without it, so the others finish their step.

``LocalExchange`` serves shards running as threads of this process (the local backend); ``ExchangeActor`` is
the same barrier as an asyncio Ray actor (``distributed.ray_backend`` starts it next to the driver). A barrier
that is not complete within ``wait_s`` raises ``TimeoutError`` in the waiting shard (its step then fails and the
driver declares it offline); the driver's own deadline normally drops the late shard well before.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from agentsim_env.distributed.bridge import Bridge, Packed
from agentsim_env.distributed.wire import WireServer

Key = tuple[int, str]
"""A barrier's name: the step's tick and the phase."""


class _Barriers:
    """The bookkeeping both exchanges share: posts per key, the live shards, the routed results."""

    def __init__(self, bridge: Bridge, n_shards: int) -> None:
        self.bridge = bridge
        self.alive = set(range(int(n_shards)))
        self.posts: dict[Key, dict[int, Packed]] = {}
        self.results: dict[Key, dict[int, Packed]] = {}
        self.taken: dict[Key, set[int]] = {}
        self.waiting: set[int] = set()  # shards inside ``swap`` now (posted, not yet answered)

    def post(self, key: Key, k: int, payload: Packed) -> None:
        self.posts.setdefault(key, {})[k] = payload
        self.waiting.add(k)

    def complete(self) -> list[Key]:
        """Route every barrier whose live shards have all posted; the keys completed now."""
        done = []
        for key, posts in list(self.posts.items()):
            if self.alive <= set(posts):
                live = {k: v for k, v in posts.items() if k in self.alive}
                self.results[key] = self.bridge.route(key[1], live)
                self.taken[key] = set()
                del self.posts[key]
                done.append(key)
        return done

    def take(self, key: Key, k: int) -> Packed:
        self.waiting.discard(k)
        out = self.results[key].get(k, {})
        taken = self.taken[key]
        taken.add(k)
        if self.alive <= taken:  # every live shard has its part: forget the barrier
            del self.results[key], self.taken[key]
        return out

    def drop(self, k: int) -> None:
        self.alive.discard(int(k))

    def revive(self, k: int) -> None:
        self.alive.add(int(k))
        self.posts.clear()
        self.results.clear()
        self.taken.clear()


class LocalExchange:
    """The barrier for shards that run as threads of this process.

    Args:
        bridge: The routing.
        n_shards: Number of shards K.
        wait_s: Longest wait at one barrier.
    """

    def __init__(self, bridge: Bridge, n_shards: int, wait_s: float = 60.0) -> None:
        self._b = _Barriers(bridge, n_shards)
        self._cond = threading.Condition()
        self.wait_s = float(wait_s)

    @property
    def bridge(self) -> Bridge:
        """The routing."""
        return self._b.bridge

    def swap(self, key: Key, k: int, payload: Packed) -> Packed:
        """Post ``payload`` for barrier ``key`` as shard ``k``; wait until it completes; shard ``k``'s part.

        Raises:
            TimeoutError: When the barrier is not complete within ``wait_s``.
        """
        with self._cond:
            self._b.post(key, k, payload)
            if self._b.complete():
                self._cond.notify_all()
            if not self._cond.wait_for(lambda: key in self._b.results, timeout=self.wait_s):
                self._b.waiting.discard(k)
                raise TimeoutError(
                    f"exchange {key[1]!r} of step {key[0]}: the other shards did not post within {self.wait_s:g} s"
                )
            return self._b.take(key, k)

    def waiting(self) -> set[int]:
        """The shards waiting at a barrier now (not late themselves: they wait for the others)."""
        with self._cond:
            return set(self._b.waiting)

    def drop(self, k: int) -> None:
        """Shard ``k`` is offline: barriers no longer wait for it."""
        with self._cond:
            self._b.drop(k)
            if self._b.complete():
                self._cond.notify_all()

    def revive(self, k: int) -> None:
        """Shard ``k`` runs again (a new episode starts: every pending barrier is forgotten)."""
        with self._cond:
            self._b.revive(k)

    def set_owner(self, owner: Any) -> None:
        """The shard owning each strip from now on."""
        with self._cond:
            self._b.bridge.set_owner(owner)

    def set_slot_owner(self, owner: Any) -> None:
        """The shard owning each slot (at the start of an episode)."""
        with self._cond:
            self._b.bridge.set_slot_owner(owner)

    def take_bytes(self) -> dict[str, int]:
        """The bytes routed since the previous call, by phase (``Bridge.take_bytes``)."""
        with self._cond:
            return self._b.bridge.take_bytes()


class ExchangeActor:
    """The barrier as an asyncio Ray actor (wrapped with ``ray.remote`` by ``distributed.ray_backend``).

    Args:
        bridge: The routing.
        n_shards: Number of shards K.
        wait_s: Longest wait at one barrier.
    """

    def __init__(self, bridge: Bridge, n_shards: int, wait_s: float = 60.0) -> None:
        self._b = _Barriers(bridge, n_shards)
        self._events: dict[Key, asyncio.Event] = {}
        self.wait_s = float(wait_s)
        self._wire: WireServer | None = None
        self.port = 0
        """The TCP port the shards post to (``serve``; 0 before)."""

    async def serve(self, host: str, token: bytes) -> int:
        """Serve ``swap`` to the shards over TCP on ``host`` (``distributed.wire``); the port."""
        if self._wire is None:
            self._wire = WireServer(self.swap, token, len(self._b.alive))
            self.port = await self._wire.start(host)
        return self.port

    async def refused(self) -> int:
        """Connections the wire server closed unanswered (a bad token, a broken frame)."""
        return self._wire.refused if self._wire is not None else 0

    def _wake(self) -> None:
        for key in self._b.complete():
            self._events.pop(key, asyncio.Event()).set()

    async def swap(self, key: Key, k: int, payload: Packed) -> Packed:
        """As ``LocalExchange.swap``."""
        key = (int(key[0]), str(key[1]))
        self._b.post(key, k, payload)
        event = self._events.setdefault(key, asyncio.Event())
        self._wake()
        if key not in self._b.results:
            try:
                await asyncio.wait_for(event.wait(), timeout=self.wait_s)
            except asyncio.TimeoutError:
                self._b.waiting.discard(k)
                raise TimeoutError(
                    f"exchange {key[1]!r} of step {key[0]}: the other shards did not post within {self.wait_s:g} s"
                ) from None
        return self._b.take(key, k)

    async def waiting(self) -> set[int]:
        """As ``LocalExchange.waiting``."""
        return set(self._b.waiting)

    async def drop(self, k: int) -> None:
        """As ``LocalExchange.drop``."""
        self._b.drop(k)
        self._wake()

    async def revive(self, k: int) -> None:
        """As ``LocalExchange.revive``."""
        self._b.revive(k)
        self._events.clear()

    async def set_owner(self, owner: Any) -> None:
        """As ``LocalExchange.set_owner``."""
        self._b.bridge.set_owner(owner)

    async def set_slot_owner(self, owner: Any) -> None:
        """As ``LocalExchange.set_slot_owner``."""
        self._b.bridge.set_slot_owner(owner)

    async def take_bytes(self) -> dict[str, int]:
        """As ``LocalExchange.take_bytes``."""
        return self._b.bridge.take_bytes()
