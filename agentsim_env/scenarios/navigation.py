"""navigation: N agents in G groups each reach their own goal among random 3D obstacles.

Agents (``agent_0`` ... ``agent_{N-1}``) spawn at random in an altitude band over a square map with ground
obstacles (boxes and vertical cylinders of random heights: low ones can be flown over). Each agent has its own
goal; reaching it (within ``goal_radius``) ends the agent with success. A collision ends it with a penalty.

Observation (Dict; the flat Box concatenates the parts in this order):

| part   | shape    | content                                                                                 |
|--------|----------|-----------------------------------------------------------------------------------------|
| self   | (8,)     | x, y in [-1, 1] over the map; altitude in [-1, 1] over the band; vx, vy, vz / max_speed; cos, sin heading |
| lidar  | (K, 2)   | per ray: normalised distance (1 = free), hit code / 3 (0 none, 1/3 agent, 2/3 object, 1 ground) |
| task   | (4,)     | goal minus position (dx, dy, dz) / map diagonal, distance / map diagonal                  |
| inbox  | (M, 11+D)| only with ``comms``: received messages, newest first (layout in ``agentsim_env.comms.messages``) |
| comms  | (2,)     | only with ``comms``: messages received and dropped this step / M                          |
| gnss   | (3,)     | only with ``gnss``: noisy own position over the map and band (``agentsim_env.sensors.gnss``) |

(With both, the order is self, lidar, task, gnss, inbox, comms.)

Rays: ``sensing.n_azimuth`` evenly spaced azimuths (ray 0 along the heading) per elevation ring in
``sensing.elevations_deg``; K = n_azimuth x rings (default 16 x 2 = 32: a horizontal ring and one tilted 25
degrees down). Body (``body``: radius 0.5 m, 5 m/s, 10 m/s^2, band 2-12 m) and sensing are the shared
sub-configs of ``agentsim_env.scenarios.config``; ``n_groups`` defaults to ``min(2, n_agents)``.

Action (Dict with one part ``motion``; the flat Box is the same vector), values in [-1, 1]:
- ``action_mode="velocity"`` (default): (3,) target velocity / max_speed (norm clipped to max_speed).
- ``action_mode="primitive"``: (8,) a selector and parameters for the motion primitives (keep, velocity, linear,
  circular, parabolic, goto); layout table in ``agentsim_env.motion.actions``.

With ``comms`` set, the action also has a ``comm`` part (3 + D,): channel, receiver, hop limit, payload
(layout in ``agentsim_env.comms.stack``), and every message sent costs ``reward.message_cost``.

Reward: task = progress toward the goal (metres) + ``arrival_bonus`` on arrival; composed by
``RewardConfig`` (group share = weight x mean task reward of the agent's group, collision penalty, energy =
speed^2 x dt).

Version history: v0, first release.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

import numba as nb
import numpy as np
from pydantic import Field

from agentsim_env.core.config_model import Int, Real, config, in_range
from agentsim_env.core.pipeline import Sensor
from agentsim_env.core.threads import light_min_rows
from agentsim_env.motion import MotionLimits
from agentsim_env.scenarios.base import Scenario, SlotState, StepResult, slot
from agentsim_env.scenarios.config import ObstacleHeights, ObstacleSizes, ScenarioConfig
from agentsim_env.scenarios.flat_layout import INBOX_CLIP, check_rows_at, comms_width, write_comms
from agentsim_env.scenarios.placement import jittered_points, obstacle_layout, placement_problem
from agentsim_env.scenarios.rewards import RewardConfig, compose_rewards, task_partials
from agentsim_env.sensors.gnss import GnssConfig, GnssSensor
from agentsim_env.sensors.proximity import ProximitySensor, write_lidar_row
from agentsim_env.sim import StepEvents, World, WorldConfig

SELF_DIM, TASK_DIM = 8, 4
MAX_SIDE = 1e5
"""Largest map side in metres (100 km)."""
MAX_SIDE_PYMUNK = 2e4
"""Largest map side with ``physics="pymunk"`` (its worlds share one space, 1e5 m apart)."""
MAX_OBSTACLES = 1_000_000
"""Most obstacles per world."""


def _scored_rows(world: World) -> tuple[np.ndarray, bool]:
    """The slots the scoring kernels compute: every slot in one process, a shard's own slots on a shard (its
    world holds every slot of the map, most of them other shards' agents)."""
    bridge = world.bridge
    if bridge is None:
        return np.zeros(0, dtype=np.int64), True
    return np.flatnonzero(bridge.own), False


