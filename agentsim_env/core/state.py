"""Agent state as a struct of arrays over slots.

Every per-agent quantity lives in one numpy array over a flat *slot* axis ``S = n_worlds * n_agents``.
Slot ``s`` belongs to world ``s // n_agents`` and is agent ``s % n_agents`` of that world, so a plain
environment is ``n_worlds = 1`` and a batched vector environment steps ``n_worlds`` independent worlds
with the same code. No per-agent Python objects exist anywhere in the simulator.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np


@dataclass(slots=True)
class AgentState:
    """Per-slot agent state (SI units, z up).

    Attributes:
        n_worlds: Number of independent worlds B.
        n_agents: Agents per world N.
        pos: Positions ``(S, 3)`` in metres.
        vel: Velocities ``(S, 3)`` in m/s.
        heading: Yaw ``(S,)`` in radians (direction of horizontal motion).
        radius: Collision radius ``(S,)`` in metres.
        online: Whether the slot is still in the simulation ``(S,)``.
        group: Group id ``(S,)`` (``-1`` = none).
        role: Scenario-defined role ``(S,)``.
        energy: Energy used so far ``(S,)`` in joules.
        world_id: World of each slot ``(S,)``.
        sensor_range: Proximity-sensor range ``(S,)`` in metres.
        max_speed: Speed limit ``(S,)`` in m/s.
        max_accel: Acceleration limit ``(S,)`` in m/s^2.
        home_group: Group each slot starts every episode in ``(S,)`` (set by ``configure``; a world's reset
            restores ``group`` from it, so run-time reassignments last one episode).
    """

    n_worlds: int
    n_agents: int
    pos: np.ndarray
    vel: np.ndarray
    heading: np.ndarray
    radius: np.ndarray
    online: np.ndarray
    group: np.ndarray
    role: np.ndarray
    energy: np.ndarray
    world_id: np.ndarray
    sensor_range: np.ndarray
    max_speed: np.ndarray
    max_accel: np.ndarray
    home_group: np.ndarray

    @classmethod
    def create(
        cls,
        n_worlds: int,
        n_agents: int,
        *,
        radius: float = 0.5,
        sensor_range: float = 10.0,
        max_speed: float = 5.0,
        max_accel: float = 10.0,
    ) -> AgentState:
        """Allocate a zeroed state for ``n_worlds`` worlds of ``n_agents`` agents each.

        Args:
            n_worlds: Number of independent worlds (>= 1).
            n_agents: Agents per world (>= 1).
            radius: Initial collision radius of every slot.
            sensor_range: Initial proximity-sensor range of every slot.
            max_speed: Initial speed limit of every slot.
            max_accel: Initial acceleration limit of every slot.

        Returns:
            The new state with every slot online.
        """
        if int(n_worlds) < 1:
            raise ValueError(f"n_worlds must be >= 1, got {n_worlds}")
        if int(n_agents) < 1:
            raise ValueError(f"n_agents must be >= 1, got {n_agents}")
        s = int(n_worlds) * int(n_agents)
        return cls(
            n_worlds=int(n_worlds),
            n_agents=int(n_agents),
            pos=np.zeros((s, 3)),
            vel=np.zeros((s, 3)),
            heading=np.zeros(s),
            radius=np.full(s, float(radius)),
            online=np.ones(s, dtype=bool),
            group=np.full(s, -1, dtype=np.int32),
            role=np.zeros(s, dtype=np.int32),
            energy=np.zeros(s),
            world_id=np.repeat(np.arange(n_worlds, dtype=np.int32), n_agents),
            sensor_range=np.full(s, float(sensor_range)),
            max_speed=np.full(s, float(max_speed)),
            max_accel=np.full(s, float(max_accel)),
            home_group=np.full(s, -1, dtype=np.int32),
        )

    def configure(
        self, *, radius: float, sensor_range: float, max_speed: float, max_accel: float, n_groups: int = 1
    ) -> None:
        """Give every slot the same body, sensor and limits; agent ``i`` of each world joins group ``i % n_groups``."""
        self.radius[:] = radius
        self.sensor_range[:] = sensor_range
        self.max_speed[:] = max_speed
        self.max_accel[:] = max_accel
        self.group[:] = np.tile(np.arange(self.n_agents) % n_groups, self.n_worlds)
        self.home_group[:] = self.group

    @property
    def n_slots(self) -> int:
        """Total number of slots S = B * N."""
        return self.n_worlds * self.n_agents

    def slots_of_world(self, world: int) -> np.ndarray:
        """Return the slot indices of one world (a fresh array)."""
        return np.arange(world * self.n_agents, (world + 1) * self.n_agents)

    def copy(self) -> AgentState:
        """Return a deep copy (arrays are copied, never shared)."""
        return copy.deepcopy(self)
