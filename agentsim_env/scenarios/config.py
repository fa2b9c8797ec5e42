"""Shared scenario configuration: the base every scenario config extends and its sub-configs.

A scenario config is a frozen dataclass that extends :class:`ScenarioConfig`, so the fields every scenario has
(the agent count, the body, the sensing, the episode, the world switches, rewards and communication) are declared
once. A scenario changes a sub-config's defaults by redeclaring the field with its own default, e.g.
``body: BodyConfig = field(default_factory=lambda: BodyConfig(max_speed=15.0))``; a user's dict for a
sub-config overrides only the fields it names, on top of the scenario's default (``{"body": {"radius": 1.0}}``).
Unknown keys and bad values raise ``ValueError`` naming the field and the allowed values.
"""

from __future__ import annotations

import typing
from dataclasses import field
from typing import Annotated, ClassVar, Literal

from pydantic import AfterValidator, Field

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.config_model import Choice, FieldError, Flag, Int, Real, config, ordered
from agentsim_env.core.validation import build_config
from agentsim_env.scenarios.rewards import RewardConfig
from agentsim_env.sim.config import Physics

ActionMode = Annotated[Literal["velocity", "primitive"], Choice]
"""How actions move agents: a target velocity, or a motion primitive and its parameters."""
ACTION_MODES: tuple[str, ...] = typing.get_args(typing.get_args(ActionMode)[0])
MAX_AGENTS = 1_000_000
"""Most agents a world may hold (memory is also checked against the machine before allocating)."""
MAX_STEPS = 10**9
"""Longest episode, in steps."""
MAX_RINGS = 64
"""Most elevation rings of the proximity sensor."""

Limit = Annotated[Real, Field(ge=0.01, le=1e4)]
"""A body size or motion limit, 0.01..1e4."""
Height = Annotated[Real, Field(ge=0.0, le=1e4)]
"""An altitude in metres, 0..1e4."""
Elevation = Annotated[Real, Field(ge=-90.0, le=90.0)]
"""A ray elevation in degrees, -90..90."""
HalfWidth = Annotated[Real, Field(ge=0.01, le=100.0)]
"""An obstacle half-width in metres, 0.01..100."""
ObstacleHeight = Annotated[Real, Field(ge=0.01, le=1e4)]
"""An obstacle height in metres, 0.01..1e4."""
ObstacleSizes = Annotated[tuple[HalfWidth, HalfWidth], AfterValidator(ordered)]
"""``(low, high)`` obstacle half-widths, ``0.01 <= low <= high <= 100``."""
ObstacleHeights = Annotated[tuple[ObstacleHeight, ObstacleHeight], AfterValidator(ordered)]
"""``(low, high)`` obstacle heights, ``0.01 <= low <= high <= 1e4``."""


@config("body")
class BodyConfig:
    """An agent's body and motion limits.

    Attributes:
        radius: Collision radius in metres, 0.01..1e4.
        max_speed: Speed limit in m/s, 0.01..1e4.
        max_accel: Acceleration limit in m/s^2, 0.01..1e4.
        altitude: Flight band ``(low, high)`` in metres: ``0 <= low``, ``high <= 1e4``, ``high - low >= 0.1``.
    """

    radius: Limit = 0.5
    max_speed: Limit = 5.0
    max_accel: Limit = 10.0
    altitude: tuple[Height, Height] = (2.0, 12.0)

    def __post_init__(self) -> None:
        lo, hi = self.altitude
        if hi - lo < 0.1:
            raise FieldError("altitude", f"must span at least 0.1 m (high - low >= 0.1), got {self.altitude}")


@config("sensing")
class SensingConfig:
    """The proximity sensor (a laser-scanner-like fan of rays).

    Attributes:
        range: Ray length in metres, 0.01..1e5.
        n_azimuth: Rays per elevation ring (1..1024); ray 0 points along the heading.
        elevations_deg: Elevation of each ring in degrees (negative looks down), each in [-90, 90]; 1..64
            rings.
    """

    range: Annotated[Real, Field(ge=0.01, le=1e5)] = 10.0
    n_azimuth: Annotated[Int, Field(ge=1, le=1024)] = 16
    elevations_deg: tuple[Elevation, ...] = (0.0, -25.0)

    def __post_init__(self) -> None:
        if not 1 <= len(self.elevations_deg) <= MAX_RINGS:
            raise FieldError("elevations_deg", f"must hold 1..{MAX_RINGS} elevations, got {self.elevations_deg!r}")


@config()
class ScenarioConfig:
    """Fields every scenario config has (extend it; redeclare a field to change its default).

    Attributes:
        n_agents: Agents per world, 1..1,000,000 (scenarios may lower the bound; the memory a world needs is
            estimated and checked against the machine before anything is allocated, see ``core.budget``).
        body: Body and motion limits of every agent.
        sensing: The proximity sensor.
        action_mode: ``"velocity"`` (a target velocity) or ``"primitive"`` (a motion primitive and its
            parameters; ``agentsim_env.motion.actions``).
        physics: ``"kinematic"`` or ``"pymunk"`` (planar contact resolution).
        collisions: Whether collisions are detected (and end the agents hit); a bool.
        dt: Step length in seconds, 0.001..10.
        max_steps: Steps after which every live agent is truncated, 1..10^9.
        reward: The reward composer's weights.
        comms: Communication (``None``: no bus, overlay, groups stage, inbox or ``comm`` action).
    """

    #: Sub-config fields: a dict given for one of them overrides the fields it names of the field's default.
    nested: ClassVar[dict[str, type]] = {
        "body": BodyConfig,
        "sensing": SensingConfig,
        "reward": RewardConfig,
        "comms": CommsConfig,
    }

    n_agents: Annotated[Int, Field(ge=1, le=MAX_AGENTS)] = 4
    body: BodyConfig = field(default_factory=BodyConfig)
    sensing: SensingConfig = field(default_factory=SensingConfig)
    action_mode: ActionMode = "velocity"
    physics: Physics = "kinematic"
    collisions: Flag = True
    dt: Annotated[Real, Field(ge=1e-3, le=10.0)] = 0.1
    max_steps: Annotated[Int, Field(ge=1, le=MAX_STEPS)] = 400
    reward: RewardConfig = field(default_factory=RewardConfig)
    comms: CommsConfig | None = None


__all__ = [
    "ACTION_MODES",
    "BodyConfig",
    "ObstacleHeights",
    "ObstacleSizes",
    "ScenarioConfig",
    "SensingConfig",
    "build_config",
]
