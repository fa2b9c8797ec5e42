"""Shards as Ray actors (with ``ray_cluster``, the only modules of the project that import Ray: the ``ray`` extra).

``RayShards`` starts one actor per shard on a Ray cluster (a local one bound to 127.0.0.1 when no address is
given, started here, stopped when the last env using it closes; or the cluster at ``ray_address``) and the
exchange the shards meet at during a step (``distributed.exchange.ExchangeActor``, an asyncio actor using no CPU,
next to the driver; each shard posts to it over one TCP connection, ``distributed.wire``, with a token the driver
makes). A call runs on every shard at once; ``ray.wait`` bounds it by the deadline, so a step never
hangs on a dead or slow machine: a shard that misses it is killed and reported as a
:class:`~agentsim_env.distributed.backends.Failure`, as is one whose process died, and one whose code raised (its
actor is killed: its state is unknown after it); each is dropped from the exchange at once, so the others finish
their step.

When this process has already called ``ray.init`` (a test's cluster, a trainer's), the shards join that cluster
and ``ray_address`` is not used.

The cluster itself (joining or starting one, loopback binding, placement on nodes) is ``ray_cluster``'s.
"""

from __future__ import annotations

import logging
import secrets
import time
from typing import Any

import numpy as np

import agentsim_env.distributed.obs_shm as obs_shm
from agentsim_env.distributed.backends import Failure, raised
from agentsim_env.distributed.bridge import Bridge, Packed
from agentsim_env.distributed.exchange import ExchangeActor
from agentsim_env.distributed.obs_shm import ObsSegment, ObsWriter, RowReader, RowSegment, reply_layouts
from agentsim_env.distributed.partition import Strips
from agentsim_env.distributed.ray_cluster import (
    EXCHANGE_WAIT_S,
    LOOPBACK,
    NODE_RESOURCE,
    STARTUP_TIMEOUT_S,
    OnNode,
    Placement,
    check_address,
    connect_driver,
    import_ray,
    join_cluster,
    leave_cluster,
    start_local_cluster,
)
from agentsim_env.distributed.shard import Shard as _Shard
from agentsim_env.distributed.wire import TOKEN_BYTES, WireClient

# the cluster's names that callers import from here
__all__ = [
    "NODE_RESOURCE",
    "RayShards",
    "Shard",
    "check_address",
    "connect_driver",
    "import_ray",
    "start_local_cluster",
]

log = logging.getLogger("agentsim_env.distributed")


class Shard(OnNode):
    """A ``Shard`` in a Ray actor, posting to the exchange over its TCP connection (``distributed.wire``); its
    address also names the Ray node it runs on."""

    def __init__(
        self,
        index: int,
        name: str,
        config: dict[str, Any],
        strips: Strips,
        wire: tuple[str, int, bytes],
        wait_s: float,
    ) -> None:
        host, port, token = wire
        self.wire = WireClient(host, port, token, index, wait_s)
        self.worker = _Shard(index, name, config, strips, self.wire.swap)
        self.obs: ObsWriter | None = None
        self.worker.address = f"{self.worker.address} on node {self.node()[:12]}"

    def attach_rows(
        self,
        node: str,
        obs: tuple[str, int, int, int],
        act: tuple[str, int, int, Any],
        reply: tuple[tuple[str, int, int, Any], tuple[str, int, int, Any]],
    ) -> bool:
        """Read the step API's actions from and write its observation rows and per-agent reply rows into region
        ``index`` of the driver's segments (``distributed.obs_shm``: ``obs`` = name, shards, slots, row length;
        ``act`` and each of ``reply`` = name, shards, slots, layout) when this actor runs on the driver's node
        ``node``; whether it does."""
        if node != self.node():
            return False
        k = self.worker.index
        for old in (self.obs, self.worker.act_in, *(self.worker.reply_out or ())):
            if old is not None:
                old.close()
        self.obs = ObsWriter(obs[0], k, *obs[1:])
        self.worker.obs_out, self.worker.obs_full = self.obs.array, self.obs.full
        self.worker.act_in = RowReader(act[0], k, act[1], act[2], tuple(tuple(p) for p in act[3]))
        acted, own = (RowReader(r[0], k, r[1], r[2], tuple(tuple(p) for p in r[3]), "reply") for r in reply)
        self.worker.reply_out = (acted, own)
        return True

    def reset(self, *args: Any) -> Packed:
        """``Shard.reset``."""
        return self.worker.reset(*args)

    def step(self, *args: Any) -> Packed:
        """``Shard.step``."""
        return self.worker.step(*args)

    def begin(self, *args: Any) -> Packed:
        """``Shard.begin``."""
        return self.worker.begin(*args)

    def act(self, *args: Any) -> Packed:
        """``Shard.act``."""
        return self.worker.act(*args)

    def finish(self) -> Packed:
        """``Shard.finish``."""
        return self.worker.finish()

    def send(self, *args: Any) -> Packed:
        """``Shard.send``."""
        return self.worker.send(*args)

    def assign_group(self, *args: Any) -> Packed:
        """``Shard.assign_group``."""
        return self.worker.assign_group(*args)

    def set_delay(self, delay_s: float) -> None:
        """``Shard.set_delay``."""
        self.worker.set_delay(delay_s)


