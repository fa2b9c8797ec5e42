"""One shard of a distributed simulation: the agents of some strips of the map, plus the ghosts around them.

A shard holds a whole ``World`` of the scenario (full-length slot arrays, so a slot keeps its index everywhere)
and a replica of the static scene, but only its **own** agents and its **ghosts** (copies of the agents of other
shards within its halo, see ``distributed.partition``) are online in it: the spatial stages (motion, collisions,
the proximity scan, the comms range graph) therefore work on its part of the map only. Every other stage
(stage 1's comm part, groups, the bus and overlay deliveries, non-spatial sensors, scoring, observations) runs on
the coordinator, over the gathered arrays, with the single-process code.

A step is three calls, each answered with packed arrays and a heartbeat (``distributed.coordinator``):

1. ``move``: stage 1 (motion part) and stages 2-4 for the own agents; returns their new kinematics and the
   agents that crossed into another shard's strip (handed over with their whole motion state).
2. ``collide``: takes in the agents handed over to it and the step's ghosts, then runs stage 5; returns the
   collisions of its own agents.
3. ``sense``: takes the slots that went offline anywhere (collisions, heartbeat timeouts), then the range graph
   (each own agent's nearest neighbour), one overlay hop into the own agents and stage 8's proximity scan.

(``collide_sense`` is calls 2 and 3 in one, for collisions that take nobody offline.)

This module imports no Ray: ``distributed.ray_backend`` wraps a ``Shard`` in an actor; the local backend calls
it in process.
"""

from __future__ import annotations

import os
import socket
import time
from dataclasses import fields
from typing import Any

import numpy as np

from agentsim_env.core.pipeline import StepContext
from agentsim_env.distributed.flooding import ShardReaders
from agentsim_env.distributed.partition import Strips
from agentsim_env.motion import MotionState
from agentsim_env.scenarios.registry import make_scenario
from agentsim_env.sensors.proximity import ProximitySensor

#: AgentState fields that travel with an agent handed over to another shard (the rest is fixed per episode).
AGENT_FIELDS = ("pos", "vel", "heading", "radius", "sensor_range", "max_speed", "max_accel")
MOTION_FIELDS = tuple(f.name for f in fields(MotionState))

Packed = dict[str, Any]
"""A message between coordinator and shards: names to numpy arrays (and a few scalars)."""


