"""uav_release: UAVs release wireless sensors over circular hot zones, denser toward each zone's centre.

K = ``n_agents`` UAVs (``uav_0`` ...; ``n_uavs`` is an alias key) take off from the base with ``payload`` sensors each
and a battery (rotary-wing power
model, the mass falling as sensors leave). A released sensor falls with quadratic drag and wind (log-law
mean per episode plus gusts) and lands with scatter (GNSS, timing jitter, bounce). Zones come from a zone
designer JSON file (``docs/zones.md``). The episode ends when the zones' sensors have all landed (or nothing is left on
board
and nothing is falling, or at ``max_steps``);
a collision or an empty battery ends a UAV.

Observation (Dict; flat Box = parts in this order):

| part    | shape        | content                                                                          |
|---------|--------------|----------------------------------------------------------------------------------|
| self    | (10,)        | x, y over the map and z over the band in [-1, 1]; velocity / max_speed; cos, sin heading; payload left / payload; battery left / capacity |
| lidar   | (K, 2)       | per ray: distance / range, hit code / 3 (rays: n_azimuth x elevations_deg)        |
| zones   | (Z, 5)       | per zone: centre - UAV (dx, dy) / map diagonal, radius / map diagonal, unmet demand (sensors not yet landed or falling there / n_sensors), weight / max weight |
| landed  | (C, C)       | landed sensors around the UAV (window ``grid_extent`` m, C = ``grid_cells``), count / 4, clipped |
| inbox   | (M, 11 + D)  | received messages, newest first (``agentsim_env.comms.messages``)                 |
| comms   | (2,)         | received and dropped this step / M                                               |
| autopilot | (4,)       | autopilot mode only: predicted coverage gain of releasing now x N / 4 (N = the zones' sensors), route progress, whether the predicted landing point is in a zone (1 / -1), payload left / payload - (1 - progress); all x 2 - 1 but the last, clipped to [-1, 1] |

Action (Dict; flat Box = parts in this order), values in [-1, 1]:
- ``motion``: (3,) velocity / max_speed (``action_mode="velocity"``) or (8,) primitive
(``agentsim_env.motion.actions``).
- ``release``: (3,) trigger (> 0 releases one sensor this step, from the UAV's position and velocity), and the
  intended landing point's offset from the UAV (dx, dy) x ``target_scale`` m (used for the miss distance and
  recorded as the sensor's target; the zone containing it is the sensor's zone).
- ``comm``: (3 + D,) channel, receiver, hop limit, payload (``agentsim_env.comms.stack``).

Autopilot mode (``autopilot=True``; ``uav_autopilot``; default off, then nothing below applies): the
scenario flies every UAV over its share of boustrophedon lanes covering the zones (transit at ``max_speed``,
sweep at ``autopilot_speed`` and ``autopilot_altitude``) and the ``motion`` action is ignored; the policy only
decides when to release. Only ``release[0]`` (trigger) counts: the sensor's target is its predicted landing
point (mean wind, no gusts) and releases are masked out in transit, after the UAV's sweep and with an empty
payload. The mission also completes once every UAV has finished its sweep and nothing is falling.

| action part | autopilot mode                                                   |
|-------------|------------------------------------------------------------------|
| motion      | ignored (the autopilot flies); with ``autopilot_offset=True``, ``motion[0]`` x ``autopilot_lane`` / 2 m offsets the UAV sideways from its lane while it sweeps (left of its flying direction when positive), the other components ignored |
| release     | trigger > 0 releases at the predicted landing point; dx, dy ignored |
| comm        | as without autopilot                                             |

Autopilot shaping (the episode's sum is unchanged up to a constant): the coverage term is credited at release
time with the predicted gain ``g`` (importance of the lattice points within ``r_s`` of the predicted landing
point not yet claimed by an earlier release or covered) and corrected at landing by ``gain - g``; each release
costs ``c = w_coverage x release_cost / N`` and carrying a sensor costs ``c`` spread over the route
(``-c x d(payload_left x progress)`` per step), so that over an episode these terms add up to
``-c x payload`` whatever the policy does (when every UAV ends its sweep).

Reward per UAV (domain §5.4), through the reward composer: w_coverage x weighted-coverage gain of its landed
sensors - w_fidelity x change of the zone's radial W1 - w_energy x energy / battery - w_miss x landing miss / zone
radius - w_out x landings outside every zone; at the end of the episode every UAV still flying gets
w_lcc x largest-component fraction + w_lifetime x FND / FND of the oracle layout (B8).

Version history: v0, first release; autopilot mode added (off by default, layouts unchanged without it); the
autopilot's lane offset action added (``autopilot_offset``, off by default, layouts unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from agentsim_env.motion import MotionLimits
from agentsim_env.motion.actions import decode_velocity_unchecked
from agentsim_env.payloads import FallParams
from agentsim_env.payloads.stage import PayloadStage
from agentsim_env.scenarios.base import Scenario, SlotState, StepResult, slot
from agentsim_env.scenarios.rewards import compose_rewards
from agentsim_env.sensors.proximity import ProximitySensor
from agentsim_env.sim import StepEvents, World, WorldConfig
from agentsim_env.uav.autopilot import AutopilotMode, ClaimMap
from agentsim_env.uav.config import UavReleaseConfig
from agentsim_env.uav.energy import DEFAULT_ROTOR, energy_step
from agentsim_env.uav.landed_grid import local_counts
from agentsim_env.uav.outcome import final_bonus, oracle_fnd
from agentsim_env.uav.tracking import DeploymentTracker
from agentsim_env.uav.zones import DENSITY_SAMPLES, ZoneSet


@dataclass(slots=True)
class UavSlots(SlotState):
    """Per-slot state of ``uav_release``: sensors left on board, this step's releases, per-world mission end."""

    payload_left: np.ndarray = slot(dtype=np.int64)
    released: np.ndarray = slot(dtype=np.int8)
    finished: np.ndarray = slot(dtype=bool, per_world=True)
    wp: np.ndarray = slot(dtype=np.int64)  # autopilot: waypoint flown to (0: transit)
    route_done: np.ndarray = slot(dtype=bool)  # autopilot: piece swept
    release_gain: np.ndarray = slot()  # autopilot: predicted coverage gain of this step's release
    progress: np.ndarray = slot()  # autopilot: fraction of the piece swept
    tracker: DeploymentTracker | None = None  # coverage and radial fidelity of the landed sensors, per world
    claims: ClaimMap | None = None  # autopilot: lattice claimed by released sensors' predicted landings


