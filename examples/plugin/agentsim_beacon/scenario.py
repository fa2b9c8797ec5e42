"""beacon: N agents fly to a beacon at the centre of the map.

Observation: ``self (6,)`` position over the map and band, velocity / max_speed; ``lidar (K, 2)``; ``task (3,)``
beacon minus position / map side (x, y, z). Action: ``motion`` (3,) velocity. Reward: progress toward the
beacon (metres) + ``bonus`` on arrival within ``radius``, which ends that agent's episode. Version history: v0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field

from agentsim_env import Scenario, World
from agentsim_env.core.config_model import Real, config
from agentsim_env.scenarios.base import SlotState, StepResult, slot
from agentsim_env.scenarios.config import ScenarioConfig
from agentsim_env.sensors.proximity import ProximitySensor
from agentsim_env.sim import StepEvents, WorldConfig


@config()
class BeaconConfig(ScenarioConfig):
    """``beacon``: the shared fields plus the map side (10..1e4 m), the arrival radius (0.1..1e4 m), the bonus."""

    side: Annotated[Real, Field(ge=10.0, le=1e4)] = 40.0
    radius: Annotated[Real, Field(ge=0.1, le=1e4)] = 3.0
    bonus: Annotated[Real, Field(ge=0.0, le=1e6)] = 10.0


@dataclass(slots=True)
class BeaconSlots(SlotState):
    """Each agent's last distance to the beacon."""

    prev_dist: np.ndarray = slot()


class Beacon(Scenario[BeaconConfig]):
    """Fly to the beacon; see the module docstring."""

    name, config_cls, test_configs = "beacon", BeaconConfig, ({"n_agents": 3},)

    def make_world(self, n_worlds: int) -> World:
        c = self.config
        wc = WorldConfig(bounds=(0.0, c.side, 0.0, c.side), z_range=(0.0, c.body.altitude[1] + 5.0), dt=c.dt)
        world = World(wc, n_worlds, c.n_agents, sensors=[ProximitySensor(self.lidar)], comms=c.comms)
        world.state.configure(
            radius=c.body.radius,
            sensor_range=c.sensing.range,
            max_speed=c.body.max_speed,
            max_accel=c.body.max_accel,
        )
        world.task = BeaconSlots.allocate(world.state.n_slots)
        return world

    def _beacon(self) -> np.ndarray:
        c = self.config
        return np.array([c.side / 2, c.side / 2, sum(c.body.altitude) / 2])

    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        c, st, sl = self.config, world.state, world.state.slots_of_world(world=w)
        st.pos[sl] = np.column_stack(
            [rng.uniform(2, c.side - 2, (c.n_agents, 2)), rng.uniform(*c.body.altitude, c.n_agents)]
        )
        st.vel[sl], st.online[sl] = 0.0, True
        world.task.prev_dist[sl] = np.linalg.norm(st.pos[sl] - self._beacon(), axis=1)

    def score(
        self,
        world: World,
        events: StepEvents,
        acting: np.ndarray,
        totals: dict[str, np.ndarray] | None = None,
    ) -> StepResult:
        st, t = world.state, world.task
        dist = np.linalg.norm(st.pos - self._beacon(), axis=1)
        arrived = acting & (dist <= self.config.radius)
        reward = np.where(acting, t.prev_dist - dist, 0.0) + self.config.bonus * arrived
        np.copyto(t.prev_dist, dist)
        return StepResult(reward, arrived, {"distance": dist, "arrived": arrived.astype(np.int8)})

    def observe(self, world: World) -> dict[str, np.ndarray]:
        c, st = self.config, world.state
        lo, hi = c.body.altitude
        xyz = (st.pos - [0.0, 0.0, lo]) / [c.side, c.side, hi - lo] * 2 - 1
        me = np.column_stack([xyz, st.vel / c.body.max_speed])
        return {
            "self": np.clip(me, -1, 1).astype(np.float32),
            "lidar": world.sensors[0].observe(world.scan),
            "task": np.clip((self._beacon() - st.pos) / c.side, -1, 1).astype(np.float32),
        }