class Shard:
    """The own agents of some strips and their ghosts, in a whole-map ``World`` of the scenario.

    Args:
        index: This shard's index k.
        name: Registered scenario name.
        config: The scenario's config fields (as given to ``make``).
        strips: The partition (strip edges, halo and the strips' owners).
        delay_s: Test hook: sleep this long in every call (a slow machine).
    """

    def __init__(
        self, index: int, name: str, config: dict[str, Any], strips: Strips, delay_s: float = 0.0
    ) -> None:
        self.index = int(index)
        self.scenario = make_scenario(name, **config)
        self.world = self.scenario.build(1)
        self.strips = strips
        self.delay_s = float(delay_s)
        s = self.world.state.n_slots
        self.own = np.zeros(s, dtype=bool)
        self.ghost = np.zeros(s, dtype=bool)
        self.address = f"{socket.gethostname()}:{os.getpid()}"
        self._ctx: StepContext | None = None
        self._scan = [x for x in self.world.sensors if isinstance(x, ProximitySensor)]
        self.readers = ShardReaders(s)

    # ------------------------------------------------------------------ helpers
    def _beat(self, t0: float) -> Packed:
        return {"shard": self.index, "address": self.address, "step": int(self.world.tick),
                "compute_s": time.perf_counter() - t0}  # fmt: skip

    def _pause(self) -> None:
        if self.delay_s > 0:
            time.sleep(self.delay_s)

    def set_delay(self, delay_s: float) -> None:
        """Test hook: sleep ``delay_s`` seconds in every later call (0: none)."""
        self.delay_s = float(delay_s)

    def _set_online(self) -> None:
        st = self.world.state
        st.online[:] = False
        st.online[self.own | self.ghost] = True

    def _sense(
        self, ctx: StepContext, ov: Packed | None, link_range: np.ndarray | None, hit_ids: bool = True
    ) -> Packed:
        """Range graph, one overlay hop into the own agents and the proximity scan; the own agents' rows."""
        world, st = self.world, self.world.state
        mine = np.flatnonzero(self.own)
        out: Packed = {"slots": mine}
        if world.comms is not None:
            comms = world.comms
            if link_range is not None:
                comms.overlay.set_range(link_range)
            walk = ov is not None and ov["fr_u"].size > 0
            comms.graph.set_grid(ctx.grid, st.pos, st.online, st.world_id, comms.overlay.link_range, walk)
            out["nearest"] = comms.graph.nearest()[mine].copy()
            if ov is not None:
                s = st.n_slots
                links = comms.graph.links(comms.overlay.link_range) if walk else (
                    np.zeros(s, np.int64), np.zeros(s, np.int64), np.zeros(0, np.int64))  # fmt: skip
                v, f, e = self.readers.hop(links, self.own, ov["active"], ov["started"], ov["origin"], ov["fr_f"],
                                           ov["fr_u"])  # fmt: skip
                out["ov.slot"], out["ov.flood"], out["ov.links"] = v, f, e
        readings = {}
        for sensor in self._scan:
            readings[sensor.name] = sensor.step(ctx)
        world.readings.update(readings)
        for name, scan in readings.items():
            out[f"{name}.distance"] = scan.distance[mine]
            out[f"{name}.hit_kind"] = scan.hit_kind[mine]
            if hit_ids:
                out[f"{name}.hit_id"] = scan.hit_id[mine]
        return out

    # ------------------------------------------------------------------ episode
    def reset(self, seed: np.random.SeedSequence, owner: np.ndarray) -> Packed:
        """Start the episode of ``seed`` exactly as a single process does, then keep this shard's part online.

        Args:
            seed: The episode's seed sequence (the same on every shard and on the coordinator).
            owner: ``(K,)`` the shard owning each strip.

        Returns:
            The own slots with their range-graph and proximity rows, and a heartbeat.
        """
        t0 = time.perf_counter()
        self._pause()
        world, st = self.world, self.world.state
        placement = world.reset_world(0, seed)
        self.scenario.reset_world(world, 0, placement)
        self.readers.reset()
        self.strips.owner = np.asarray(owner, dtype=np.int64).copy()
        alive = st.online.copy()
        slots = np.flatnonzero(alive)
        x = st.pos[slots, 0]
        self.own[:] = False
        self.own[slots[self.strips.owner_of(x) == self.index]] = True
        self.ghost[:] = False
        self.ghost[self.strips.ghosts(x, slots, self.index)] = True
        self._set_online()
        if world.physics is not None:
            world.physics.sync(st, world.scene)
        ctx = world.context()
        world.regrid(ctx)
        out = self._sense(ctx, None, None)
        out["beat"] = self._beat(t0)
        return out

    # ------------------------------------------------------------------ step, call 1
    def move(
        self,
        slots: np.ndarray,
        parts: dict[str, np.ndarray],
        offline: np.ndarray,
        objects: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        owner: np.ndarray,
    ) -> Packed:
        """Stage 1 (motion part) and stages 2-4 for the own agents.

        Args:
            slots: The own slots that act this step (sorted).
            parts: Their action parts other than ``comm`` (rows in the order of ``slots``).
            offline: Slots that ended at the previous step (they leave the shard).
            objects: Static objects added since the previous step, ``(kind, centre, half)`` each.
            owner: ``(K,)`` the shard owning each strip (changes when a shard went offline).

        Returns:
            ``slots`` / ``pos`` / ``vel`` / ``heading`` of every own agent after the motion, the agents handed
            over (``out`` slots with their ``AGENT_FIELDS`` and ``MOTION_FIELDS`` rows) and a heartbeat.
        """
        t0 = time.perf_counter()
        self._pause()
        world, st, sc = self.world, self.world.state, self.scenario
        self.strips.owner = np.asarray(owner, dtype=np.int64).copy()
        for kind, centre, half in objects:
            world.scene.add(kind, centre, half, 0)
        if offline.size:
            self.own[offline] = False
            world.set_offline(offline)
        self.ghost[:] = False  # ghosts come fresh with every step's second call
        self._set_online()
        s = st.n_slots
        acting = np.zeros(s, dtype=bool)
        acting[slots] = True
        full = {}
        for k, rows in parts.items():
            a = np.zeros((s, rows.shape[1]), dtype=rows.dtype)
            a[slots] = rows
            full[k] = a
        sc.apply_actions(world, full, acting)
        ctx = world.context()
        self._ctx = ctx
        world.run_motion(ctx)
        mine = np.flatnonzero(self.own)
        out: Packed = {"slots": mine, "pos": st.pos[mine], "vel": st.vel[mine], "heading": st.heading[mine]}
        leave = mine[self.strips.owner_of(st.pos[mine, 0]) != self.index]
        out["out"] = leave
        for f in AGENT_FIELDS:
            out[f"a.{f}"] = getattr(st, f)[leave]
        for f in MOTION_FIELDS:
            out[f"m.{f}"] = getattr(world.motion, f)[leave]
        if (
            leave.size
        ):  # their reads of the floods go with them (a scan of the reader lists: only when needed)
            gone = np.zeros(s, dtype=bool)
            gone[leave] = True
            out["r.flood"], out["r.slot"] = self.readers.take_leaving(gone)
        else:
            out["r.flood"] = out["r.slot"] = np.zeros(0, dtype=np.int64)
        self.own[leave] = False
        st.online[leave] = False
        out["beat"] = self._beat(t0)
        return out

    # ------------------------------------------------------------------ step, call 2
    def collide(self, arrivals: Packed | None, ghost_slots: np.ndarray, ghost_pos: np.ndarray) -> Packed:
        """Take in the agents handed over and the step's ghosts, then stage 5 for the own agents.

        Args:
            arrivals: Agents handed over to this shard (``out`` slots and their rows, as ``move`` packs them),
                or ``None``.
            ghost_slots: Slots of the ghosts (agents of other shards within the halo).
            ghost_pos: Their positions after this step's motion.

        Returns:
            The collision events whose hit agent is one of the own agents, and a heartbeat.
        """
        t0 = time.perf_counter()
        self._pause()
        world, st = self.world, self.world.state
        if arrivals is not None and arrivals["out"].size:
            new = arrivals["out"]
            for f in AGENT_FIELDS:
                getattr(st, f)[new] = arrivals[f"a.{f}"]
            for f in MOTION_FIELDS:
                getattr(world.motion, f)[new] = arrivals[f"m.{f}"]
            self.own[new] = True
            self.readers.add(arrivals["r.flood"], arrivals["r.slot"])
        self.ghost[:] = False
        self.ghost[ghost_slots] = True
        st.pos[ghost_slots] = ghost_pos
        self._set_online()
        ctx = self._ctx
        assert ctx is not None, "move() must come first"
        events, _ = world.run_collisions(ctx)
        keep = self.own[events.agent]
        return {"agent": events.agent[keep], "other_agent": events.other_agent[keep], "obj": events.obj[keep],
                "beat": self._beat(t0)}  # fmt: skip

    # ------------------------------------------------------------------ step, call 3
    def sense(
        self, offline: np.ndarray, ov: Packed | None, link_range: np.ndarray | None, hit_ids: bool = True
    ) -> Packed:
        """Take the slots that went offline this step anywhere, then the range graph, the hop and the scan.

        Args:
            offline: Slots taken offline this step (collisions found by any shard, heartbeat timeouts).
            ov: The overlay's hop (``None`` when no flood spreads): ``active`` floods, the ``started`` ones and
                their ``origin``, and the frontier entries this shard can walk (``fr_f``, ``fr_u``).
            link_range: The overlay's per-slot range when it is no longer uniform, else ``None``.
            hit_ids: Send the scan's hit ids too (the observations do not read them; the viewer does).

        Returns:
            The own slots with their nearest neighbour, the hop's deliveries to own slots (``ov.slot``,
            ``ov.flood``) and links walked (``ov.links``), the scan rows, and a heartbeat.
        """
        t0 = time.perf_counter()
        self._pause()
        world = self.world
        ctx = self._ctx
        assert ctx is not None, "move() must come first"
        if offline.size:
            world.set_offline(offline)
            self.ghost[offline] = False
            world.regrid(ctx)
        out = self._sense(ctx, ov, link_range, hit_ids)
        world.step_count += 1
        world.tick += 1
        self._ctx = None
        out["beat"] = self._beat(t0)
        return out

    # ------------------------------------------------------------------ step, calls 2 and 3 in one
    def collide_sense(
        self,
        arrivals: Packed | None,
        ghost_slots: np.ndarray,
        ghost_pos: np.ndarray,
        offline: np.ndarray,
        ov: Packed | None,
        link_range: np.ndarray | None,
        hit_ids: bool = True,
    ) -> Packed:
        """``collide`` then ``sense`` in one call, when collisions take no agent offline (the coordinator then
        knows every slot that goes offline before the collisions: the heartbeat timeouts)."""
        t0 = time.perf_counter()
        out = self.collide(arrivals, ghost_slots, ghost_pos)
        out.update(self.sense(offline, ov, link_range, hit_ids))
        out["beat"]["compute_s"] = time.perf_counter() - t0
        return out
