"""uav_release: UAVs release wireless sensors over circular hot zones, denser toward each zone's centre.

K UAVs (``uav_0`` ...) take off from the base with ``payload`` sensors each and a battery (rotary-wing power
model, the mass falling as sensors leave). A released sensor falls with quadratic drag and wind (log-law
mean per episode plus gusts) and lands with scatter (GNSS, timing jitter, bounce). Zones come from a zone
designer JSON file (``docs/zones.md``). The episode ends when the zones' sensors have all landed (or nothing is left on board
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

Action (Dict; flat Box = parts in this order), values in [-1, 1]:
- ``motion``: (3,) velocity / max_speed (``action_mode="velocity"``) or (8,) primitive (``agentsim_env.motion.actions``).
- ``release``: (3,) trigger (> 0 releases one sensor this step, from the UAV's position and velocity), and the
  intended landing point's offset from the UAV (dx, dy) x ``target_scale`` m (used for the miss distance and
  recorded as the sensor's target; the zone containing it is the sensor's zone).
- ``comm``: (3 + D,) channel, receiver, hop limit, payload (``agentsim_env.comms.stack``).

Reward per UAV (domain §5.4), through the reward composer: w_coverage x weighted-coverage gain of its landed
sensors - w_fidelity x change of the zone's radial W1 - w_energy x energy / battery - w_miss x landing miss / zone
radius - w_out x landings outside every zone; at the end of the episode every UAV still flying gets
w_lcc x largest-component fraction + w_lifetime x FND / FND of the oracle layout (B8).

Version history: v0, first release.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.core.world import StepEvents, World, WorldConfig
from agentsim_env.motion import MotionLimits, decode_primitive, decode_velocity, set_hold
from agentsim_env.payloads import FallParams, PayloadSet, WindModel
from agentsim_env.scenarios.base import Part, Scenario, StepResult
from agentsim_env.scenarios.landed_grid import local_counts
from agentsim_env.scenarios.rewards import compose_rewards
from agentsim_env.scenarios.uav_config import UavReleaseConfig
from agentsim_env.scenarios.uav_energy import DEFAULT_ROTOR, energy_step
from agentsim_env.scenarios.uav_outcome import final_bonus, oracle_fnd
from agentsim_env.scenarios.uav_tracking import DeploymentTracker
from agentsim_env.scenarios.uav_zones import ZoneSet
from agentsim_env.sensors.proximity import ProximityConfig


class UavReleaseScenario(Scenario):
    """UAV sensor release over hot zones; see the module docstring for layouts and rewards."""

    name = "uav_release"
    config_cls = UavReleaseConfig
    version = 0
    agent_prefix = "uav"
    test_configs = (
        {"zones": "tiny", "n_uavs": 2, "payload": 12, "max_steps": 400},
        {
            "zones": "tiny",
            "n_uavs": 3,
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
        self.lidar = ProximityConfig(n_azimuth=c.n_azimuth, elevations_deg=tuple(c.elevations_deg))
        w, h = self.zones.map_size
        self.diag = float(np.hypot(w, h))
        self.limits = MotionLimits(max_speed=c.max_speed, max_accel=c.max_accel, max_radius=min(w, h) / 4,
                                   max_duration=30.0, z_min=c.altitude[0], z_max=c.altitude[1], max_omega=1.0,
                                   arrival_radius=1.0)  # fmt: skip
        self.fall = FallParams(mass=c.sensor_mass, cd=c.sensor_cd, area=c.sensor_area)
        self.payloads = PayloadSet(self.fall, c.scatter)
        self.fnd_oracle = oracle_fnd(self.zones, c.wsn)
        self.rng = np.random.default_rng(0)
        self._released = np.zeros(0, dtype=np.int64)  # slots that released in the current step

    @property
    def n_agents(self) -> int:
        """UAVs per world."""
        return int(self.config.n_uavs)

    def build(self, n_worlds: int) -> World:
        """World over the zones' map; payload, wind and deployment trackers for ``n_worlds`` worlds."""
        c = self.config
        w, h = self.zones.map_size
        wc = WorldConfig(bounds=(0.0, w, 0.0, h), z_range=(0.0, c.altitude[1]), dt=c.dt, physics=c.physics,
                         collisions=c.collisions, lidar=self.lidar, grid_cell=max(c.sensor_range / 2, 5.0))  # fmt: skip
        world = World(wc, n_worlds, c.n_uavs, comms=c.comms)
        st = world.state
        # one group: the whole fleet
        st.configure(radius=c.uav_radius, sensor_range=c.sensor_range, max_speed=c.max_speed,
                     max_accel=c.max_accel)  # fmt: skip
        self.payload_left = np.zeros(st.n_slots, dtype=np.int64)
        self.wind = WindModel(c.wind, self.rng, n_worlds)
        self.tracker = DeploymentTracker(self.zones, n_worlds, c.wsn.r_s)
        self.finished = np.zeros(n_worlds, dtype=bool)
        return world

    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        """UAVs at the base with full payload and battery; new wind; no sensors."""
        c, st = self.config, world.state
        sl = st.slots_of_world(w)
        base = np.asarray(self.zones.base if self.zones.base is not None else (10.0, 10.0))
        offs = np.column_stack([np.arange(c.n_uavs) * 3.0, np.zeros(c.n_uavs)])
        st.pos[sl] = np.column_stack([base + offs, np.full(c.n_uavs, c.altitude[0])])
        st.vel[sl], st.heading[sl], st.energy[sl] = 0.0, 0.0, 0.0
        st.online[sl] = True
        self.payload_left[sl] = c.payload
        set_hold(world.motion, sl)
        self.wind.reset(rng, world=[w])
        self.payloads.clear_world(w)
        self.tracker.reset_world(w)
        self.finished[w] = False
        if w == 0:
            self.rng = rng.spawn(1)[0]

    def obs_parts(self) -> dict[str, Part]:
        """self, lidar, zones, landed, inbox, comms."""
        c = self.config
        parts = {"self": Part((10,), -1.0, 1.0), "lidar": Part((self.lidar.n_rays, 2), 0.0, 1.0),
                 "zones": Part((len(self.zones.zones), 5), -1.0, 1.0),
                 "landed": Part((c.grid_cells, c.grid_cells), 0.0, 1.0)}  # fmt: skip
        return {**parts, **self.comm_obs_parts()}

    def act_parts(self) -> dict[str, Part]:
        """motion, release, comm."""
        motion = Part((3 if self.config.action_mode == "velocity" else 8,), -1.0, 1.0)
        return {"motion": motion, "release": Part((3,), -1.0, 1.0), **self.comm_act_parts()}

    def state_size(self) -> int:
        """Base state plus payload left and battery used per UAV."""
        return self.n_agents * 10

    def apply_actions(self, world: World, actions: dict[str, np.ndarray], acting: np.ndarray) -> None:
        """Motion commands, then releases from the UAVs' current position and velocity."""
        c, st = self.config, world.state
        slots = np.flatnonzero(acting)
        if c.action_mode == "velocity":
            decode_velocity(world.motion, slots, actions["motion"][slots], st.max_speed[slots])
        else:
            decode_primitive(world.motion, slots, actions["motion"][slots], st.pos, self.limits)
        rel = actions["release"]
        go = np.flatnonzero(acting & st.online & (rel[:, 0] > 0) & (self.payload_left > 0))
        if go.size:
            target = st.pos[go, :2] + rel[go, 1:3] * c.target_scale
            t = float(world.step_count[st.world_id[go[0]]]) * c.dt
            self.payloads.release(go, st.world_id[go], st.pos[go], st.vel[go], t, self.zones.zone_index(target),
                                  target, self.rng)  # fmt: skip
            self.payload_left[go] -= 1
        self._released = go

    def after_world_step(self, world: World, events: StepEvents, acting: np.ndarray) -> StepResult:
        """Falling sensors land; coverage, fidelity, energy and miss terms; end of mission bonus."""
        c, st = self.config, world.state
        s = st.n_slots
        landed = self.payloads.step(c.dt, self.wind, self.rng)
        task = np.zeros(s)
        n_landed = np.zeros(s)
        if landed.size:
            idx = self.payloads.index_of(landed)
            get = self.payloads.get
            owner, wld, zone = get("owner")[idx], get("world")[idx], get("zone")[idx]
            land, target = get("land_xy")[idx], get("target_xy")[idx]
            gain, dw1 = self.tracker.land(wld, land, zone)
            radius = np.where(zone >= 0, self.zones.radii()[np.maximum(zone, 0)], c.target_scale)
            miss = np.nan_to_num(np.linalg.norm(land - target, axis=1) / radius)
            out = self.zones.zone_index(land) < 0
            term = c.w_coverage * gain - c.w_fidelity * dw1 - c.w_miss * miss - c.w_out * out
            np.add.at(task, owner, term)
            np.add.at(n_landed, owner, 1.0)
        mass = DEFAULT_ROTOR.mass_kg + self.payload_left * c.sensor_mass
        energy = np.where(st.online, energy_step(st.vel, mass, c.dt), 0.0)
        st.energy += energy
        task -= c.w_energy * energy / c.battery_j
        empty_battery = acting & (st.energy >= c.battery_j)
        collided = np.zeros(s)
        collided[events.went_offline] = 1.0
        # mission complete in a world, nothing falling and: every zone's sensors landed, or nothing left on board
        n = c.n_uavs
        left = (self.payload_left * st.online).reshape(-1, n).sum(axis=1)
        ps_world = self.payloads.get("world")
        falling = np.bincount(ps_world[self.payloads.get("falling")], minlength=world.n_worlds)
        down = np.bincount(ps_world[self.payloads.get("landed")], minlength=world.n_worlds)
        complete = (falling == 0) & ((left == 0) | (down >= self.zones.n_sensors))
        done_now = ~self.finished & (complete | (world.step_count >= c.max_steps))
        terminated = empty_battery.copy()
        for w in np.flatnonzero(done_now).tolist():
            self.finished[w] = True
            sl = st.slots_of_world(w)
            task[sl] += final_bonus(self.payloads, w, self.zones, c, self.fnd_oracle)
            terminated[sl] |= world.step_count[w] < c.max_steps  # finished, not cut off by the time limit
        rewards = compose_rewards(c.reward, task, group=st.group, world=st.world_id, acting=acting, n_groups=1,
                                  collided=collided, messages_sent=world.comms.sent if world.comms else None)  # fmt: skip
        released = np.zeros(s, dtype=np.int8)
        released[self._released] = 1
        cov = np.repeat([self.tracker.weighted_coverage(w) for w in range(world.n_worlds)], n)
        info: dict[str, np.ndarray] = {
            "released": released, "landed": n_landed.astype(np.int8), "payload_left": self.payload_left.copy(),
            "energy_j": st.energy.copy(), "coverage_weighted": cov,
        }  # fmt: skip
        return StepResult(rewards, terminated & acting, info)

    def observe(self, world: World) -> dict[str, np.ndarray]:
        """Observation parts for every slot (see the module docstring)."""
        c, st = self.config, world.state
        w, h = self.zones.map_size
        lo, hi = c.altitude
        selfp = np.column_stack(
            [
                st.pos[:, 0] / w * 2 - 1,
                st.pos[:, 1] / h * 2 - 1,
                (st.pos[:, 2] - lo) / (hi - lo) * 2 - 1,
                st.vel / c.max_speed,
                np.cos(st.heading),
                np.sin(st.heading),
                self.payload_left / c.payload,
                1.0 - st.energy / c.battery_j,
            ]
        )
        scan = world.scan
        assert scan is not None
        rel = self.zones.centres()[None, :, :] - st.pos[:, None, :2]
        demand = self._demand(world)[st.world_id]
        wts = self.zones.weights()
        radius = np.broadcast_to(self.zones.radii() / self.diag, rel.shape[:2])
        zones = np.concatenate([rel / self.diag, radius[..., None], demand[..., None],
                                np.broadcast_to(wts / wts.max(), rel.shape[:2])[..., None]], axis=2)  # fmt: skip
        ps = self.payloads
        done = ps.get("landed")
        grid = local_counts(st.pos[:, :2], st.world_id, ps.get("land_xy")[done], ps.get("world")[done],
                            c.grid_cells, c.grid_extent)  # fmt: skip
        return {
            "self": np.clip(selfp, -1, 1).astype(np.float32),
            "lidar": np.stack([scan.distance, scan.hit_kind / 3.0], axis=-1).astype(np.float32),
            "zones": np.clip(zones, -1, 1).astype(np.float32),
            "landed": grid,
            **self.comm_observe(world),
        }

    def _demand(self, world: World) -> np.ndarray:
        """Unmet demand per (world, zone): sensors not yet landed or falling there / n_sensors."""
        k = len(self.zones.zones)
        ps = self.payloads
        zone, wld = ps.get("zone"), ps.get("world")
        ok = zone >= 0
        got = np.bincount(wld[ok] * k + zone[ok], minlength=world.n_worlds * k).reshape(world.n_worlds, k)
        need = np.array([z.n_sensors for z in self.zones.zones], dtype=np.float64)
        return np.clip((need - got) / need, 0.0, 1.0)

    def state(self, world: World, w: int) -> np.ndarray:
        """Base state plus payload left / payload and battery used / capacity per UAV."""
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        extra = np.column_stack([self.payload_left[sl] / self.config.payload,
                                 world.state.energy[sl] / self.config.battery_j])  # fmt: skip
        return np.concatenate([super().state(world, w), extra.ravel()]).astype(np.float32)

    def markers(self, world: World, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Zones as tinted discs, landed sensors as dark dots, falling ones as orange dots."""
        ps = self.payloads
        mine = ps.get("world") == w
        landed, falling = mine & ps.get("landed"), mine & ps.get("falling")
        tints = np.array([[205, 225, 245], [245, 220, 200], [215, 240, 210], [240, 215, 240]], dtype=np.uint8)
        k = len(self.zones.zones)
        xy = np.vstack([self.zones.centres(), ps.get("land_xy")[landed], ps.get("pos")[falling, :2]])
        rgb = np.vstack([tints[np.arange(k) % 4], np.tile([[40, 40, 40]], (landed.sum(), 1)),
                         np.tile([[240, 140, 20]], (falling.sum(), 1))]).astype(np.uint8)  # fmt: skip
        rad = np.concatenate([self.zones.radii(), np.full(landed.sum() + falling.sum(), 1.2)])
        return xy, rgb, rad


SCENARIO = UavReleaseScenario


def parallel_env(**config: object):  # type: ignore[no-untyped-def]
    """The ``uav_release`` ParallelEnv (``render_mode``, ``obs_format``, ``action_format`` plus config keys)."""
    from agentsim_env import make

    return make("uav_release", **config)


def env(**config: object):  # type: ignore[no-untyped-def]
    """The ``uav_release`` env in PettingZoo's AEC form."""
    from agentsim_env.env.parallel_env import to_aec

    return to_aec(parallel_env(**config))