# The two kernels below replace a few dozen small numpy passes per step (the fixed cost that dominated small
# worlds). They evaluate the same float64 expressions in the same order as the numpy statements they replace
# (error_model="numpy": x / 0 gives inf like numpy), so observations and rewards are unchanged bit for bit.
@nb.njit(cache=True, error_model="numpy", nogil=True)
def _task_kernel(lo, hi, goal, pos, prev_dist, acting, online, goal_radius, bonus, rows, every, task):  # type: ignore[no-untyped-def]  # noqa: E501
    # The task values alone, changing no state (the group partial sums read them before the scoring), of the slots
    # [lo, hi) when ``every``, else of rows[lo:hi] (the caller zeroes the others: a shard scores its own agents).
    for r in range(lo, hi):
        s = r if every else rows[r]
        # the task expression of _score_kernel, written out in both: a helper returning (d, arrived, task) per
        # slot kept the loop from vectorizing (3.8 ms instead of 0.22 at 100,000 slots)
        dx, dy, dz = goal[s, 0] - pos[s, 0], goal[s, 1] - pos[s, 1], goal[s, 2] - pos[s, 2]
        d = np.sqrt(dx * dx + dy * dy + dz * dz)
        arr = acting[s] and online[s] and d <= goal_radius
        task[s] = (prev_dist[s] - d if acting[s] else 0.0) + bonus * (1.0 if arr else 0.0)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _score_kernel(
    lo,
    hi,
    goal,
    pos,
    vel,
    prev_dist,
    arrived_acc,
    energy,
    acting,
    online,
    goal_radius,
    bonus,
    dt,  # type: ignore[no-untyped-def]  # noqa: E501
    rows,
    every,
    dist,
    arrived,
    task,
    effort,
):
    # The slots [lo, hi) when ``every``, else rows[lo:hi] (a shard's own slots; the caller zeroes the others'
    # outputs and their state is left alone: a slot's state travels with its agent when it changes shards).
    for r in range(lo, hi):
        s = r if every else rows[r]
        # slot s's distance to its goal, arrival and task value (the expression of _task_kernel)
        dx, dy, dz = goal[s, 0] - pos[s, 0], goal[s, 1] - pos[s, 1], goal[s, 2] - pos[s, 2]
        d = np.sqrt(dx * dx + dy * dy + dz * dz)
        arr = acting[s] and online[s] and d <= goal_radius
        task[s] = (prev_dist[s] - d if acting[s] else 0.0) + bonus * (1.0 if arr else 0.0)
        dist[s] = d
        arrived[s] = arr
        arrived_acc[s] |= arr
        # |v|^2 associated as numpy's einsum does it (x + z first), so energy stays bit-identical
        e = ((vel[s, 0] * vel[s, 0] + vel[s, 2] * vel[s, 2]) + vel[s, 1] * vel[s, 1]) * dt
        effort[s] = e
        energy[s] += e if acting[s] else 0.0