class RayShards:
    """K worker actors and their exchange on a Ray cluster.

    Args:
        name: Scenario name.
        config: The scenario's config fields.
        strips: The partition.
        n_shards: Number of workers K.
        address: Cluster address, or ``None`` for a local cluster on 127.0.0.1.
        bridge: The routing the exchange runs.
        spread: Place the workers on different nodes (``ray_cluster.Placement``); ``None``: unless the cluster
            is the local one this process started.
    """

    def __init__(
        self,
        name: str,
        config: dict[str, Any],
        strips: Strips,
        n_shards: int,
        address: str | None,
        bridge: Bridge,
        spread: bool | None = None,
    ) -> None:
        ray = import_ray()
        self.n_shards = int(n_shards)
        self._ray = ray
        self._own = join_cluster(ray, address, self.n_shards)
        self._cls = ray.remote(num_cpus=1 if address is not None else 0, max_restarts=0)(Shard)
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
        self.exchange = (
            ray.remote(num_cpus=0, max_restarts=0)(ExchangeActor)
            .options(scheduling_strategy=here)
            .remote(bridge, self.n_shards, EXCHANGE_WAIT_S)
        )  # next to the driver
        # the barriers' data path (``distributed.wire``): on loopback for the local cluster, else on the driver
        # node's address, where Ray's own ports are
        host = LOOPBACK if self._own else str(ray.util.get_node_ip_address())
        token = secrets.token_bytes(TOKEN_BYTES)
        self.wire = (host, int(ray.get(self.exchange.serve.remote(host, token))), token)
        self.placement = Placement(ray, not self._own if spread is None else bool(spread))
        self._args = (name, config, strips)
        self.actors: dict[int, Any] = {k: self._start(k) for k in range(self.n_shards)}
        self.address = address or "local cluster on 127.0.0.1"
        self.obs_segment: ObsSegment | None = None
        self.act_segment: RowSegment | None = None
        self.reply_segments: tuple[RowSegment, RowSegment] | None = None
        self._shm_warned = False
        self.shared: dict[int, bool] = {}
        """Which workers take their actions from ``act_segment`` and write their observation rows into
        ``obs_segment`` (those on the driver's node)."""

    def share_rows(
        self, n_slots: int, obs_dim: int, act_layout: tuple[tuple[str, int, str], ...], n_info: int = 0
    ) -> None:
        """Workers on the driver's node exchange the step API's actions, observation rows and per-agent reply
        rows (``n_info``: the scenario's info keys) through shared-memory segments (``distributed.obs_shm``)
        instead of Ray's object store; the others keep Ray."""
        need = obs_shm.rows_bytes(n_slots, obs_dim, act_layout, n_info)
        room = obs_shm.shm_room()
        if self.obs_segment is None and room is not None and 2 * need > room:  # a full /dev/shm kills its writer
            if not self._shm_warned:
                log.warning(
                    "%s holds %d MB free, the step API's shared rows need about %d MB (twice that kept free): "
                    "their rows go through Ray's object store instead (slower; a larger /dev/shm, e.g. docker "
                    "--shm-size, brings them back)",
                    obs_shm.SHM_DIR,
                    room >> 20,
                    need >> 20,
                )
                self._shm_warned = True
            self.shared = dict.fromkeys(self.actors, False)
            return
        if self.obs_segment is None or self.act_segment is None or self.reply_segments is None:
            self._close_segments()
            self.obs_segment = ObsSegment(self.n_shards, n_slots, obs_dim)
            self.act_segment = RowSegment(self.n_shards, n_slots, act_layout)
            acted, own = reply_layouts(n_info)
            self.reply_segments = (
                RowSegment(self.n_shards, n_slots, acted, "acted"),
                RowSegment(self.n_shards, n_slots, own, "own"),
            )
        for k in self.actors:
            if k not in self.shared:
                self._attach_rows(k)

    def _close_segments(self) -> None:
        for seg in (self.obs_segment, self.act_segment, *(self.reply_segments or ())):
            if seg is not None:
                seg.close()
        self.obs_segment, self.act_segment, self.reply_segments = None, None, None

    def _attach_rows(self, k: int) -> None:
        obs, act, reply = self.obs_segment, self.act_segment, self.reply_segments
        assert obs is not None and act is not None and reply is not None
        here = str(self._ray.get_runtime_context().get_node_id())
        ref = self.actors[k].attach_rows.remote(
            here,
            (obs.name, obs.n_shards, obs.n_slots, obs.obs_dim),
            (act.name, act.n_shards, act.n_slots, act.layout),
            tuple((r.name, r.n_shards, r.n_slots, r.layout) for r in reply),
        )
        try:
            self.shared[k] = bool(self._ray.get(ref, timeout=STARTUP_TIMEOUT_S))
        except Exception:  # a worker that cannot map them uses Ray (a dead one fails its next call)
            self.shared[k] = False

    def write_actions(self, k: int, slots: Any, parts: dict[str, Any]) -> int | None:
        """Worker ``k``'s acting slots and action rows into its region of the action segment: their count, or
        None when the worker does not share (its call then carries them)."""
        if self.act_segment is None or not self.shared.get(k):
            return None
        return self.act_segment.write(k, slots, parts)

    def reply_rows(self, k: int, reply: Packed) -> None:
        """Worker ``k``'s per-agent reply rows, written into its regions of the reply segments, into ``reply``
        as the keys a reply through Ray carries (views: read them before the worker's next call)."""
        if self.reply_segments is None or not self.shared.get(k):
            raise RuntimeError(f"shard {k} does not share its reply rows")
        acted, own = self.reply_segments
        slots, cols = acted.rows(k, int(reply.pop("rows_n")))
        reply["slots"], reply["rewards"], reply["terminated"] = slots, cols["rewards"][:, 0], cols["terminated"][:, 0]
        reply["info"] = {
            key: cols[f"info{i}"][:, 0].astype(np.dtype(dt), copy=False)
            for i, (key, dt) in enumerate(reply.pop("info_dtypes"))
        }
        mine, kin = own.rows(k, int(reply.pop("own_n")))
        reply["own"] = mine
        if reply.pop("own_kin"):
            reply["pos"], reply["vel"] = kin["pos"], kin["vel"]
            reply["heading"], reply["online"] = kin["heading"][:, 0], kin["online"][:, 0]

    def obs_rows(self, k: int, n: int) -> Any:
        """The ``n`` observation rows worker ``k`` wrote into the segment in its latest call (a view)."""
        if self.obs_segment is None or not self.shared.get(k):
            raise RuntimeError(f"shard {k} does not share its observation rows")
        return self.obs_segment.rows(k, n)

    def obs_buffer(self, avoid: Any = None) -> Any:
        """An array of every slot's observation row in the observation segment that no one else holds and that is
        not ``avoid`` (``ObsSegment.free_full``): a step given it has the workers beside the driver write their
        rows straight there; None when there is none."""
        return None if self.obs_segment is None else self.obs_segment.free_full(avoid)

    def full_index(self, out: Any) -> int:
        """Which of the segment's full arrays ``out`` is (-1: none)."""
        return -1 if self.obs_segment is None else self.obs_segment.full_index(out)

    def retire(self, b: int) -> None:
        """Never hand full array ``b`` out again (a worker lost while it may have been writing into it)."""
        if self.obs_segment is not None:
            self.obs_segment.retired.add(int(b))

    def _start(self, k: int) -> Any:
        name, config, strips = self._args
        return self.placement.start(k, self._cls, k, name, config, strips, self.wire, EXCHANGE_WAIT_S + 30.0)

    def node_of(self, k: int) -> str:
        """The id (hex) of the Ray node worker ``k`` runs on (or last ran on); ``""`` when it never said."""
        return self.placement.node_of(k)

    def _drop(self, k: int) -> None:
        self._ray.get(self.exchange.drop.remote(k))

    def call(
        self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float, on_reply: Any = None
    ) -> dict[int, Packed | Failure]:
        """Run ``method`` on every named worker at once; a reply or a ``Failure`` per worker. ``on_reply(k, reply)``
        is called with each reply (not with failures) as it comes in, while slower workers still run."""
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
                got = out[refs[ref]] = self._answer(ref, refs[ref])
                if on_reply is not None and not isinstance(got, Failure):
                    on_reply(refs[ref], got)
        if pending:  # late: the ones not waiting at the exchange are killed and dropped; the others then finish
            waiting = ray.get(self.exchange.waiting.remote())
            late = [ref for ref in pending if refs[ref] not in waiting] or pending
            for ref in late:
                k = refs[ref]
                self.placement.failed(k)
                self.kill(k)
                out[k] = Failure(f"missed the {timeout_s:g} s deadline of {method}")
            rest = [ref for ref in pending if ref not in late]
            if rest:
                out.update(self.call_rest(rest, refs, timeout_s))
        return out

    def _answer(self, ref: Any, k: int) -> Packed | Failure:
        """Worker ``k``'s reply, or its failure (a dead one is dropped, one that raised is killed and dropped)."""
        ray = self._ray
        try:
            return dict(ray.get(ref))
        except ray.exceptions.RayActorError as e:
            self.placement.failed(k)
            self._drop(k)
            return Failure(f"died: {type(e).__name__}")
        except ray.exceptions.RayTaskError as e:
            self.kill(k)
            return raised(e.cause if isinstance(e.cause, BaseException) else e)

    def call_rest(self, pending: list[Any], refs: dict[Any, int], timeout_s: float) -> dict[int, Packed | Failure]:
        """The answers of the calls that waited at the exchange for a late shard (one more deadline)."""
        ray, out = self._ray, {}
        done, late = ray.wait(pending, num_returns=len(pending), timeout=timeout_s)
        for ref in done:
            out[refs[ref]] = self._answer(ref, refs[ref])
        for ref in late:
            k = refs[ref]
            self.kill(k)
            out[k] = Failure(f"missed the {timeout_s:g} s deadline")
        return out

    def restart(self, index: int) -> None:
        """A new actor for worker ``index`` (the old one is killed if it still runs)."""
        self.kill(index)
        self.actors[index] = self._start(index)
        self._ray.get(self.exchange.revive.remote(index))
        if self.obs_segment is not None:
            self._attach_rows(index)

    def kill(self, index: int) -> None:
        """Kill worker ``index``'s actor at once and drop it from the exchange."""
        try:
            self._ray.kill(self.actors[index], no_restart=True)
        except Exception:  # already gone
            pass
        self.shared.pop(index, None)
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

    def exchange_bytes(self) -> dict[str, int]:
        """The bytes the exchange routed since the previous call, by phase."""
        return dict(self._ray.get(self.exchange.take_bytes.remote()))

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
        self._close_segments()
        self.shared = {}
        leave_cluster(self._ray, self._own)
        self._own = False
