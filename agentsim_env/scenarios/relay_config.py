"""Configuration of the ``relay`` scenario: geometry, sensing, rewards and the default comms settings.

Field meanings and the layouts they produce are documented in ``agentsim_env.scenarios.relay``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.validation import check_float, check_int
from agentsim_env.scenarios.config import BodyConfig, ScenarioConfig, SensingConfig
from agentsim_env.scenarios.rewards import RewardConfig

RELAY_COMMS = CommsConfig(payload_dim=4, inbox_size=8, max_range=35.0, overlay_range=35.0, max_hops=8,
                          nearest_range=35.0)  # fmt: skip
"""The default communication settings (a ``comms`` dict overrides some of these fields)."""


@dataclass(frozen=True)
class RelayConfig(ScenarioConfig):
    """Configuration of ``relay`` (every field validated at construction; shared fields in ``ScenarioConfig``).

    The agent count is ``n_groups x group_size``: give ``n_agents`` (a multiple of ``n_groups``) or
    ``group_size`` (default 4), or both when they agree.
    """

    n_agents: int | None = None  # type: ignore[assignment]  # None: n_groups x group_size
    n_groups: int = 3
    group_size: int | None = None  # the scout plus group_size - 1 members that must reach the target
    corridor_width: float = 40.0
    gap: tuple[float, float] = (12.0, 22.0)  # distance along x between consecutive start points
    lateral_spread: float = 8.0  # start points lie within this distance of the corridor's centre line
    target_offset: tuple[float, float] = (4.0, 10.0)  # distance scout -> target
    obstacle_density: float = 1.0 / 1000.0
    obstacle_size: tuple[float, float] = (1.0, 2.5)
    obstacle_height: tuple[float, float] = (4.0, 20.0)
    arrival_radius: float = 3.0
    arrival_bonus: float = 10.0
    body: BodyConfig = field(default_factory=lambda: BodyConfig(max_speed=6.0, altitude=(4.0, 10.0)))
    sensing: SensingConfig = field(default_factory=lambda: SensingConfig(range=8.0, n_azimuth=12,
                                                                        elevations_deg=(0.0,)))  # fmt: skip
    reward: RewardConfig = field(
        default_factory=lambda: RewardConfig(group_share=0.5, energy_weight=0.001, message_cost=0.01)
    )
    comms: CommsConfig = RELAY_COMMS  # type: ignore[assignment]  # a dict overrides fields of RELAY_COMMS

    def __post_init__(self) -> None:
        check_int("n_groups", self.n_groups, 1, 64)
        if self.group_size is not None:
            check_int("group_size", self.group_size, 2, 256)
        if self.n_agents is None:
            size = 4 if self.group_size is None else self.group_size
            object.__setattr__(self, "group_size", size)
            object.__setattr__(self, "n_agents", self.n_groups * size)
        else:
            check_int("n_agents", self.n_agents, 2 * self.n_groups, 256 * self.n_groups)
            if self.n_agents % self.n_groups:
                raise ValueError(f"n_agents ({self.n_agents}) must be a multiple of n_groups ({self.n_groups})")
            size = self.n_agents // self.n_groups
            if self.group_size is not None and self.group_size != size:
                raise ValueError(f"n_agents ({self.n_agents}) must equal n_groups x group_size "
                                 f"({self.n_groups} x {self.group_size}); give one of the two")  # fmt: skip
            object.__setattr__(self, "group_size", size)
        super().__post_init__()
        if self.comms is None:
            raise ValueError("comms must be a CommsConfig or a dict of its fields (relay needs comms), got None")
        check_float("corridor_width", self.corridor_width, 0.0, lo_open=True)
        check_float("lateral_spread", self.lateral_spread, 0.0)
        check_float("corridor_width", self.corridor_width, 2.0 * self.lateral_spread + 4.0)
        check_float("obstacle_density", self.obstacle_density, 0.0, 0.01)
        check_float("arrival_radius", self.arrival_radius, 0.0, lo_open=True)
        check_float("arrival_bonus", self.arrival_bonus, 0.0)
        for name in ("gap", "target_offset", "obstacle_size", "obstacle_height"):
            pair = getattr(self, name)
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise ValueError(f"{name} must be a pair (low, high), got {pair!r}")
            check_float(f"{name}[0]", pair[0], 0.0, lo_open=name == "gap")
            check_float(f"{name}[1]", pair[1], pair[0])

    @property
    def margin(self) -> float:
        """Free space at each end of the corridor (room for targets beyond the end points)."""
        return float(self.target_offset[1]) + 5.0

    @property
    def length(self) -> float:
        """Corridor length in metres: the longest possible chain plus a margin at both ends."""
        return (int(self.n_agents or 0) - 1) * float(self.gap[1]) + 2.0 * self.margin