@nb.njit(cache=True, error_model="numpy", inline="always")
def _observe_row(s, r, pos, vel, heading, goal, distance, hit_kind, side, lo, hi, vmax, out):  # type: ignore[no-untyped-def]
    # Slot s into row r of out (., 8 + 2K + 4) float32: self | lidar (the sensor's part) | task.
    n_k = distance.shape[1]
    diag = side * np.sqrt(2.0)
    t0 = SELF_DIM + 2 * n_k
    out[r, 0] = min(max(pos[s, 0] / side * 2 - 1, -1.0), 1.0)
    out[r, 1] = min(max(pos[s, 1] / side * 2 - 1, -1.0), 1.0)
    out[r, 2] = min(max((pos[s, 2] - lo) / (hi - lo) * 2 - 1, -1.0), 1.0)
    for a in range(3):
        out[r, 3 + a] = min(max(vel[s, a] / vmax, -1.0), 1.0)
    out[r, 6] = min(max(np.cos(heading[s]), -1.0), 1.0)
    out[r, 7] = min(max(np.sin(heading[s]), -1.0), 1.0)
    write_lidar_row(distance, hit_kind, s, out, r, SELF_DIM)
    dx, dy, dz = goal[s, 0] - pos[s, 0], goal[s, 1] - pos[s, 1], goal[s, 2] - pos[s, 2]
    out[r, t0] = min(max(dx / diag, -1.0), 1.0)
    out[r, t0 + 1] = min(max(dy / diag, -1.0), 1.0)
    out[r, t0 + 2] = min(max(dz / diag, -1.0), 1.0)
    out[r, t0 + 3] = min(max(np.sqrt(dx * dx + dy * dy + dz * dz) / diag, -1.0), 1.0)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _observe_kernel(r0, r1, pos, vel, heading, goal, distance, hit_kind, side, lo, hi, vmax, out):  # type: ignore[no-untyped-def]
    # Rows r0..r1-1 of out (S, 8 + 2K + 4).
    for s in range(r0, r1):
        _observe_row(s, s, pos, vel, heading, goal, distance, hit_kind, side, lo, hi, vmax, out)


@nb.njit(cache=True, error_model="numpy")
def _observe_rows_kernel(rows, at, pos, vel, heading, goal, distance, hit_kind, side, lo, hi, vmax, out):  # type: ignore[no-untyped-def]
    # Slot rows[r] into row at[r] of out (., 8 + 2K + 4): a shard's own agents.
    for r in range(rows.shape[0]):
        _observe_row(rows[r], at[r], pos, vel, heading, goal, distance, hit_kind, side, lo, hi, vmax, out)


