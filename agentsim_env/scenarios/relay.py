"""relay: in each group one scout sees the group's target; the others reach it only through messages.

Agents (``agent_0`` ... ``agent_{N-1}``, N = ``n_agents`` = ``n_groups x group_size``, slot i in group
``i % n_groups``)
start strung out along a corridor (``length x corridor_width``): N start points form a chain along x with
gaps drawn from ``gap``, lateral offsets up to ``lateral_spread`` and altitudes in ``body.altitude``, taken by the
agents in a random order. Each episode draws one **scout** per group; the group's **target** (a ground
marker) lies ``target_offset`` metres from its scout. Only the scout perceives the target; the others'
``task`` part is zeros.

Why messages must relay: at the defaults the chain spans about 190 m while the bus reaches
``comms.max_range`` = 35 m, so about 4 in 5 non-scouts start beyond one bus hop of their scout (seeds 0-19);
the chain is connected for the overlay (consecutive points at most sqrt(22^2 + 16^2 + 6^2) = 28 m apart,
``comms.overlay_range`` = 35 m), so a flood with hop limit ``comms.max_hops`` = 8, relayed by agents of any
group, reaches most of it.

Observation (Dict; the flat Box concatenates the parts in this order):

| part  | shape     | content                                                                               |
|-------|-----------|---------------------------------------------------------------------------------------|
| self  | (9,)      | x, y in [-1, 1] over the map; altitude in [-1, 1] over the band; velocity / max_speed |
|       |           | (3); cos, sin heading; group code ``2 g / (G - 1) - 1`` (0 when G = 1)                |
| lidar | (K, 2)    | per ray: distance / range (1 = free), hit code / 3 (1/3 agent, 2/3 object, 1 ground)  |
| task  | (4,)      | scout: 1, (target - position) x, y / map diagonal, distance / diagonal; others: zeros |
| inbox | (M, 11+D) | received messages, newest first (layout in ``agentsim_env.comms.messages``)           |
| comms | (2,)      | messages received and dropped this step / M                                           |

Rays: ``sensing.n_azimuth`` azimuths (ray 0 along the heading) per ring of ``sensing.elevations_deg``
(default 12 x 1).

Action (Dict; the flat Box is ``motion`` then ``comm``), values in [-1, 1]:

| part   | shape  | content                                                                            |
|--------|--------|------------------------------------------------------------------------------------|
| motion | (3,)   | target velocity / max_speed (norm clipped to max_speed)                            |
| comm   | (3+D,) | channel, receiver, hop limit, payload (layout in ``agentsim_env.comms.stack``)     |

Reward (``RewardConfig``): task = progress toward the group's target (horizontal metres) plus
``arrival_bonus`` on arrival for non-scouts, 0 for scouts (they earn through the group share); collision
penalty; energy = speed^2 x dt; ``reward.message_cost`` per message sent.

Episode: a non-scout within ``arrival_radius`` of its target (horizontally) ends with success; a collision
ends an agent; a scout ends once none of its group's non-scouts is still live (all arrived or out); the rest
are truncated at ``max_steps``. ``RelayScenario.group_success`` scores an episode.

Version history: v0, first release.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from agentsim_env.scenarios.base import Scenario, SlotState, StepResult, slot
from agentsim_env.scenarios.placement import obstacle_layout
from agentsim_env.scenarios.relay_config import RELAY_COMMS, RelayConfig
from agentsim_env.scenarios.rewards import at_keys, compose_rewards, task_partials
from agentsim_env.sensors.proximity import ProximitySensor
from agentsim_env.sim import StepEvents, World, WorldConfig

__all__ = ["RELAY_COMMS", "SCENARIO", "RelayConfig", "RelayScenario"]


@dataclass(slots=True)
class RelaySlots(SlotState):
    """Per-slot state of ``relay``: the group's target, the scout flag, the last distance and arrival."""

    target: np.ndarray = slot((2,))
    scout: np.ndarray = slot(dtype=bool)
    prev_dist: np.ndarray = slot()
    arrived: np.ndarray = slot(dtype=bool)


