"""Configuration of the ``relay`` scenario: geometry, sensing, rewards and the default comms settings.

Field meanings and the layouts they produce are documented in ``agentsim_env.scenarios.relay``.
"""

from __future__ import annotations

from dataclasses import field
from typing import Annotated

from pydantic import AfterValidator, Field

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.config_model import FieldError, Int, Real, config, in_range, ordered
from agentsim_env.scenarios.config import (
    BodyConfig,
    ObstacleHeights,
    ObstacleSizes,
    ScenarioConfig,
    SensingConfig,
)
from agentsim_env.scenarios.rewards import RewardConfig

RELAY_COMMS = CommsConfig(
    payload_dim=4, inbox_size=8, max_range=35.0, overlay_range=35.0, max_hops=8, nearest_range=35.0
)
"""The default communication settings (a ``comms`` dict overrides some of these fields)."""


Distance = Annotated[Real, Field(ge=0.0, le=1e3)]
"""A distance in metres, 0..1e3."""
Distances = Annotated[tuple[Distance, Distance], AfterValidator(ordered)]
"""``(low, high)`` distances, ``0 <= low <= high <= 1e3``."""


@config()
class RelayConfig(ScenarioConfig):
    """Configuration of ``relay`` (every field validated at construction; shared fields in ``ScenarioConfig``).

    The agent count is ``n_groups x group_size``: give ``n_agents`` (a multiple of ``n_groups``) or
    ``group_size`` (default 4), or both when they agree.

    Attributes:
        n_groups: Groups (one scout each), 1..64.
        group_size: Agents per group, 2..256 (``None``: from ``n_agents``, else 4).
        corridor_width: Corridor width in metres, ``2 x lateral_spread + 4`` .. 1e4.
        gap: ``(low, high)`` distance along x between consecutive start points,
            ``2 x body.radius + 0.5 <= low <= high <= 1e3`` (neighbours start clear of each other).
        lateral_spread: Start points lie within this distance of the centre line, 0..1e3 metres.
        target_offset: ``(low, high)`` distance scout -> target, ``0 <= low <= high <= 1e3``.
        obstacle_density: Obstacles per square metre, 0..0.01.
        obstacle_size: ``(low, high)`` obstacle half-width, ``0.01 <= low <= high <= 100``.
        obstacle_height: ``(low, high)`` obstacle height, ``0.01 <= low <= high <= 1e4``.
        arrival_radius: Arrival distance in metres, in (0, 1e3].
        arrival_bonus: Reward on arrival, 0..1e6.

    The corridor (``(n_agents - 1) x gap[1] + 2 x (target_offset[1] + 5)`` metres) must be at most 1e5 m
    (2e4 m with ``physics="pymunk"``).
    """

    n_agents: Int | None = None  # type: ignore[assignment]  # None: n_groups x group_size
    n_groups: Annotated[Int, Field(ge=1, le=64)] = 3
    group_size: Annotated[Int, Field(ge=2, le=256)] | None = None  # the scout plus group_size - 1 members
    corridor_width: Annotated[Real, Field(le=1e4)] = 40.0  # at least 2 x lateral_spread + 4
    gap: Distances = (12.0, 22.0)  # distance along x between consecutive start points
    lateral_spread: Distance = 8.0  # start points lie within this distance of the corridor's centre line
    target_offset: Distances = (4.0, 10.0)  # distance scout -> target
    obstacle_density: Annotated[Real, Field(ge=0.0, le=0.01)] = 1.0 / 1000.0
    obstacle_size: ObstacleSizes = (1.0, 2.5)
    obstacle_height: ObstacleHeights = (4.0, 20.0)
    arrival_radius: Annotated[Real, Field(gt=0.0, le=1e3)] = 3.0
    arrival_bonus: Annotated[Real, Field(ge=0.0, le=1e6)] = 10.0
    body: BodyConfig = field(default_factory=lambda: BodyConfig(max_speed=6.0, altitude=(4.0, 10.0)))
    sensing: SensingConfig = field(
        default_factory=lambda: SensingConfig(range=8.0, n_azimuth=12, elevations_deg=(0.0,))
    )
    reward: RewardConfig = field(
        default_factory=lambda: RewardConfig(group_share=0.5, energy_weight=0.001, message_cost=0.01)
    )
    comms: CommsConfig = RELAY_COMMS  # type: ignore[assignment]  # a dict overrides fields of RELAY_COMMS

    def __post_init__(self) -> None:
        if self.n_agents is None:
            size = 4 if self.group_size is None else self.group_size
            object.__setattr__(self, "group_size", size)
            object.__setattr__(self, "n_agents", self.n_groups * size)
        else:
            in_range("n_agents", self.n_agents, 2 * self.n_groups, 256 * self.n_groups)
            if self.n_agents % self.n_groups:
                raise ValueError(f"n_agents ({self.n_agents}) must be a multiple of n_groups ({self.n_groups})")
            size = self.n_agents // self.n_groups
            if self.group_size is not None and self.group_size != size:
                raise ValueError(
                    f"n_agents ({self.n_agents}) must equal n_groups x group_size "
                    f"({self.n_groups} x {self.group_size}); give one of the two"
                )
            object.__setattr__(self, "group_size", size)
        if self.comms is None:
            raise FieldError("comms", "must be a CommsConfig or a dict of its fields (relay needs comms), got None")
        in_range("corridor_width", self.corridor_width, 2.0 * self.lateral_spread + 4.0)
        in_range("gap[0]", self.gap[0], 2.0 * self.body.radius + 0.5)  # neighbours start clear of each other
        limit = 2e4 if self.physics == "pymunk" else 1e5
        if self.length > limit:
            raise ValueError(
                f"the corridor is (n_agents - 1) x gap[1] + 2 x (target_offset[1] + 5) = "
                f"{self.length:.0f} m long, over the {limit:.0f} m limit"
                f"{' of physics=pymunk' if self.physics == 'pymunk' else ''}; lower n_agents or gap"
            )

    @property
    def margin(self) -> float:
        """Free space at each end of the corridor (room for targets beyond the end points)."""
        return float(self.target_offset[1]) + 5.0

    @property
    def length(self) -> float:
        """Corridor length in metres: the longest possible chain plus a margin at both ends."""
        return (int(self.n_agents or 0) - 1) * float(self.gap[1]) + 2.0 * self.margin
