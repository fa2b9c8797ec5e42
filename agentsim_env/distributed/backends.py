"""How the coordinator reaches its shards: in this process (``LocalShards``, a thread each) or on Ray (``ray_backend``).

A backend runs one method on several shards at once. The shards meet each other at the exchange during the
call (``distributed.exchange``), so the calls run concurrently, and a shard that fails must leave the exchange at
once (else the others wait for it at the next barrier): the backend drops a failed shard from the exchange as
soon as it sees the failure, and answers, per shard, its reply or a :class:`Failure` (the shard died, missed
the deadline, or raised). It never raises for a shard that failed: the coordinator declares that shard offline
and goes on. An exception raised by the shard's own code counts as a failure too: the shard's state is unknown
after it, so it is dropped like a dead one and started anew at the next ``reset``; the exception travels in
the ``Failure`` (the coordinator logs its traceback, and chains it when no shard is left).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from agentsim_env.distributed.bridge import Bridge, Packed
from agentsim_env.distributed.exchange import LocalExchange
from agentsim_env.distributed.shard import Shard


@dataclass(frozen=True, slots=True)
class Failure:
    """A shard that did not answer: why (``"died: ..."``, ``"missed the ... deadline"`` or ``"raised ..."``).

    Attributes:
        reason: One line for ``env.shards`` and the log.
        error: The exception the shard's code raised (``None`` for a shard that died or was late).
    """

    reason: str
    error: BaseException | None = None


def raised(error: BaseException) -> Failure:
    """The failure of a shard whose code raised ``error``."""
    return Failure(f"raised {type(error).__name__}: {error}", error)


ShardFactory = Callable[[int, Any], Shard]
"""Builds shard ``k`` given the exchange's ``swap``."""


class LocalShards:
    """Shards in this process, each call on its own thread (debugging, tests, machines without Ray).

    Args:
        factory: Builds shard ``k`` (given its index and the swap function).
        n_shards: Number of shards K.
        bridge: The coordinator's routing.
    """

    def __init__(self, factory: ShardFactory, n_shards: int, bridge: Bridge) -> None:
        self.n_shards = int(n_shards)
        self.exchange = LocalExchange(bridge, self.n_shards)
        self._factory = factory
        self.shards: dict[int, Shard | None] = {k: factory(k, self.exchange.swap) for k in range(self.n_shards)}
        self.address = "local"

    def call(
        self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float, on_reply: Any = None
    ) -> dict[int, Packed | Failure]:
        """Run ``method`` on each named shard at once; a reply or a ``Failure`` per shard (``on_reply`` is not
        called: the replies are in this process as soon as the last shard is done)."""
        del on_reply
        out: dict[int, Packed | Failure] = {}
        threads: dict[int, threading.Thread] = {}

        def run(k: int, shard: Shard, args: tuple[Any, ...]) -> None:
            try:
                out[k] = getattr(shard, method)(*args)
            except BaseException as e:  # noqa: BLE001 - the shard's state is unknown now: drop it
                self.shards[k] = None
                self.exchange.drop(k)
                out[k] = raised(e)

        for k, args in calls.items():
            shard = self.shards.get(k)
            if shard is None:
                out[k] = Failure("died: the shard was stopped")
                self.exchange.drop(k)
                continue
            threads[k] = threading.Thread(target=run, args=(k, shard, args), daemon=True)
        for t in threads.values():
            t.start()
        late = _wait_all(threads, timeout_s, self.exchange.waiting)
        for k in late:  # dropped (the thread finishes on its own; its answer is thrown away)
            self.shards[k] = None
            self.exchange.drop(k)
        for k, t in threads.items():
            if k not in late:
                t.join(timeout_s)  # they were waiting for the late ones at the exchange: they finish now
        for k in late:
            out[k] = Failure(f"missed the {timeout_s:g} s deadline of {method}")
        return out

    def restart(self, index: int) -> None:
        """Build shard ``index`` anew."""
        self.shards[index] = self._factory(index, self.exchange.swap)
        self.exchange.revive(index)

    def kill(self, index: int) -> None:
        """Drop shard ``index`` (its next call answers a failure)."""
        self.shards[index] = None
        self.exchange.drop(index)

    def set_delay(self, index: int, delay_s: float) -> None:
        """Test hook: shard ``index`` sleeps ``delay_s`` in every call."""
        shard = self.shards[index]
        if shard is not None:
            shard.set_delay(delay_s)

    def set_owner(self, owner: Any) -> None:
        """The shard owning each strip (for the exchange's routing)."""
        self.exchange.set_owner(owner)

    def set_slot_owner(self, owner: Any) -> None:
        """The shard owning each slot (for routing bus messages)."""
        self.exchange.set_slot_owner(owner)

    def share_rows(
        self, n_slots: int, obs_dim: int, act_layout: tuple[tuple[str, int, str], ...], n_info: int = 0
    ) -> None:
        """Nothing to share: in-process shards get their actions and hand their rows over by reference."""
        del n_slots, obs_dim, act_layout, n_info

    def write_actions(self, k: int, slots: Any, parts: dict[str, Any]) -> int | None:
        """None: an in-process shard's call carries its actions by reference."""
        del k, slots, parts
        return None

    def reply_rows(self, k: int, reply: Packed) -> None:
        """Never called: in-process shards return their rows in the reply."""
        raise RuntimeError(f"shard {k} returns its rows in its reply, not {sorted(reply)}")

    def obs_rows(self, k: int, n: int) -> Any:
        """Never called: in-process shards return their rows in the reply."""
        raise RuntimeError(f"shard {k} returns its {n} observation rows in its reply")

    def obs_buffer(self, avoid: Any = None) -> Any:
        """None: in-process shards hand their rows over by reference (the driver copies them where they go)."""
        del avoid
        return None

    def full_index(self, out: Any) -> int:
        """-1: no array of every slot's row is shared with in-process shards."""
        del out
        return -1

    def retire(self, b: int) -> None:
        """Nothing to retire (no shared arrays)."""
        del b

    def exchange_bytes(self) -> dict[str, int]:
        """The bytes the exchange routed since the previous call, by phase."""
        return self.exchange.take_bytes()

    def close(self) -> None:
        """Drop every shard."""
        self.shards = dict.fromkeys(self.shards)


def _wait_all(threads: dict[int, threading.Thread], timeout_s: float, waiting: Callable[[], set[int]]) -> list[int]:
    """Wait until every thread ended or the deadline passed; the late shards (those not waiting at the exchange).

    A shard waiting at the exchange when the deadline passes waits for a late one: it is not late itself.
    """
    deadline = time.perf_counter() + timeout_s
    for t in threads.values():
        t.join(max(0.0, deadline - time.perf_counter()))
    alive = {k for k, t in threads.items() if t.is_alive()}
    if not alive:
        return []
    late = alive - waiting()
    return sorted(late or alive)  # all of them waiting: none can go on, so all are late
