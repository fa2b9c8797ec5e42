"""rendezvous: N agents meet at their centroid (the tutorial scenario of ``docs/new_scenario.md``).

Observation: ``self (6,)`` position over the map and band, velocity / max_speed; ``lidar (K, 2)``; ``task (3,)``
centroid of the world's online agents minus position / map side (x, y, z). Action: ``motion`` (3,) velocity.
Reward: progress toward the centroid (metres) + ``bonus`` once every online agent is within ``radius`` of it,
which ends the episode for all. Version history: v0, first release.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import Field

from agentsim_env.core.config_model import Real, config
from agentsim_env.scenarios.base import Scenario, SlotState, StepResult, slot
from agentsim_env.scenarios.config import ScenarioConfig
from agentsim_env.sensors.proximity import ProximitySensor
from agentsim_env.sim import StepEvents, World, WorldConfig


@config()
class RendezvousConfig(ScenarioConfig):
    """``rendezvous``: the shared fields plus the map side (10..1e4 m), the meeting radius (0.1..1e4 m), the bonus."""

    side: Annotated[Real, Field(ge=10.0, le=1e4)] = 60.0
    radius: Annotated[Real, Field(ge=0.1, le=1e4)] = 4.0
    bonus: Annotated[Real, Field(ge=0.0, le=1e6)] = 10.0


@dataclass(slots=True)
class RendezvousSlots(SlotState):
    """Each agent's last distance to the centroid."""

    prev_dist: np.ndarray = slot()


class Rendezvous(Scenario[RendezvousConfig]):
    """Meet at the centroid; see the module docstring."""

    name, config_cls, test_configs = (
        "rendezvous",
        RendezvousConfig,
        ({"n_agents": 4}, {"n_agents": 3, "max_steps": 50}),
    )
    event_keys = ("met",)  # what an evaluation counts per agent: 1 for each agent of a world that met

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
        world.task = RendezvousSlots.allocate(world.state.n_slots)
        return world

    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        c, st, sl = self.config, world.state, world.state.slots_of_world(world=w)
        st.pos[sl] = np.column_stack(
            [rng.uniform(2, c.side - 2, (c.n_agents, 2)), rng.uniform(*c.body.altitude, c.n_agents)]
        )
        st.vel[sl], st.online[sl] = 0.0, True
        world.task.prev_dist[sl] = np.linalg.norm(st.pos[sl] - self._centroid(world)[sl], axis=1)

    def _centroid(self, world: World) -> np.ndarray:
        st = world.state  # the centroid of each world's online agents, per slot
        w = np.where(st.online, 1.0, 0.0).reshape(-1, self.n_agents, 1)
        c = (st.pos.reshape(-1, self.n_agents, 3) * w).sum(1) / np.maximum(w.sum(1), 1.0)
        return np.repeat(c, self.n_agents, axis=0)

    def score(
        self,
        world: World,
        events: StepEvents,
        acting: np.ndarray,
        totals: dict[str, np.ndarray] | None = None,
    ) -> StepResult:
        st, t = world.state, world.task
        dist = np.linalg.norm(st.pos - self._centroid(world), axis=1)
        near = ((dist <= self.config.radius) | ~st.online).reshape(-1, self.n_agents).all(axis=1)
        met = acting & np.repeat(near, self.n_agents)
        reward = np.where(acting, t.prev_dist - dist, 0.0) + self.config.bonus * met
        np.copyto(t.prev_dist, dist)  # the state keeps its array (resets write it); dist goes out as info
        return StepResult(reward, met, {"distance": dist, "met": met.astype(np.int8)})

    def observe(self, world: World) -> dict[str, np.ndarray]:
        c, st, scan = self.config, world.state, world.scan
        lo, hi = c.body.altitude
        xyz = (st.pos - [0.0, 0.0, lo]) / [c.side, c.side, hi - lo] * 2 - 1
        me = np.column_stack([xyz, st.vel / c.body.max_speed])
        return {
            "self": np.clip(me, -1, 1).astype(np.float32),
            "lidar": world.sensors[0].observe(scan),
            "task": np.clip((self._centroid(world) - st.pos) / c.side, -1, 1).astype(np.float32),
        }


SCENARIO = Rendezvous
