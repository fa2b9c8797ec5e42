"""The World: owns the state and the subsystems and runs the step pipeline.

``World.step`` runs, for every world at once: motion (the centralised movement worker), optional pymunk
physics in the horizontal plane, collisions (events, hit agents go offline), and the proximity scan. Action
decoding happens before (the scenario sets motion primitives), rewards and observations after (the scenario).
Later stages (payloads, groups, comms) hook in through the scenario, which owns them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from agentsim_env.comms.stack import CommsConfig, CommsEvents, CommsStack
from agentsim_env.core.collisions import CollisionEvents, find_collisions
from agentsim_env.core.scene import Scene
from agentsim_env.core.spatial import Grid, GridSpec, build_grid, build_object_grid
from agentsim_env.core.state import AgentState
from agentsim_env.motion import MotionState, integrate
from agentsim_env.sensors.proximity import ProximityConfig, ProximitySensor, ScanResult

PHYSICS_MODES = ("kinematic", "pymunk")


@dataclass(frozen=True)
class WorldConfig:
    """Geometry and pipeline switches of a world.

    Attributes:
        bounds: Map ``(xmin, xmax, ymin, ymax)`` in metres; agents are kept inside.
        z_range: Allowed altitude ``(zmin, zmax)``.
        dt: Step length in seconds.
        physics: ``"kinematic"`` (motion only) or ``"pymunk"`` (planar contact resolution).
        physics_substeps: Pymunk sub-steps per step.
        collisions: Whether distance-threshold collisions are detected (and end agents).
        collision_margin: Extra distance added to collision thresholds.
        collision_ends_agent: Whether a collision (or a pymunk contact) takes the agent offline; switch it off
            to let agents slide along walls under pymunk while still reporting contact events.
        grid_cell: Cell side of the neighbour grid (``None``: from the sensor range).
        lidar: Proximity-sensor configuration.
        max_waypoints: Waypoint capacity of path primitives.
    """

    bounds: tuple[float, float, float, float] = (0.0, 100.0, 0.0, 100.0)
    z_range: tuple[float, float] = (0.0, 50.0)
    dt: float = 0.1
    physics: str = "kinematic"
    physics_substeps: int = 4
    collisions: bool = True
    collision_margin: float = 0.0
    collision_ends_agent: bool = True
    grid_cell: float | None = None
    lidar: ProximityConfig = field(default_factory=ProximityConfig)
    max_waypoints: int = 16

    def __post_init__(self) -> None:
        if self.physics not in PHYSICS_MODES:
            raise ValueError(f"physics must be one of {PHYSICS_MODES}, got {self.physics!r}")
        if not self.dt > 0:
            raise ValueError(f"dt must be > 0, got {self.dt}")
        if self.physics_substeps < 1:
            raise ValueError(f"physics_substeps must be >= 1, got {self.physics_substeps}")
        if len(self.bounds) != 4 or not (self.bounds[1] > self.bounds[0] and self.bounds[3] > self.bounds[2]):
            raise ValueError(
                f"bounds must be (xmin, xmax, ymin, ymax) with xmin < xmax, ymin < ymax, got {self.bounds}"
            )
        if len(self.z_range) != 2 or not self.z_range[1] > self.z_range[0]:
            raise ValueError(f"z_range must be (zmin, zmax) with zmin < zmax, got {self.z_range}")
        # pymunk steps every world in one space, world w shifted by w * 1e5 m along x, and the world calls its
        # step without per-step input checks: keep the map well inside the +-5e4 m each world may use
        if self.physics == "pymunk" and max(abs(self.bounds[0]), abs(self.bounds[1])) >= 2.5e4:
            raise ValueError(f"bounds x must lie within +-25000 m with physics='pymunk', got {self.bounds}")


@dataclass(slots=True)
class StepEvents:
    """What happened in one world step (arrays over all worlds).

    Attributes:
        collisions: Collision events (stage 5).
        went_offline: Slots taken offline this step by collisions (stage 5).
        timed_out: Slots taken offline by heartbeat timeouts (stage 6).
        comms: The step's traffic: sent, delivered and dropped messages, overlay deliveries, group changes.
    """

    collisions: CollisionEvents
    went_offline: np.ndarray
    timed_out: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    comms: CommsEvents | None = None


class World:
    """B independent worlds of N agents each, stepped together.

    Args:
        config: World configuration.
        n_worlds: Number of worlds B.
        n_agents: Agents per world N.
        state: Optional pre-built state (otherwise a zeroed one is created).
        comms: Communication settings (None: no bus, overlay or groups controller).
    """

    def __init__(
        self,
        config: WorldConfig,
        n_worlds: int,
        n_agents: int,
        state: AgentState | None = None,
        comms: CommsConfig | None = None,
    ) -> None:
        self.config = config
        self.state = state if state is not None else AgentState.create(n_worlds, n_agents)
        self.motion = MotionState.create(self.state.n_slots, config.max_waypoints)
        self.scene = Scene()
        self.sensor = ProximitySensor(config.lidar)
        cell = config.grid_cell or max(float(self.state.sensor_range.max()) / 2.0, 2.0)
        self.grid_spec = GridSpec.for_bounds(config.bounds, cell, n_worlds)
        self.agent_grid: Grid = build_grid(
            self.grid_spec, self.state.pos, self.state.world_id, self.state.online
        )
        self._object_grid: Grid | None = None
        self._object_grid_version = -1
        self.physics: object | None = None
        self._physics_version = -1
        self.step_count = np.zeros(n_worlds, dtype=np.int64)
        self.tick = 0  # global step counter (message timestamps); never reset per world
        self.comms = (
            CommsStack(comms, n_worlds, n_agents, self.state.group, np.random.default_rng(0))
            if comms
            else None
        )
        self.scan: ScanResult | None = None
        self.last_events = StepEvents(CollisionEvents.empty(), np.zeros(0, dtype=np.int64))

    # ------------------------------------------------------------------ helpers
    @property
    def n_worlds(self) -> int:
        """Number of worlds."""
        return self.state.n_worlds

    @property
    def n_agents(self) -> int:
        """Agents per world."""
        return self.state.n_agents

    def object_grid(self) -> Grid | None:
        """The static objects' grid, rebuilt only when the scene changed."""
        sc = self.scene
        if sc.n_objects == 0:
            return None
        if self._object_grid is None or self._object_grid_version != sc.version:
            self._object_grid = build_object_grid(self.grid_spec, sc.centre, sc.footprint_radius(), sc.world)
            self._object_grid_version = sc.version
        return self._object_grid

    def _physics_backend(self):  # type: ignore[no-untyped-def]
        from agentsim_env.physics.pymunk_backend import PymunkPlanarBackend

        sc = self.scene
        if self.physics is None or self._physics_version != sc.version:
            # Objects only added: the backend takes the new ones and keeps its contact state. Anything else
            # (objects removed or changed, as on a world reset) rebuilds it, which also drops pymunk's hidden
            # contact state, so that a reset episode replays exactly.
            be = self.physics
            if be is None or not be.extend_obstacles(sc.kind, sc.centre, sc.half, sc.world):
                self.physics = PymunkPlanarBackend(
                    self.state.radius,
                    self.state.world_id,
                    self.n_worlds,
                    sc.kind,
                    sc.centre,
                    sc.half,
                    sc.world,
                    substeps=self.config.physics_substeps,
                )
            self._physics_version = sc.version
        return self.physics

    def remove_objects_of_world(self, world: int) -> None:
        """Drop every static object of one world (used when a world is reset with a new random scene)."""
        sc = self.scene
        keep = sc.world != world
        if keep.all():
            return
        sc.kind, sc.centre, sc.half, sc.world = sc.kind[keep], sc.centre[keep], sc.half[keep], sc.world[keep]
        sc.version += 1

    def set_offline(self, slots: np.ndarray) -> None:
        """Take slots out of the simulation: they stop, vanish from sensors and never collide again."""
        st = self.state
        st.online[slots] = False
        st.vel[slots] = 0.0

    def refresh(self) -> None:
        """Rebuild the neighbour grid, the comms range graph and the scan from the current state (after a reset)."""
        st = self.state
        self.agent_grid = build_grid(self.grid_spec, st.pos, st.world_id, st.online)
        if self.comms is not None:
            self.comms.update_graph(self.agent_grid, st.pos, st.online, st.world_id)
        if self.config.physics == "pymunk":
            self._physics_backend()  # a reset's new scene: rebuild now rather than inside the next step
        self.scan = self._scan()

    def reset_comms(self, rng: np.random.Generator, world: int | None = None) -> None:
        """Drop in-flight traffic: of every world (``world=None``, with ``rng`` for the channel) or of one."""
        if self.comms is None:
            return
        if world is None:
            self.comms.reset(rng, self.tick)
        else:
            self.comms.reset_world(world, self.tick)

    def apply_comm(self, comm: np.ndarray, acting: np.ndarray) -> None:
        """Stage 1 (communication part): the acting slots' ``comm`` actions become messages and floods."""
        if self.comms is None:
            raise ValueError("this scenario has no communication (its config has no comms settings)")
        self.comms.send_actions(self.tick, comm, acting, self.state.group)

    def _scan(self) -> ScanResult:
        st, sc = self.state, self.scene
        og = self.object_grid()
        return self.sensor.scan(
            st.pos,
            st.heading,
            st.sensor_range,
            st.radius,
            st.online,
            st.world_id,
            self.agent_grid,
            sc.kind,
            sc.centre,
            sc.half,
            sc.world,
            og,
            sc.ground,
            out=self.scan,
        )

    # ------------------------------------------------------------------ pipeline
    def step(self) -> StepEvents:
        """Advance every world by one ``dt`` (pipeline stages 2, 3, 5 and 8; see DESIGN §4)."""
        cfg, st = self.config, self.state
        prev_xy = st.pos[:, :2].copy() if cfg.physics == "pymunk" else None
        # 2. motion: every primitive of every online slot, in one kernel
        integrate(self.motion, st.pos, st.vel, st.heading, st.max_speed, st.max_accel, st.online, cfg.dt)
        # 3. physics: pymunk resolves horizontal contacts; altitude stays with motion
        contact_events = CollisionEvents.empty()
        if cfg.physics == "pymunk":
            assert prev_xy is not None
            # motion's horizontal displacement becomes the commanded velocity; pymunk moves x, y from the
            # step's start and writes the online rows' x, y and vx, vy back in place (the new z stays)
            desired = st.pos[:, :2] - prev_xy
            desired /= cfg.dt
            st.pos[:, :2] = prev_xy
            contacts = self._physics_backend().step_unchecked(
                st.pos, desired, st.online, cfg.dt, st.pos, st.vel
            )
            if cfg.collisions and len(contacts.agent):
                contact_events = CollisionEvents(contacts.agent, contacts.other_agent, contacts.obj)
        # keep agents inside the map and the altitude band
        xmin, xmax, ymin, ymax = cfg.bounds
        np.clip(st.pos[:, 0], xmin, xmax, out=st.pos[:, 0])
        np.clip(st.pos[:, 1], ymin, ymax, out=st.pos[:, 1])
        np.clip(st.pos[:, 2], cfg.z_range[0], cfg.z_range[1], out=st.pos[:, 2])
        self.agent_grid = build_grid(self.grid_spec, st.pos, st.world_id, st.online)
        # 5. collisions: distance threshold -> events; the agents hit go offline
        events = CollisionEvents.empty()
        if cfg.collisions:
            sc = self.scene
            events = find_collisions(
                st.pos,
                st.radius,
                st.online,
                st.world_id,
                self.agent_grid,
                sc.kind,
                sc.centre,
                sc.half,
                sc.world,
                self.object_grid(),
                cfg.collision_margin,
            ).concat(contact_events)
        went = np.unique(events.agent) if cfg.collision_ends_agent else np.zeros(0, dtype=np.int64)
        if went.size:
            self.set_offline(went)
        timed_out = np.zeros(0, dtype=np.int64)
        comm_events = None
        if self.comms is not None:
            # the environment tells each hit agent what hit it
            self.comms.on_collisions(self.tick, events.agent, events.other_agent, events.obj)
            # 6. groups: heartbeat tick; agents silent past the timeout go offline
            timed_out = self.comms.tick_groups(self.tick, st.online, st.pos)
            timed_out = timed_out[st.online[timed_out]]
            if timed_out.size:
                self.set_offline(timed_out)
        if went.size or timed_out.size:
            self.agent_grid = build_grid(self.grid_spec, st.pos, st.world_id, st.online)
        if self.comms is not None:
            # 7. comms: bus messages due this step; one overlay hop over the range graph
            comm_events = self.comms.deliver(
                self.tick, st.pos, st.online, st.group, st.world_id, self.agent_grid
            )
        # 8. sensors: proximity scan of every online slot
        self.scan = self._scan()
        self.step_count += 1
        self.tick += 1
        self.last_events = StepEvents(events, went, timed_out, comm_events)
        return self.last_events
