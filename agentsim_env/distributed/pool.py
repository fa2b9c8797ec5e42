"""Workers that step themselves, reached in process (``LocalPool``: one thread each) or on Ray (``ray_pool``).

A pool runs one method on several workers at once. The workers meet each other at the exchange during the call,
so the calls must run concurrently, and a worker that fails must leave the exchange at once (else the others
wait for it at the next barrier): the pool drops a failed worker from the exchange as soon as it sees the
failure, and answers, per worker, its reply or a ``backends.Failure``. It never raises for a worker that failed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from agentsim_env.distributed.backends import Failure, raised
from agentsim_env.distributed.bridge import Bridge, Packed
from agentsim_env.distributed.exchange import LocalExchange
from agentsim_env.distributed.worker import Worker

WorkerFactory = Callable[[int, Any], Worker]
"""Builds worker ``k`` given the exchange's ``swap``."""


class LocalPool:
    """Workers in this process, each call on its own thread (debugging, tests, machines without Ray).

    Args:
        factory: Builds worker ``k`` (given its index and the swap function).
        n_shards: Number of workers K.
        bridge: The coordinator's routing.
    """

    def __init__(self, factory: WorkerFactory, n_shards: int, bridge: Bridge) -> None:
        self.n_shards = int(n_shards)
        self.exchange = LocalExchange(bridge, self.n_shards)
        self._factory = factory
        self.shards: dict[int, Worker | None] = {k: factory(k, self.exchange.swap) for k in range(self.n_shards)}
        self.address = "local"

    def call(self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float) -> dict[int, Packed | Failure]:
        """Run ``method`` on each named worker at once; a reply or a ``Failure`` per worker."""
        out: dict[int, Packed | Failure] = {}
        threads: dict[int, threading.Thread] = {}

        def run(k: int, worker: Worker, args: tuple[Any, ...]) -> None:
            try:
                out[k] = getattr(worker, method)(*args)
            except BaseException as e:  # noqa: BLE001 - the worker's state is unknown now: drop it
                self.shards[k] = None
                self.exchange.drop(k)
                out[k] = raised(e)

        for k, args in calls.items():
            worker = self.shards.get(k)
            if worker is None:
                out[k] = Failure("died: the shard was stopped")
                self.exchange.drop(k)
                continue
            threads[k] = threading.Thread(target=run, args=(k, worker, args), daemon=True)
        t0 = time.perf_counter()
        for t in threads.values():
            t.start()
        for k, t in threads.items():
            t.join(max(0.0, timeout_s - (time.perf_counter() - t0)))
            if t.is_alive():  # late: dropped (the thread finishes on its own; its answer is thrown away)
                self.shards[k] = None
                self.exchange.drop(k)
        for k in threads:
            if self.shards.get(k) is None and not isinstance(out.get(k), Failure):
                out[k] = Failure(f"missed the {timeout_s:g} s deadline of {method}")
        return out

    def restart(self, index: int) -> None:
        """Build worker ``index`` anew."""
        self.shards[index] = self._factory(index, self.exchange.swap)
        self.exchange.revive(index)

    def kill(self, index: int) -> None:
        """Drop worker ``index`` (its next call answers a failure)."""
        self.shards[index] = None
        self.exchange.drop(index)

    def set_delay(self, index: int, delay_s: float) -> None:
        """Test hook: worker ``index`` sleeps ``delay_s`` in every call."""
        worker = self.shards[index]
        if worker is not None:
            worker.set_delay(delay_s)

    def set_owner(self, owner: Any) -> None:
        """The shard owning each strip (for the exchange's routing)."""
        self.exchange.set_owner(owner)

    def set_slot_owner(self, owner: Any) -> None:
        """The shard owning each slot (for routing bus messages)."""
        self.exchange.set_slot_owner(owner)

    def close(self) -> None:
        """Drop every worker."""
        self.shards = dict.fromkeys(self.shards)
