"""The coordinator: steps the shards in lock step and runs the non-spatial stages over the gathered arrays.

It holds a whole-map ``World`` of the scenario (the "mirror"): the kinematics the shards send back each step,
the static scene, and everything that is not spatial: stage 1's comm part, the groups stage (heartbeats), the
bus and the overlay (the bridged bus: one bus for every shard's agents), the non-spatial sensors, and stage 9
(rewards, terminations, observations), all with the single-process code. So results do not depend on the split:
the spatial stages are exact on a shard whose halo holds everything its agents interact with, and every random
draw (placement, bus losses, sensor noise) is made once, here or identically everywhere, never per shard.

One step (see ``distributed.shard`` for the shard's side):

1. ``move`` on every shard; the kinematics go into the mirror; agents that crossed a strip edge are routed to
   their new shard; each shard's ghosts are the agents of other shards within its halo (from the mirror).
2. ``collide``: handed-over agents and ghosts in, collisions of own agents out (a contact across an edge is
   found by both shards, each reporting its own agent: it is counted once per agent, as in one process). The
   groups stage (heartbeat timeouts) runs here.
3. ``sense`` with every slot that went offline and the overlay frontier each shard can walk; the nearest
   neighbours and the hop's deliveries come back for the comms stage (which runs here), and the proximity rows
   for the observations. When collisions take nobody offline, calls 2 and 3 go as one (``collide_sense``).

Faults: every reply carries a heartbeat (shard, address, step, compute time) kept in ``shards``; a shard that
dies, misses the deadline or raises is declared offline at once: its agents go offline (they report
``terminations`` once), its strips pass to the nearest live shard, the rest goes on. ``reset`` restarts offline
shards. When no shard is left, the call raises a ``RuntimeError`` naming every shard's reason (chained to the
exception a shard raised, if any).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from agentsim_env.core.collisions import CollisionEvents
from agentsim_env.distributed.backends import Backend, Failure
from agentsim_env.distributed.flooding import ShardedOverlay
from agentsim_env.distributed.graph import GatheredGraph
from agentsim_env.distributed.partition import Strips
from agentsim_env.distributed.shard import Packed
from agentsim_env.scenarios.base import Scenario, StepResult, StepScores
from agentsim_env.sensors.proximity import ProximitySensor, ScanResult
from agentsim_env.sim import StepEvents, World

log = logging.getLogger("agentsim_env.distributed")
_NONE = np.zeros(0, dtype=np.int64)


@dataclass(slots=True)
class ShardInfo:
    """What the coordinator knows of one shard (the integrator's map of machines).

    Attributes:
        index: Shard index k.
        address: ``host:pid`` of its process (from its heartbeats).
        alive: Whether it still answers.
        last_answer: ``time.time()`` of its latest heartbeat.
        last_step: The simulation tick of its latest heartbeat.
        step_s: Seconds of its latest call (its exchanges included).
        wait_s: Seconds of that call spent at the exchange (waiting for the others, routing, transfers).
        reason: Why it went offline (empty while alive).
        restarts: How many times it was started anew.
    """

    index: int
    address: str = ""
    alive: bool = True
    last_answer: float = 0.0
    last_step: int = -1
    step_s: float = 0.0
    wait_s: float = 0.0
    reason: str = ""
    restarts: int = 0


@dataclass(slots=True)
class Traffic:
    """Bytes that crossed between coordinator and shards in the latest step, by kind."""

    actions: int = 0
    kinematics: int = 0
    handover: int = 0
    halo: int = 0
    readings: int = 0
    other: int = 0

    @property
    def total(self) -> int:
        """Every byte of the step."""
        return self.actions + self.kinematics + self.handover + self.halo + self.readings + self.other


def nbytes(obj: Any) -> int:
    """Bytes of the numpy arrays inside ``obj`` (dicts, lists, tuples; other values count 8)."""
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(nbytes(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(nbytes(v) for v in obj)
    return 8


class Coordinator:
    """Steps K shards in lock step over one world (see the module docstring).

    Args:
        scenario: The scenario (its config validated, its shardability checked by the caller).
        world: The coordinator's mirror world (``scenario.build(1)``).
        strips: The partition.
        backend: The shards.
        timeout_s: Deadline of every call, in seconds.
    """

    def __init__(
        self, scenario: Scenario, world: World, strips: Strips, backend: Backend, timeout_s: float
    ) -> None:
        self.scenario = scenario
        self.world = world
        self.strips = strips
        self.backend = backend
        self.timeout_s = float(timeout_s)
        self.shards = [ShardInfo(k) for k in range(backend.n_shards)]
        s = world.state.n_slots
        self.owner = np.full(s, -1, dtype=np.int64)
        self.graph: GatheredGraph | None = None
        if world.comms is not None:
            self.graph = GatheredGraph(s, world.comms.cfg.nearest_range)
            world.comms.graph = self.graph  # type: ignore[assignment]
            world.comms.overlay = ShardedOverlay.like(world.comms.overlay)
            self._range0 = world.comms.overlay.link_range.copy()
        # collisions that take nobody offline let the groups stage run first and calls 2 and 3 go as one
        self._fused = not (world.config.collisions and world.config.collision_ends_agent)
        self._spatial = [x for x in world.sensors if isinstance(x, ProximitySensor)]
        self._others = [x for x in world.sensors if not isinstance(x, ProximitySensor)]
        n_rays = {x.name: x.n_rays for x in self._spatial}
        world.readings.update({name: ScanResult.empty(s, k) for name, k in n_rays.items()})
        self._ended = _NONE
        self._objects: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.lost = _NONE
        self.traffic = Traffic()

    # ------------------------------------------------------------------ faults
    @property
    def alive(self) -> np.ndarray:
        """``(K,)`` bool: the shards still answering."""
        return np.array([i.alive for i in self.shards], dtype=bool)

    def _declare_offline(self, k: int, failure: Failure) -> None:
        info = self.shards[k]
        if not info.alive:
            return
        info.alive, info.reason = False, failure.reason
        slots = np.flatnonzero(self.owner == k)
        self.owner[slots] = -1
        self.world.set_offline(slots)
        self.lost = np.union1d(self.lost, slots)
        if not self.alive.any():
            reasons = "; ".join(f"shard {i.index}: {i.reason}" for i in self.shards)
            raise RuntimeError(f"every shard is offline ({reasons}): the simulation cannot go on (reset() restarts "
                               f"them)") from failure.error  # fmt: skip
        self.strips.reassign(k, self.alive)
        # a shard that raised: its traceback goes with the warning (a bug shows where it is)
        log.warning("shard %d (%s) is offline: %s; its %d agents terminate, the simulation goes on",
                    k, info.address, failure.reason, slots.size, exc_info=failure.error)  # fmt: skip

    def _call(self, method: str, calls: dict[int, tuple[Any, ...]]) -> dict[int, Packed]:
        """Run ``method`` on the live shards; declare the ones that fail offline; the answers of the others."""
        calls = {k: a for k, a in calls.items() if self.shards[k].alive}
        replies = self.backend.call(method, calls, self.timeout_s)
        out: dict[int, Packed] = {}
        now = time.time()
        for k, r in replies.items():
            if isinstance(r, Failure):
                self._declare_offline(k, r)
                continue
            beat, info = r["beat"], self.shards[k]
            info.address, info.last_answer, info.last_step = beat["address"], now, beat["step"]
            info.step_s = (
                beat["compute_s"] if method in ("move", "reset") else info.step_s + beat["compute_s"]
            )
            out[k] = r
        return out

    def restart_offline(self) -> None:
        """Start every offline shard anew and give each its strips back (before an episode)."""
        for info in self.shards:
            if not info.alive:
                self.backend.restart(info.index)
                info.alive, info.reason = True, ""
                info.restarts += 1
                log.info("shard %d restarted", info.index)
        self.strips.owner = np.arange(self.strips.n_strips, dtype=np.int64)

    # ------------------------------------------------------------------ scene
    def add_objects(self, kind: np.ndarray, centre: np.ndarray, half: np.ndarray) -> None:
        """Add static objects to the world now; every shard gets them before the next step's motion."""
        self.world.scene.add(kind, centre, half, 0)
        sc = self.world.scene
        k = np.atleast_2d(np.asarray(centre)).shape[0]
        self._objects.append((sc.kind[-k:].copy(), sc.centre[-k:].copy(), sc.half[-k:].copy()))

    # ------------------------------------------------------------------ gathering
    def _take_rows(self, replies: dict[int, Packed]) -> None:
        """The proximity rows and the range-graph rows of every reply into the mirror."""
        world = self.world
        if self.graph is not None:
            self.graph.clear()
        for r in replies.values():
            slots = r["slots"]
            for sensor in self._spatial:
                scan = world.readings[sensor.name]
                scan.distance[slots] = r[f"{sensor.name}.distance"]
                scan.hit_kind[slots] = r[f"{sensor.name}.hit_kind"]
                if f"{sensor.name}.hit_id" in r:
                    scan.hit_id[slots] = r[f"{sensor.name}.hit_id"]
            if self.graph is not None:
                self.graph.put(slots, r["nearest"])
        if self.graph is not None and any("ov.slot" in r for r in replies.values()):
            got = [r for r in replies.values() if "ov.slot" in r]
            overlay: ShardedOverlay = world.comms.overlay  # type: ignore[union-attr, assignment]
            overlay.put(np.concatenate([r["ov.slot"] for r in got]), np.concatenate([r["ov.flood"] for r in got]),
                        sum(int(r["ov.links"]) for r in got))  # fmt: skip

    def _sense_others(self, fresh: bool) -> None:
        ctx = self.world.context()
        if fresh:
            ctx.fresh = np.zeros(1, dtype=np.int64)
        for sensor in self._others:
            self.world.readings[sensor.name] = sensor.step(ctx)

    def _hop_for(self, k: int, ghosts: np.ndarray) -> Packed | None:
        """What shard ``k`` needs for this step's overlay hop (``None`` when no flood spreads)."""
        comms = self.world.comms
        if comms is None or not comms.overlay.frontier_size:
            return None
        overlay: ShardedOverlay = comms.overlay  # type: ignore[assignment]
        active, fr_f, fr_u, new = overlay.hop_plan()
        mine = self.owner[fr_u] == k
        if ghosts.size:
            mine |= np.isin(fr_u, ghosts)
        return {
            "active": active,
            "started": fr_f[new],
            "origin": fr_u[new],
            "fr_f": fr_f[mine],
            "fr_u": fr_u[mine],
        }

    def _link_range(self) -> np.ndarray | None:
        comms = self.world.comms
        if comms is None:
            return None
        rng = comms.overlay.link_range
        if rng.max(initial=0.0) > self.strips.halo:
            raise ValueError(f"the overlay range {rng.max():g} m is wider than the shards' halo of "
                             f"{self.strips.halo:g} m: set the range before make(), or use one shard")  # fmt: skip
        return None if np.array_equal(rng, self._range0) else rng.copy()

    # ------------------------------------------------------------------ episode
    def reset(self, seed: np.random.SeedSequence) -> None:
        """Start the episode of ``seed`` on the mirror and on every shard (offline shards are restarted first)."""
        self.restart_offline()
        world, sc = self.world, self.scenario
        placement = world.reset_world(0, seed)
        sc.reset_world(world, 0, placement)
        self._ended, self._objects, self.lost = _NONE, [], _NONE
        self.owner[:] = -1
        replies = self._call("reset", {k: (seed, self.strips.owner) for k in range(len(self.shards))})
        for k, r in replies.items():
            self.owner[r["slots"]] = k
        if not self.alive.all():  # a shard that failed its reset loses its agents at once
            self.lost = np.flatnonzero(world.state.online & (self.owner < 0))
            world.set_offline(self.lost)
        self._take_rows(replies)
        self._sense_others(fresh=True)

    # ------------------------------------------------------------------ step
    def step(self, parts: dict[str, np.ndarray], acting: np.ndarray) -> tuple[StepResult, np.ndarray]:
        """Stages 1-10 of one step over the shards (the distributed ``run_step``).

        Args:
            parts: Validated action parts ``(S, size)`` of every slot.
            acting: ``(S,)`` the live slots.

        Returns:
            The scenario's result and the slots that terminated (those of an offline shard included).
        """
        world, sc, st = self.world, self.scenario, self.world.state
        self.lost = _NONE
        tr = self.traffic = Traffic()
        link_range = self._link_range()
        if "comm" in parts:  # 1. the comm part: one bus for every shard (nearest from the shards' graphs)
            world.apply_comm(parts["comm"], acting)
        motion = {k: v for k, v in parts.items() if k != "comm"}
        calls: dict[int, tuple[Any, ...]] = {}
        for k in range(len(self.shards)):
            slots = np.flatnonzero(acting & (self.owner == k))
            calls[k] = (slots, {p: v[slots] for p, v in motion.items()}, self._ended, self._objects,
                        self.strips.owner)  # fmt: skip
            tr.actions += nbytes(calls[k][:2])
            tr.other += nbytes(calls[k][2:])
        self._objects = []
        moved = self._call("move", calls)  # 2-4 on the shards
        for r in moved.values():
            sl = r["slots"]
            st.pos[sl], st.vel[sl], st.heading[sl] = r["pos"], r["vel"], r["heading"]
            tr.kinematics += nbytes([sl, r["pos"], r["vel"], r["heading"]])
        live = np.flatnonzero(self.owner >= 0)
        x = st.pos[live, 0]
        self.owner[live] = self.strips.owner_of(x)
        arrivals = _route_arrivals(list(moved.values()), self.owner)
        calls = {}
        ghost_of: dict[int, np.ndarray] = {}
        for k in range(len(self.shards)):
            g = ghost_of[k] = self.strips.ghosts(x, live, k)
            calls[k] = (arrivals.get(k), g, st.pos[g])
            tr.handover += nbytes(calls[k][0]) if calls[k][0] is not None else 0
            tr.halo += nbytes(calls[k][1:])
        ctx = world.context()
        hit_ids = bool(world.hooks)  # the viewer and the recorder may read them; the observations do not
        if self._fused:  # collisions take nobody offline: the groups stage first, then one call
            timed_out, group_events = world.run_groups(ctx)  # 6 here
            offline = np.union1d(timed_out, self.lost)
            for k in range(len(self.shards)):
                sense = (offline, self._hop_for(k, ghost_of[k]), link_range, hit_ids)
                tr.other += nbytes(sense)
                calls[k] = (*calls[k], *sense)
            # 5 and 8 (with the range graph and the overlay hop) on the shards
            sensed = hit = self._call("collide_sense", calls)
            events = _merge_collisions(list(hit.values()))
            ctx.collisions = events
            went = _NONE
        else:
            hit = self._call("collide", calls)  # 5 on the shards
            events = _merge_collisions(list(hit.values()))
            ctx.collisions = events
            went = np.unique(events.agent) if len(events) else _NONE
            if went.size:
                world.set_offline(went)
            timed_out, group_events = world.run_groups(ctx)  # 6 here
            offline = np.union1d(np.union1d(went, timed_out), self.lost)
            calls = {
                k: (offline, self._hop_for(k, ghost_of[k]), link_range, hit_ids)
                for k in range(len(self.shards))
            }
            tr.other += sum(nbytes(c) for c in calls.values())
            sensed = self._call("sense", calls)  # 8 (and the range graph, the overlay hop) on the shards
        tr.readings += sum(nbytes(r) for r in sensed.values())
        self._take_rows(sensed)
        # drop the replies now: Ray frees their shared memory while the comms stage runs, not while the front end
        # allocates the observations (measured: fewer page-fault stalls there)
        del moved, hit, sensed, calls, arrivals
        comm_events = world.run_comms(ctx)  # 7 here
        self._sense_others(fresh=False)
        ev = StepEvents(events, went, timed_out, comm_events, group_events, None, world.readings)
        ev.lost = self.lost
        world.end_step(ev, hooks=False)
        res = sc.score(world, ev, acting)  # 9
        terminated = acting & (res.terminated | ~st.online)
        ended = np.flatnonzero(terminated)
        world.set_offline(ended)
        self.owner[ended] = -1
        self._ended = ended
        if world.hooks:  # 10
            ev.scores = StepScores(acting, res.rewards, terminated, res.info)
            world.run_hooks(ev)
        return res, terminated


def _route_arrivals(replies: list[Packed], owner: np.ndarray) -> dict[int, Packed]:
    """The agents handed over by every shard, with their rows and reads, grouped by their new shard."""
    parts: dict[int, list[Packed]] = {}
    for r in replies:
        out = r["out"]
        if not out.size:
            continue
        dest, rdest = owner[out], owner[r["r.slot"]]
        for d in np.unique(dest).tolist():
            sel, rsel = dest == d, rdest == d
            pack = {k: v[sel] for k, v in r.items() if k[:2] in ("a.", "m.")}
            pack.update({"out": out[sel], "r.flood": r["r.flood"][rsel], "r.slot": r["r.slot"][rsel]})
            parts.setdefault(int(d), []).append(pack)
    return {d: {key: np.concatenate([g[key] for g in got]) for key in got[0]} for d, got in parts.items()}


def _merge_collisions(replies: list[Packed]) -> CollisionEvents:
    """Every shard's collisions of its own agents, in slot order of the hit agent (the single-process order)."""
    if not replies:
        return CollisionEvents.empty()
    agent = np.concatenate([r["agent"] for r in replies])
    other = np.concatenate([r["other_agent"] for r in replies])
    obj = np.concatenate([r["obj"] for r in replies])
    order = np.argsort(agent, kind="stable")
    return CollisionEvents(agent[order], other[order], obj[order])
