"""Self-stepping workers as Ray actors, meeting at an exchange actor (see ``distributed.pool`` for the contract).

The cluster is joined or started as for ``ray_backend.RayShards`` (a local one bound to 127.0.0.1 by default).
The exchange (``distributed.exchange.ExchangeActor``, an asyncio actor using no CPU) runs next to the driver;
every worker calls it at its step's barriers. A worker that dies, raises or misses the deadline is dropped from
the exchange at once, so the others finish their step.
"""

from __future__ import annotations

import time
from typing import Any

from agentsim_env.distributed.backends import Failure, raised
from agentsim_env.distributed.bridge import Bridge, Packed
from agentsim_env.distributed.exchange import ExchangeActor
from agentsim_env.distributed.partition import Strips
from agentsim_env.distributed.ray_backend import STARTUP_TIMEOUT_S, import_ray, join_cluster, leave_cluster
from agentsim_env.distributed.worker import Worker


class WorkerActor:
    """A ``Worker`` in a Ray actor, its exchange reached through the exchange actor's handle."""

    def __init__(self, index: int, name: str, config: dict[str, Any], strips: Strips, exchange: Any) -> None:
        ray = import_ray()

        def swap(key: tuple[int, str], k: int, payload: Packed) -> Packed:
            return ray.get(exchange.swap.remote(key, k, payload))  # type: ignore[no-any-return]

        self.worker = Worker(index, name, config, strips, swap)

    def reset(self, *args: Any) -> Packed:
        """``Worker.reset``."""
        return self.worker.reset(*args)

    def step(self, *args: Any) -> Packed:
        """``Worker.step``."""
        return self.worker.step(*args)

    def begin(self, *args: Any) -> Packed:
        """``Worker.begin``."""
        return self.worker.begin(*args)

    def act(self, *args: Any) -> Packed:
        """``Worker.act``."""
        return self.worker.act(*args)

    def finish(self) -> Packed:
        """``Worker.finish``."""
        return self.worker.finish()

    def set_delay(self, delay_s: float) -> None:
        """``Worker.set_delay``."""
        self.worker.set_delay(delay_s)


class RayPool:
    """K worker actors and their exchange on a Ray cluster.

    Args:
        name: Scenario name.
        config: The scenario's config fields.
        strips: The partition.
        n_shards: Number of workers K.
        address: Cluster address, or ``None`` for a local cluster on 127.0.0.1.
        bridge: The routing the exchange runs.
    """

    def __init__(
        self, name: str, config: dict[str, Any], strips: Strips, n_shards: int, address: str | None, bridge: Bridge
    ) -> None:
        ray = import_ray()
        self.n_shards = int(n_shards)
        self._ray = ray
        self._own = join_cluster(ray, address, self.n_shards)
        self._cls = ray.remote(num_cpus=1 if address is not None else 0, max_restarts=0)(WorkerActor)
        self.exchange = ray.remote(num_cpus=0, max_restarts=0)(ExchangeActor).remote(bridge, self.n_shards)
        self._args = (name, config, strips)
        self.actors: dict[int, Any] = {k: self._start(k) for k in range(self.n_shards)}
        self.address = address or "local cluster on 127.0.0.1"

    def _start(self, k: int) -> Any:
        name, config, strips = self._args
        return self._cls.remote(k, name, config, strips, self.exchange)

    def _drop(self, k: int) -> None:
        self._ray.get(self.exchange.drop.remote(k))

    def call(self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float) -> dict[int, Packed | Failure]:
        """Run ``method`` on every named worker at once; a reply or a ``Failure`` per worker."""
        ray = self._ray
        if method == "reset":
            timeout_s = max(timeout_s, STARTUP_TIMEOUT_S)
        refs = {getattr(self.actors[k], method).remote(*args): k for k, args in calls.items()}
        out: dict[int, Packed | Failure] = {}
        pending = list(refs)
        deadline = time.monotonic() + timeout_s
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=max(0.0, deadline - time.monotonic()))
            if not ready:
                break
            for ref in ready:
                k = refs[ref]
                try:
                    out[k] = ray.get(ref)
                except ray.exceptions.RayActorError as e:
                    out[k] = Failure(f"died: {type(e).__name__}")
                    self._drop(k)
                except ray.exceptions.RayTaskError as e:
                    self.kill(k)
                    out[k] = raised(e.cause if isinstance(e.cause, BaseException) else e)
        for ref in pending:  # late: killed and dropped, so the others are not held at a barrier
            k = refs[ref]
            self.kill(k)
            out[k] = Failure(f"missed the {timeout_s:g} s deadline of {method}")
        return out

    def restart(self, index: int) -> None:
        """A new actor for worker ``index`` (the old one is killed if it still runs)."""
        self.kill(index)
        self.actors[index] = self._start(index)
        self._ray.get(self.exchange.revive.remote(index))

    def kill(self, index: int) -> None:
        """Kill worker ``index``'s actor at once and drop it from the exchange."""
        try:
            self._ray.kill(self.actors[index], no_restart=True)
        except Exception:  # already gone
            pass
        self._drop(index)

    def set_delay(self, index: int, delay_s: float) -> None:
        """Test hook: worker ``index`` sleeps ``delay_s`` in every call."""
        self._ray.get(self.actors[index].set_delay.remote(delay_s))

    def set_owner(self, owner: Any) -> None:
        """The shard owning each strip (for the exchange's routing)."""
        self._ray.get(self.exchange.set_owner.remote(owner))

    def set_slot_owner(self, owner: Any) -> None:
        """The shard owning each slot (for routing bus messages)."""
        self._ray.get(self.exchange.set_slot_owner.remote(owner))

    def close(self) -> None:
        """Kill every actor and the exchange; stop the local cluster when no other env uses it."""
        for k in list(self.actors):
            try:
                self._ray.kill(self.actors[k], no_restart=True)
            except Exception:  # already gone
                pass
        self.actors = {}
        try:
            self._ray.kill(self.exchange, no_restart=True)
        except Exception:  # already gone
            pass
        leave_cluster(self._ray, self._own)
        self._own = False