@config()
class NavigationConfig(ScenarioConfig):
    """Configuration of ``navigation`` (every field validated at construction; shared fields in ``ScenarioConfig``).

    Attributes:
        n_groups: Groups the agents are split into, 1..n_agents (``None``: ``min(2, n_agents)``).
        map_size: Side of the square map in metres, 10..1e5 (2e4 with ``physics="pymunk"``); ``None``: grows
            with the agent count, ``max(60, sqrt(n_agents x area_per_agent))``.
        area_per_agent: Square metres per agent when ``map_size`` is ``None``, 10..1e6.
        obstacle_density: Obstacles per square metre, 0..0.01 (at most 1,000,000 obstacles per world; a map too
            crowded for them holds fewer).
        obstacle_size: ``(low, high)`` obstacle half-width in metres, ``0.01 <= low <= high <= 100``.
        obstacle_height: ``(low, high)`` obstacle height in metres, ``0.01 <= low <= high <= 1e4``.
        goal_radius: Arrival distance in metres, in (0, 1e4].
        arrival_bonus: Reward on arrival, 0..1e6.
        gnss: A ``GnssConfig`` (or dict) adds the noisy GNSS sensor and its ``gnss`` part; ``None``: none.

    The map must hold the agents' starts and goals ``4 x body.radius + 2`` metres apart (checked here).
    """

    nested: ClassVar[dict[str, type]] = {**ScenarioConfig.nested, "gnss": GnssConfig}

    n_groups: Annotated[Int, Field(ge=1)] | None = None  # None: min(2, n_agents)
    map_size: Annotated[Real, Field(ge=10.0)] | None = None  # None: grows with n_agents, at least 60 m
    area_per_agent: Annotated[Real, Field(ge=10.0, le=1e6)] = 150.0
    obstacle_density: Annotated[Real, Field(ge=0.0, le=0.01)] = 1.0 / 600.0  # obstacles per square metre
    obstacle_size: ObstacleSizes = (1.0, 3.0)
    obstacle_height: ObstacleHeights = (4.0, 24.0)
    goal_radius: Annotated[Real, Field(gt=0.0, le=1e4)] = 1.5
    arrival_bonus: Annotated[Real, Field(ge=0.0, le=1e6)] = 10.0
    reward: RewardConfig = field(default_factory=lambda: RewardConfig(group_share=0.5, energy_weight=0.001))
    gnss: GnssConfig | None = None  # a GnssConfig (or dict) adds the noisy GNSS sensor and its ``gnss`` part

    def __post_init__(self) -> None:
        if self.n_groups is None:
            object.__setattr__(self, "n_groups", min(2, self.n_agents))
        in_range("n_groups", int(self.n_groups or 0), 1, self.n_agents)
        max_side = MAX_SIDE_PYMUNK if self.physics == "pymunk" else MAX_SIDE
        if self.map_size is not None:
            in_range("map_size", self.map_size, 10.0, max_side)
        side = self.side
        if side > max_side:
            raise ValueError(
                f"the map side grows with n_agents x area_per_agent to {side:.0f} m, over the "
                f"{max_side:.0f} m limit{' of physics=pymunk' if self.physics == 'pymunk' else ''}; "
                f"set map_size (<= {max_side:.0f}) or lower area_per_agent"
            )
        n_obs = self.obstacle_density * side * side
        if n_obs > MAX_OBSTACLES:
            raise ValueError(
                f"obstacle_density x map side^2 gives {n_obs:,.0f} obstacles per world, over the "
                f"limit of {MAX_OBSTACLES:,}; lower obstacle_density or map_size"
            )
        problem = placement_problem(self.n_agents, (2.0, side - 2.0, 2.0, side - 2.0), 4.0 * self.body.radius + 2.0)
        if problem:
            raise ValueError(
                f"n_agents: {problem} (4 x body.radius + 2 apart, on a map of side {side:g} m); "
                f"raise map_size or lower n_agents or body.radius"
            )

    @property
    def side(self) -> float:
        """Side of the square map in metres."""
        if self.map_size is not None:
            return float(self.map_size)
        return max(60.0, float(np.sqrt(self.n_agents * self.area_per_agent)))


@dataclass(slots=True)
class NavigationSlots(SlotState):
    """Per-slot state of ``navigation``: each agent's goal, last distance to it and whether it arrived."""

    goal: np.ndarray = slot((3,))
    prev_dist: np.ndarray = slot()
    arrived: np.ndarray = slot(dtype=bool)


