"""Configuration of the ``relay`` scenario: geometry, sensing, rewards and the default comms settings.

Field meanings and the layouts they produce are documented in ``agentsim_env.scenarios.relay``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.world import PHYSICS_MODES
from agentsim_env.scenarios.config import build_config, check_choice, check_float, check_int
from agentsim_env.scenarios.rewards import RewardConfig

RELAY_COMMS = CommsConfig(payload_dim=4, inbox_size=8, max_range=35.0, overlay_range=35.0, max_hops=8,
                          nearest_range=35.0)  # fmt: skip
"""The default communication settings (a ``comms`` dict overrides some of these fields)."""


@dataclass(frozen=True)
class RelayConfig:
    """Configuration of ``relay`` (every field validated at construction)."""

    n_groups: int = 3
    group_size: int = 4  # the scout plus group_size - 1 members that must reach the target
    corridor_width: float = 40.0
    gap: tuple[float, float] = (12.0, 22.0)  # distance along x between consecutive start points
    lateral_spread: float = 8.0  # start points lie within this distance of the corridor's centre line
    altitude: tuple[float, float] = (4.0, 10.0)
    target_offset: tuple[float, float] = (4.0, 10.0)  # distance scout -> target
    obstacle_density: float = 1.0 / 1000.0
    obstacle_size: tuple[float, float] = (1.0, 2.5)
    obstacle_height: tuple[float, float] = (4.0, 20.0)
    agent_radius: float = 0.5
    max_speed: float = 6.0
    max_accel: float = 10.0
    sensor_range: float = 8.0
    n_azimuth: int = 12
    elevations_deg: tuple[float, ...] = (0.0,)
    arrival_radius: float = 3.0
    arrival_bonus: float = 10.0
    physics: str = "kinematic"
    collisions: bool = True
    dt: float = 0.1
    max_steps: int = 400
    reward: RewardConfig = field(
        default_factory=lambda: RewardConfig(group_share=0.5, energy_weight=0.001, message_cost=0.01)
    )
    comms: CommsConfig = RELAY_COMMS  # a dict overrides fields of RELAY_COMMS

    def __post_init__(self) -> None:
        check_int("n_groups", self.n_groups, 1, 64)
        check_int("group_size", self.group_size, 2, 256)
        for name in ("corridor_width", "agent_radius", "max_speed", "max_accel", "sensor_range",
                     "arrival_radius", "dt"):  # fmt: skip
            check_float(name, getattr(self, name), 0.0, lo_open=True)
        check_float("lateral_spread", self.lateral_spread, 0.0)
        check_float("corridor_width", self.corridor_width, 2.0 * self.lateral_spread + 4.0)
        check_float("obstacle_density", self.obstacle_density, 0.0, 0.01)
        check_float("arrival_bonus", self.arrival_bonus, 0.0)
        check_int("n_azimuth", self.n_azimuth, 1, 1024)
        check_int("max_steps", self.max_steps, 1)
        check_choice("physics", self.physics, PHYSICS_MODES)
        for name in ("gap", "altitude", "target_offset", "obstacle_size", "obstacle_height"):
            pair = getattr(self, name)
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise ValueError(f"{name} must be a pair (low, high), got {pair!r}")
            check_float(f"{name}[0]", pair[0], 0.0, lo_open=name == "gap")
            check_float(f"{name}[1]", pair[1], pair[0])
        if isinstance(self.reward, dict):
            object.__setattr__(self, "reward", build_config(RewardConfig, self.reward))
        if not isinstance(self.reward, RewardConfig):
            raise ValueError(f"reward must be a RewardConfig or a dict of its fields, got {self.reward!r}")
        if isinstance(self.comms, dict):
            unknown = sorted(set(self.comms) - set(asdict(RELAY_COMMS)))
            if unknown:
                raise ValueError(
                    f"unknown comms key(s) {unknown}; allowed keys: {sorted(asdict(RELAY_COMMS))}"
                )
            object.__setattr__(
                self, "comms", build_config(CommsConfig, {**asdict(RELAY_COMMS), **self.comms})
            )
        if not isinstance(self.comms, CommsConfig):
            raise ValueError(
                f"comms must be a CommsConfig or a dict of its fields (relay needs comms), got {self.comms!r}"
            )

    @property
    def n_agents(self) -> int:
        """Agents per world."""
        return self.n_groups * self.group_size

    @property
    def margin(self) -> float:
        """Free space at each end of the corridor (room for targets beyond the end points)."""
        return float(self.target_offset[1]) + 5.0

    @property
    def length(self) -> float:
        """Corridor length in metres: the longest possible chain plus a margin at both ends."""
        return (self.n_agents - 1) * float(self.gap[1]) + 2.0 * self.margin