class UavReleaseScenario(Scenario[UavReleaseConfig]):
    """UAV sensor release over hot zones; see the module docstring for layouts and rewards."""

    name = "uav_release"
    config_cls = UavReleaseConfig
    version = 0
    agent_prefix = "uav"
    obs_bounds = {"landed": (0.0, 1.0)}
    event_keys = ("released", "landed")
    final_keys = ("coverage_weighted",)
    extra_actions = {"release": 3}
    test_configs = (
        {"zones": "tiny", "n_agents": 2, "payload": 12, "max_steps": 400},
        {
            "zones": "tiny",
            "n_agents": 3,
            "payload": 8,
            "max_steps": 300,
            "action_mode": "primitive",
            "comms": {"payload_dim": 6, "loss": 0.3, "latency": 1},
        },
    )

    def __init__(self, config: UavReleaseConfig) -> None:
        super().__init__(config)
        c = config
        self.zones: ZoneSet = c.zones
        w, h = self.zones.map_size
        self.diag = float(np.hypot(w, h))
        self.fall = FallParams(mass=c.sensor_mass, cd=c.sensor_cd, area=c.sensor_area)
        self.fnd_oracle = oracle_fnd(self.zones, c.wsn)
        self.pilot = AutopilotMode(c, self.zones, self.fall) if c.autopilot else None

    def extra_bytes(self) -> tuple[int, int]:
        """The payload's sensors (state, fall, landing and deployment records, about 1.7 kB each) per slot."""
        return 1700 * int(self.config.payload), 0

    def make_world(self, n_worlds: int) -> World:
        """World over the zones' map with the payload stage; deployment trackers for ``n_worlds`` worlds."""
        c, b = self.config, self.config.body
        w, h = self.zones.map_size
        wc = WorldConfig(
            bounds=(0.0, w, 0.0, h),
            z_range=(0.0, b.altitude[1]),
            dt=c.dt,
            physics=c.physics,
            collisions=c.collisions,
            grid_cell=max(c.sensing.range / 2, 5.0),
        )
        payloads = PayloadStage(self.fall, c.scatter, c.wind, n_worlds)
        world = World(wc, n_worlds, c.n_agents, sensors=[ProximitySensor(self.lidar)], comms=c.comms, payloads=payloads)
        st = world.state
        # one group: the whole fleet
        st.configure(radius=b.radius, sensor_range=c.sensing.range, max_speed=b.max_speed, max_accel=b.max_accel)
        world.task = UavSlots.allocate(st.n_slots, n_worlds)
        world.task.tracker = DeploymentTracker(self.zones, n_worlds, c.wsn.r_s)
        if self.pilot is not None:
            world.task.claims = ClaimMap(world.task.tracker, n_worlds)
        return world

    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        """UAVs at the base with full payload and battery; no sensors (the payload stage cleared the world)."""
        c, st, t = self.config, world.state, world.task
        sl = st.slots_of_world(w)
        n = c.n_agents
        base = np.asarray(self.zones.base if self.zones.base is not None else (10.0, 10.0))
        offs = np.column_stack([np.arange(n) * 3.0, np.zeros(n)])
        st.pos[sl] = np.column_stack([base + offs, np.full(n, c.body.altitude[0])])
        st.vel[sl], st.heading[sl], st.energy[sl] = 0.0, 0.0, 0.0
        st.online[sl] = True
        t.payload_left[sl] = c.payload
        t.released[sl] = 0
        t.tracker.reset_world(w)
        t.finished[w] = False
        t.wp[sl], t.route_done[sl], t.release_gain[sl], t.progress[sl] = 0, False, 0.0, 0.0
        if t.claims is not None:
            t.claims.reset_world(w)

    def motion_limits(self, world: World) -> MotionLimits:
        """Primitive limits: circles up to a quarter of the map, 30 s segments, goto arrival within 1 m."""
        b = self.config.body
        w, h = self.zones.map_size
        return MotionLimits(
            max_speed=b.max_speed,
            max_accel=b.max_accel,
            max_radius=min(w, h) / 4,
            max_duration=30.0,
            z_min=b.altitude[0],
            z_max=b.altitude[1],
            max_omega=1.0,
            arrival_radius=1.0,
        )

    def apply_actions(self, world: World, actions: dict[str, np.ndarray], acting: np.ndarray) -> None:
        """Motion commands, then releases from the UAVs' current position and velocity (into stage 4)."""
        c, st, t = self.config, world.state, world.task
        may = acting & st.online & (t.payload_left > 0)
        if self.pilot is None:
            super().apply_actions(world, actions, acting)
        else:  # the autopilot flies; releases only while sweeping
            lateral = actions["motion"][:, 0] if c.autopilot_offset else None
            cmd, t.wp[:] = self.pilot.fly(world, t.wp, lateral)
            decode_velocity_unchecked(world.motion, acting, cmd, st.max_speed)
            may &= self.pilot.on_route(t.wp, st.n_slots)
        rel = actions["release"]
        go = np.flatnonzero(may & (rel[:, 0] > 0))
        t.released[:] = 0
        t.release_gain[:] = 0.0
        if go.size:
            if self.pilot is None:
                target = st.pos[go, :2] + rel[go, 1:3] * c.target_scale
            else:
                target = self.pilot.landing(world)[go]
            wld = st.world_id[go]
            assert world.payloads is not None
            ids = world.payloads.release(
                go,
                wld,
                st.pos[go],
                st.vel[go],
                float(world.step_count[wld[0]]) * c.dt,
                self.zones.zone_index(target),
                target,
            )
            if self.pilot is not None:
                t.release_gain[go] = t.claims.claim(wld, target, ids)
            t.payload_left[go] -= 1
            t.released[go] = 1

    def score(
        self,
        world: World,
        events: StepEvents,
        acting: np.ndarray,
        totals: dict[str, np.ndarray] | None = None,
    ) -> StepResult:
        """Landings (stage 4's events): coverage, fidelity, miss terms; energy; end of mission bonus."""
        c, st, t = self.config, world.state, world.task
        assert world.payloads is not None and events.payloads is not None
        ps = world.payloads.objects
        s = st.n_slots
        landed = events.payloads.landed
        task = np.zeros(s)
        n_landed = np.zeros(s)
        if landed.size:
            idx = ps.index_of(landed)
            owner, wld, zone = ps.get("owner")[idx], ps.get("world")[idx], ps.get("zone")[idx]
            land, target = ps.get("land_xy")[idx], ps.get("target_xy")[idx]
            gain, dw1 = t.tracker.land(wld, land, zone)
            if self.pilot is not None:  # the predicted gain was credited at release
                gain = gain - t.claims.landed(landed)
            radius = np.where(zone >= 0, self.zones.radii()[np.maximum(zone, 0)], c.target_scale)
            miss = np.nan_to_num(np.linalg.norm(land - target, axis=1) / radius)
            out = self.zones.zone_index(land) < 0
            term = c.w_coverage * gain - c.w_fidelity * dw1 - c.w_miss * miss - c.w_out * out
            np.add.at(task, owner, term)
            np.add.at(n_landed, owner, 1.0)
        mass = DEFAULT_ROTOR.mass_kg + t.payload_left * c.sensor_mass
        energy = np.where(st.online, energy_step(st.vel, mass, c.dt), 0.0)
        st.energy += energy
        task -= c.w_energy * energy / c.battery_j
        route_over = np.zeros(world.n_worlds, dtype=bool)
        if self.pilot is not None:  # release-time credit, release and carrying costs; sweeps finished
            task += self.pilot.shaping(world, t)
            route_over = (t.route_done | ~st.online).reshape(-1, c.n_agents).all(axis=1)
        empty_battery = acting & (st.energy >= c.battery_j)
        collided = np.zeros(s)
        collided[events.went_offline] = 1.0
        # mission complete in a world, nothing falling and: every zone's sensors landed, or nothing left on board
        n = c.n_agents
        left = (t.payload_left * st.online).reshape(-1, n).sum(axis=1)
        ps_world = ps.get("world")
        falling = np.bincount(ps_world[ps.get("falling")], minlength=world.n_worlds)
        down = np.bincount(ps_world[ps.get("landed")], minlength=world.n_worlds)
        complete = (falling == 0) & ((left == 0) | (down >= self.zones.n_sensors) | route_over)
        done_now = ~t.finished & (complete | (world.step_count >= c.max_steps))
        terminated = empty_battery.copy()
        for w in np.flatnonzero(done_now).tolist():
            t.finished[w] = True
            sl = st.slots_of_world(w)
            task[sl] += final_bonus(ps, w, self.zones, c, self.fnd_oracle)
            terminated[sl] |= world.step_count[w] < c.max_steps  # finished, not cut off by the time limit
        rewards = compose_rewards(
            c.reward,
            task,
            group=st.group,
            world=st.world_id,
            acting=acting,
            n_groups=1,
            collided=collided,
            messages_sent=world.comms.sent if world.comms else None,
            threads=world.threads,
        )
        cov = np.repeat([t.tracker.weighted_coverage(w) for w in range(world.n_worlds)], n)
        info: dict[str, np.ndarray] = {
            "released": t.released.copy(),
            "landed": n_landed.astype(np.int8),
            "payload_left": t.payload_left.copy(),
            "energy_j": st.energy.copy(),
            "coverage_weighted": cov,
        }
        return StepResult(rewards, terminated & acting, info)

    def observe(self, world: World) -> dict[str, np.ndarray]:
        """self, lidar, zones and landed parts for every slot (see the module docstring)."""
        c, st, t = self.config, world.state, world.task
        w, h = self.zones.map_size
        lo, hi = c.body.altitude
        selfp = np.column_stack(
            [
                st.pos[:, 0] / w * 2 - 1,
                st.pos[:, 1] / h * 2 - 1,
                (st.pos[:, 2] - lo) / (hi - lo) * 2 - 1,
                st.vel / c.body.max_speed,
                np.cos(st.heading),
                np.sin(st.heading),
                t.payload_left / c.payload,
                1.0 - st.energy / c.battery_j,
            ]
        )
        scan = world.scan
        assert scan is not None and world.payloads is not None
        rel = self.zones.centres()[None, :, :] - st.pos[:, None, :2]
        demand = self._demand(world)[st.world_id]
        wts = self.zones.weights()
        radius = np.broadcast_to(self.zones.radii() / self.diag, rel.shape[:2])
        zones = np.concatenate(
            [
                rel / self.diag,
                radius[..., None],
                demand[..., None],
                np.broadcast_to(wts / wts.max(), rel.shape[:2])[..., None],
            ],
            axis=2,
        )
        ps = world.payloads.objects
        done = ps.get("landed")
        grid = local_counts(
            st.pos[:, :2],
            st.world_id,
            ps.get("land_xy")[done],
            ps.get("world")[done],
            c.grid_cells,
            c.grid_extent,
        )
        out = {
            "self": np.clip(selfp, -1, 1).astype(np.float32),
            "lidar": world.sensors[0].observe(scan),
            "zones": np.clip(zones, -1, 1).astype(np.float32),
            "landed": grid,
        }
        if self.pilot is not None:
            in_zone = self.zones.zone_index(self.pilot.landing(world)) >= 0
            out["autopilot"] = self.pilot.observe(world, t.claims, t.wp, t.payload_left / c.payload, in_zone)
        return out

    def _demand(self, world: World) -> np.ndarray:
        """Unmet demand per (world, zone): sensors not yet landed or falling there / n_sensors."""
        k = len(self.zones.zones)
        assert world.payloads is not None
        ps = world.payloads.objects
        zone, wld = ps.get("zone"), ps.get("world")
        ok = zone >= 0
        got = np.bincount(wld[ok] * k + zone[ok], minlength=world.n_worlds * k).reshape(world.n_worlds, k)
        need = np.array([z.n_sensors for z in self.zones.zones], dtype=np.float64)
        return np.clip((need - got) / need, 0.0, 1.0)

    def state_extra(self, world: World, w: int) -> np.ndarray:
        """Payload left / payload and battery used / capacity per UAV."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        return np.column_stack(
            [
                world.task.payload_left[sl] / self.config.payload,
                world.state.energy[sl] / self.config.battery_j,
            ]
        ).ravel()

    def markers(self, world: World, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Zones as tinted discs, landed sensors as dark dots, falling ones as orange dots."""
        assert world.payloads is not None
        ps = world.payloads.objects
        mine = ps.get("world") == w
        landed, falling = mine & ps.get("landed"), mine & ps.get("falling")
        tints = np.array([[205, 225, 245], [245, 220, 200], [215, 240, 210], [240, 215, 240]], dtype=np.uint8)
        k = len(self.zones.zones)
        xy = np.vstack([self.zones.centres(), ps.get("land_xy")[landed], ps.get("pos")[falling, :2]])
        rgb = np.vstack(
            [
                tints[np.arange(k) % 4],
                np.tile([[40, 40, 40]], (landed.sum(), 1)),
                np.tile([[240, 140, 20]], (falling.sum(), 1)),
            ]
        ).astype(np.uint8)
        rad = np.concatenate([self.zones.radii(), np.full(landed.sum() + falling.sum(), 1.2)])
        return xy, rgb, rad

    def view_markers(self, world: World, w: int) -> list[dict[str, Any]]:
        """The hot zones, each with its areal density sampled from the centre to the rim (scaled to max 1)."""
        out = []
        for i, z in enumerate(self.zones.zones):
            d = z.density_curve(DENSITY_SAMPLES)
            out.append(
                {
                    "kind": "zone",
                    "pos": [float(z.centre[0]), float(z.centre[1]), 0.0],
                    "radius": z.radius,
                    "colour": "#d7301f",
                    "label": z.name or f"zone {i}",
                    "name": z.name or f"zone {i}",
                    "n_sensors": z.n_sensors,
                    "density": np.round(d, 4).tolist(),
                }
            )
        return out


SCENARIO = UavReleaseScenario