class NavigationScenario(Scenario[NavigationConfig]):
    """Reach your own goal among obstacles; see the module docstring for layouts."""

    name = "navigation"
    config_cls = NavigationConfig
    version = 0
    agent_prefix = "agent"
    shardable = True
    test_configs = (
        {"n_agents": 4},
        {"n_agents": 5, "n_groups": 1, "action_mode": "primitive"},
        {"n_agents": 3, "physics": "pymunk"},
        {"n_agents": 6, "n_groups": 2, "comms": {"loss": 0.2, "latency": 1, "heartbeat_period": 5}},
        {"n_agents": 3, "gnss": {"sigma_h": 2.0}},
    )

    def __init__(self, config: NavigationConfig) -> None:
        super().__init__(config)
        self._obs = np.zeros((0, SELF_DIM + 2 * self.lidar.n_rays + TASK_DIM), dtype=np.float32)
        self._side = float(config.side)

    def extra_bytes(self) -> tuple[int, int]:
        """Goals per slot; the obstacles (scene arrays and object grid, about 200 bytes each) per world."""
        c = self.config
        return 64, int(200 * c.obstacle_density * c.side * c.side)

    def make_world(self, n_worlds: int) -> World:
        """World sized for the map, the band and the sensors; goals allocated per slot."""
        c = self.config
        s, b = c.side, c.body
        wc = WorldConfig(
            bounds=(0.0, s, 0.0, s),
            z_range=(0.0, b.altitude[1] + 5.0),
            dt=c.dt,
            physics=c.physics,
            collisions=c.collisions,
            grid_cell=max(c.sensing.range / 2, 2.0),
        )
        sensors: list[Sensor] = [ProximitySensor(self.lidar)]
        if c.gnss is not None:
            sensors.append(GnssSensor(c.gnss, n_worlds, c.n_agents, wc.bounds, b.altitude))
        world = World(wc, n_worlds, c.n_agents, sensors=sensors, comms=c.comms)
        st = world.state
        st.configure(
            radius=b.radius,
            sensor_range=c.sensing.range,
            max_speed=b.max_speed,
            max_accel=b.max_accel,
            n_groups=int(c.n_groups or 1),
        )
        world.task = NavigationSlots.allocate(st.n_slots)
        return world

    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        """New starts, goals and obstacles for world ``w``."""
        c, st, t = self.config, world.state, world.task
        sl = st.slots_of_world(w)
        s, n = c.side, c.n_agents
        bounds = (2.0, s - 2.0, 2.0, s - 2.0)
        sep = 4.0 * c.body.radius + 2.0
        start = jittered_points(rng, n, bounds, sep)
        goal = jittered_points(rng, n, bounds, sep)
        z_lo, z_hi = c.body.altitude
        z0 = rng.uniform(z_lo, z_hi, n)
        zg = rng.uniform(z_lo, z_hi, n)
        st.pos[sl] = np.column_stack([start, z0])
        st.vel[sl] = 0.0
        st.heading[sl] = rng.uniform(-np.pi, np.pi, n)
        st.online[sl] = True
        st.energy[sl] = 0.0
        t.goal[sl] = np.column_stack([goal, zg])
        t.prev_dist[sl] = np.linalg.norm(t.goal[sl] - st.pos[sl], axis=1)
        t.arrived[sl] = False
        world.remove_objects_of_world(w)
        n_obs = int(round(c.obstacle_density * s * s))
        kind, centre, half = obstacle_layout(
            rng,
            n_obs,
            (0.0, s, 0.0, s),
            c.obstacle_size,
            c.obstacle_height,
            np.vstack([start, goal]),
            keep_clear_radius=c.body.radius + 2.0,
        )
        if kind.size:
            world.scene.add(kind, centre, half, w)

    def motion_limits(self, world: World) -> MotionLimits:
        """Primitive limits: circles up to a quarter of the map, 10 s segments, goto arrival at goal_radius / 2."""
        b = self.config.body
        return MotionLimits(
            max_speed=b.max_speed,
            max_accel=b.max_accel,
            max_radius=self.config.side / 4,
            max_duration=10.0,
            z_min=b.altitude[0],
            z_max=b.altitude[1],
            max_omega=1.0,
            arrival_radius=self.config.goal_radius / 2,
        )

    def group_partials(
        self, world: World, events: StepEvents, acting: np.ndarray, mine: np.ndarray
    ) -> dict[str, np.ndarray]:
        """The group share's fixed-point task sums over the acting slots in ``mine`` (none without a share)."""
        c, st, t = self.config, world.state, world.task
        if not c.reward.group_share:
            return {}
        rows, every = _scored_rows(world)
        n = st.n_slots
        task = np.empty(n) if every else np.zeros(n)  # rows not scored stay 0
        args = (
            t.goal,
            st.pos,
            t.prev_dist,
            acting,
            st.online,
            float(c.goal_radius),
            float(c.arrival_bonus),
            rows,
            every,
            task,
        )
        world.threads.run(
            lambda lo, hi, _: _task_kernel(lo, hi, *args), n if every else rows.shape[0], light_min_rows()
        )
        return task_partials(
            task, st.group, st.world_id, acting & mine, int(c.n_groups or 1), world.n_worlds, world.threads
        )

    def score(
        self,
        world: World,
        events: StepEvents,
        acting: np.ndarray,
        totals: dict[str, np.ndarray] | None = None,
    ) -> StepResult:
        """Progress, arrival, collisions and energy -> rewards and terminations (group share from ``totals``)."""
        c, st, t = self.config, world.state, world.task
        rows, every = _scored_rows(world)
        n = st.n_slots
        new = np.empty if every else np.zeros  # rows not scored stay 0
        dist, task, effort = new(n), new(n), new(n)
        arrived, collided = np.zeros(n, dtype=np.bool_), np.zeros(n)
        args = (
            t.goal,
            st.pos,
            st.vel,
            t.prev_dist,
            t.arrived,
            st.energy,
            acting,
            st.online,
            float(c.goal_radius),
            float(c.arrival_bonus),
            float(world.config.dt),
            rows,
            every,
            dist,
            arrived,
            task,
            effort,
        )
        world.threads.run(
            lambda lo, hi, _: _score_kernel(lo, hi, *args), n if every else rows.shape[0], light_min_rows()
        )
        collided[events.went_offline] = 1.0
        # the state keeps its array (resets write it); dist goes out as info
        if every:
            np.copyto(t.prev_dist, dist)
        else:
            t.prev_dist[rows] = dist[rows]
        rewards = compose_rewards(
            c.reward,
            task,
            group=st.group,
            world=st.world_id,
            acting=acting,
            n_groups=int(c.n_groups or 1),
            collided=collided,
            energy=effort,
            messages_sent=None if world.comms is None else world.comms.sent,
            totals=totals,
            n_worlds=world.n_worlds,
            threads=world.threads,
        )
        info: dict[str, np.ndarray] = {
            "arrived": arrived.astype(np.int8),
            "collided": collided.astype(np.int8),
            "distance": dist,
        }
        return StepResult(rewards, arrived, info)

    def observe(self, world: World) -> dict[str, np.ndarray]:
        """self, lidar and task parts for every slot (see the module docstring)."""
        k = self.lidar.n_rays
        if self._obs.shape[0] != world.state.n_slots:
            self._obs = np.zeros((world.state.n_slots, self._obs.shape[1]), dtype=np.float32)
        out = self._write_obs(world, self._obs)
        # Views of one reused buffer: the envs copy them into the fresh arrays they return.
        return {
            "self": out[:, :SELF_DIM],
            "lidar": out[:, SELF_DIM : SELF_DIM + 2 * k].reshape(-1, k, 2),
            "task": out[:, SELF_DIM + 2 * k :],
        }

    def observe_rows(self, world: World, slots: np.ndarray) -> dict[str, np.ndarray]:
        """self, lidar and task parts of ``slots`` only (fresh arrays)."""
        k = self.lidar.n_rays
        rows = np.ascontiguousarray(slots, dtype=np.int64)
        out = np.empty((rows.shape[0], self._obs.shape[1]), dtype=np.float32)
        self._write_obs_rows(world, rows, out, np.arange(rows.shape[0], dtype=np.int64))
        return {
            "self": out[:, :SELF_DIM],
            "lidar": out[:, SELF_DIM : SELF_DIM + 2 * k].reshape(-1, k, 2),
            "task": out[:, SELF_DIM + 2 * k :],
        }

    def flat_observation_rows(
        self, world: World, slots: np.ndarray, out: np.ndarray | None = None, at: np.ndarray | None = None
    ) -> np.ndarray:
        """The flat rows of ``slots`` written straight into ``out`` (or a fresh array; at rows ``at`` when given):
        the three parts by the rows kernel, then the inbox and counters (with comms), when no sensor adds a
        part."""
        if any(s.obs_part is not None for s in world.sensors) or type(self).observation is not Scenario.observation:
            return super().flat_observation_rows(world, slots, out, at)
        rows = np.ascontiguousarray(slots, dtype=np.int64)
        lead = self._obs.shape[1]
        if out is None:
            if at is not None:
                raise ValueError("at needs out: the array whose rows it names")
            out = np.empty((rows.shape[0], lead + comms_width(world)), dtype=np.float32)
        rows_at = check_rows_at(rows, at, out, lead + comms_width(world))
        self._write_obs_rows(world, rows, out, rows_at)
        if world.comms is not None:
            world.comms.observe_rows_flat(world.state.pos, max(world.tick - 1, 0), rows, out, lead, INBOX_CLIP, at)
        return out

    def _write_obs_rows(self, world: World, rows: np.ndarray, out: np.ndarray, at: np.ndarray) -> np.ndarray:
        """The self | lidar | task columns of slot ``rows[r]`` into row ``at[r]`` of ``out`` (its first columns)."""
        c, st = self.config, world.state
        scan = world.scan
        assert scan is not None
        lo, hi = float(c.body.altitude[0]), float(c.body.altitude[1])
        _observe_rows_kernel(
            rows,
            at,
            st.pos,
            st.vel,
            st.heading,
            world.task.goal,
            scan.distance,
            scan.hit_kind,
            self._side,
            lo,
            hi,
            float(c.body.max_speed),
            out,
        )
        return out

    def flat_observation(self, world: World, out: np.ndarray | None = None) -> np.ndarray:
        """The flat layout written straight into ``out`` or a fresh array: the three parts by the observation
        kernel, then the inbox and counters (with comms), when no sensor adds a part."""
        if any(s.obs_part is not None for s in world.sensors) or type(self).observation is not Scenario.observation:
            return super().flat_observation(world, out)
        lead = self._obs.shape[1]
        if out is None:
            out = np.empty((world.state.n_slots, lead + comms_width(world)), dtype=np.float32)
        if world.comms is None:
            return self._write_obs(world, out)
        self._write_obs(world, out[:, :lead])
        write_comms(world, out, lead)
        return out

    def _write_obs(self, world: World, out: np.ndarray) -> np.ndarray:
        """The self | lidar | task columns of every slot into ``out`` ``(S, obs_dim)`` float32."""
        c, st = self.config, world.state
        scan = world.scan
        assert scan is not None
        lo, hi = float(c.body.altitude[0]), float(c.body.altitude[1])
        args = (
            st.pos,
            st.vel,
            st.heading,
            world.task.goal,
            scan.distance,
            scan.hit_kind,
            self._side,
            lo,
            hi,
            float(c.body.max_speed),
            out,
        )
        world.threads.run(lambda r0, r1, _: _observe_kernel(r0, r1, *args), st.n_slots)
        return out

    def state_extra(self, world: World, w: int) -> np.ndarray:
        """Every goal / 100 m."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        return world.task.goal[sl].ravel() / 100.0

    def markers(self, world: World, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Goals as green discs (grey once reached)."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        t = world.task
        rgb = np.where(t.arrived[sl, None], [160, 200, 160], [40, 170, 60]).astype(np.uint8)
        return t.goal[sl, :2], rgb, np.full(self.n_agents, self.config.goal_radius)

    def view_markers(self, world: World, w: int) -> list[dict[str, Any]]:
        """Each agent's goal (the viewer draws it in its agent's colour and links the two)."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        names, r = self.agent_names(), round(float(self.config.goal_radius), 3)
        return [
            {
                "kind": "goal",
                "pos": [round(float(x), 3), round(float(y), 3), 0.0],
                "radius": r,
                "colour": "#2e9e44",
                "label": f"goal of {names[i]}",
                "slot": i,
            }
            for i, (x, y) in enumerate(world.task.goal[sl, :2].tolist())
        ]


SCENARIO = NavigationScenario