class RelayScenario(Scenario[RelayConfig]):
    """Scouts see targets, members reach them through relayed messages; see the module docstring."""

    name = "relay"
    config_cls = RelayConfig
    version = 0
    agent_prefix = "agent"
    shardable = True
    test_configs = (
        {"n_groups": 2, "group_size": 3},
        {
            "n_groups": 2,
            "group_size": 2,
            "max_steps": 120,
            "comms": {"loss": 0.3, "latency": 2, "heartbeat_period": 5},
        },
        {"n_groups": 1, "n_agents": 3, "obstacle_density": 0.0, "comms": {"overlay_full": True}},
    )

    def make_world(self, n_worlds: int) -> World:
        """World sized for the corridor and the band; per-slot target, scout and arrival arrays."""
        c = self.config
        b = c.body
        wc = WorldConfig(
            bounds=(0.0, c.length, 0.0, c.corridor_width),
            z_range=(0.0, b.altitude[1] + 5.0),
            dt=c.dt,
            physics=c.physics,
            collisions=c.collisions,
            grid_cell=max(c.sensing.range / 2, 2.0),
        )
        world = World(wc, n_worlds, self.n_agents, sensors=[ProximitySensor(self.lidar)], comms=c.comms)
        st = world.state
        st.configure(
            radius=b.radius,
            sensor_range=c.sensing.range,
            max_speed=b.max_speed,
            max_accel=b.max_accel,
            n_groups=c.n_groups,
        )
        world.task = RelaySlots.allocate(st.n_slots)
        return world

    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        """New chain of start points, scouts, targets and obstacles for world ``w``."""
        c, st, t = self.config, world.state, world.task
        sl = st.slots_of_world(w)
        n, g_n, length, width = self.n_agents, c.n_groups, c.length, c.corridor_width
        gaps = rng.uniform(c.gap[0], c.gap[1], n - 1)
        # the slack is >= 0 in exact arithmetic (every gap <= gap[1]); max() absorbs the rounding of the sum
        x0 = c.margin + rng.uniform(0.0, max(length - 2.0 * c.margin - gaps.sum(), 0.0))
        chain = np.column_stack(
            [
                x0 + np.concatenate([[0.0], np.cumsum(gaps)]),
                width / 2.0 + rng.uniform(-c.lateral_spread, c.lateral_spread, n),
                rng.uniform(c.body.altitude[0], c.body.altitude[1], n),
            ]
        )
        st.pos[sl] = chain[rng.permutation(n)]
        st.vel[sl] = 0.0
        st.heading[sl] = rng.uniform(-np.pi, np.pi, n)
        st.online[sl] = True
        st.energy[sl] = 0.0
        scout_slot = np.arange(g_n) + g_n * rng.integers(0, int(c.group_size or 1), g_n)  # slot i is in group i % G
        ang = rng.uniform(-np.pi, np.pi, g_n)
        r = rng.uniform(c.target_offset[0], c.target_offset[1], g_n)
        tgt = st.pos[sl][scout_slot, :2] + r[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
        tgt = np.clip(tgt, [2.0, 2.0], [length - 2.0, width - 2.0])
        t.target[sl] = tgt[np.arange(n) % g_n]
        t.scout[sl] = False
        t.scout[sl[scout_slot]] = True
        t.prev_dist[sl] = np.linalg.norm(t.target[sl] - st.pos[sl, :2], axis=1)
        t.arrived[sl] = False
        world.remove_objects_of_world(w)
        n_obs = int(round(c.obstacle_density * length * width))
        kind, centre, half = obstacle_layout(
            rng,
            n_obs,
            (0.0, length, 0.0, width),
            c.obstacle_size,
            c.obstacle_height,
            np.vstack([chain[:, :2], tgt]),
            keep_clear_radius=max(c.body.radius + 2.0, c.arrival_radius + 1.0),
        )
        if kind.size:
            world.scene.add(kind, centre, half, w)

    def _task(self, world: World, acting: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distance to the target, arrivals and task values of this step (no state changed)."""
        c, st, t = self.config, world.state, world.task
        dist = np.linalg.norm(t.target - st.pos[:, :2], axis=1)
        member = acting & ~t.scout
        arrived = member & st.online & (dist <= c.arrival_radius)
        task = np.where(member, t.prev_dist - dist, 0.0) + c.arrival_bonus * arrived
        return dist, arrived, task

    def _key(self, world: World) -> np.ndarray:
        # group-major like rewards.group_keys; a group id outside the configured groups counts in the nearest one
        st, g_n = world.state, self.config.n_groups
        return np.clip(st.group, 0, g_n - 1).astype(np.int64) * world.n_worlds + st.world_id

    def group_partials(
        self, world: World, events: StepEvents, acting: np.ndarray, mine: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Per (world, group) over the slots in ``mine``: the members still live after this step (``pending``,
        for the scouts' end) and, with a group share, the fixed-point task sums."""
        c, st, t = self.config, world.state, world.task
        _, arrived, task = self._task(world, acting)
        pending = ~t.scout & st.online & ~(t.arrived | arrived) & mine
        size = world.n_worlds * c.n_groups
        out = {"pending": np.bincount(self._key(world)[pending], minlength=size).astype(np.int64)}
        if c.reward.group_share:
            out.update(
                task_partials(task, st.group, st.world_id, acting & mine, c.n_groups, world.n_worlds, world.threads)
            )
        return out

    def score(
        self,
        world: World,
        events: StepEvents,
        acting: np.ndarray,
        totals: dict[str, np.ndarray] | None = None,
    ) -> StepResult:
        """Progress and arrival of non-scouts, scouts' end, collisions, energy and messages -> rewards.

        ``totals``: the combined :meth:`group_partials` (``None``: computed here over every slot).
        """
        c, st, t = self.config, world.state, world.task
        if totals is None:
            totals = self.group_partials(world, events, acting, np.ones(st.n_slots, dtype=bool))
        dist, arrived, task = self._task(world, acting)
        np.copyto(t.prev_dist, dist)  # the state keeps its array (resets write it); dist goes out as info
        t.arrived |= arrived
        # a scout is done once no member of its (world, group) is still live
        scout_done = acting & t.scout & (at_keys(totals["pending"], self._key(world)) == 0)
        collided = np.zeros(st.n_slots)
        collided[events.went_offline] = 1.0
        effort = np.einsum("ij,ij->i", st.vel, st.vel) * world.config.dt
        st.energy += np.where(acting, effort, 0.0)
        assert world.comms is not None
        rewards = compose_rewards(
            c.reward,
            task,
            group=st.group,
            world=st.world_id,
            acting=acting,
            n_groups=c.n_groups,
            collided=collided,
            energy=effort,
            messages_sent=world.comms.sent,
            totals=totals if c.reward.group_share else None,
            n_worlds=world.n_worlds,
            threads=world.threads,
        )
        info = {
            "arrived": arrived.astype(np.int8),
            "collided": collided.astype(np.int8),
            "distance": dist,
            "scout": t.scout.astype(np.int8),
        }
        return StepResult(rewards, arrived | scout_done, info)

    def observe(self, world: World) -> dict[str, np.ndarray]:
        """self, lidar and task parts for every slot (see the module docstring)."""
        c, st, t = self.config, world.state, world.task
        lo, hi = c.body.altitude
        code = st.group / max(c.n_groups - 1, 1) * 2.0 - 1.0 if c.n_groups > 1 else np.zeros(st.n_slots)
        selfp = np.column_stack(
            [
                st.pos[:, 0] / c.length * 2 - 1,
                st.pos[:, 1] / c.corridor_width * 2 - 1,
                (st.pos[:, 2] - lo) / max(hi - lo, 1e-9) * 2 - 1,
                st.vel / c.body.max_speed,
                np.cos(st.heading),
                np.sin(st.heading),
                code,
            ]
        )
        scan = world.scan
        assert scan is not None
        diag = float(np.hypot(c.length, c.corridor_width))
        d = t.target - st.pos[:, :2]
        task = np.column_stack([np.ones(st.n_slots), d / diag, np.linalg.norm(d, axis=1) / diag])
        task[~t.scout] = 0.0  # only the scout perceives the target
        return {
            "self": np.clip(selfp, -1, 1).astype(np.float32),
            "lidar": world.sensors[0].observe(scan),
            "task": np.clip(task, -1, 1).astype(np.float32),
        }

    def state_extra(self, world: World, w: int) -> np.ndarray:
        """Scout flags, then each group's target / 100 m."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        t = world.task
        tgt = t.target[sl][: self.n_groups]
        return np.concatenate([t.scout[sl].astype(np.float64), tgt.ravel() / 100.0])

    def markers(self, world: World, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Targets as discs, one colour per group."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        g = np.arange(self.n_groups)
        rgb = np.column_stack([40 + 70 * (g % 3), 170 - 50 * (g % 2), 60 + 60 * ((g + 1) % 3)]).astype(np.uint8)
        return (
            world.task.target[sl][: self.n_groups].copy(),
            rgb,
            np.full(self.n_groups, self.config.arrival_radius),
        )

    def view_markers(self, world: World, w: int) -> list[dict[str, Any]]:
        """Each group's target, with the scout that sees it (``slot``)."""
        n = self.n_agents
        sl = slice(w * n, (w + 1) * n)
        t, names = world.task, self.agent_names()
        scouts = np.flatnonzero(t.scout[sl])
        out = []
        for s in scouts.tolist():
            g = s % self.n_groups  # slot i is in group i % n_groups
            x, y = t.target[sl][s].tolist()
            out.append(
                {
                    "kind": "target",
                    "pos": [round(x, 3), round(y, 3), 0.0],
                    "radius": round(float(self.config.arrival_radius), 3),
                    "colour": "#2e9e44",
                    "label": f"target of group {g} (seen by its scout {names[s]})",
                    "slot": s,
                    "group": g,
                }
            )
        return out

    def group_success(self, world: World, w: int = 0, fraction: float = 0.5) -> np.ndarray:
        """Per group of world ``w``: whether at least ``fraction`` of its non-scouts arrived (so far).

        Args:
            world: The scenario's world.
            w: World index.
            fraction: Share of the group's non-scouts that must have arrived.

        Returns:
            ``(n_groups,)`` bool.
        """
        c, n = self.config, self.n_agents
        sl = slice(w * n, (w + 1) * n)
        g = np.arange(n) % c.n_groups
        t = world.task
        hits = np.bincount(g, weights=t.arrived[sl] & ~t.scout[sl], minlength=c.n_groups)
        return hits >= fraction * (n // c.n_groups - 1) - 1e-9


SCENARIO = RelayScenario
