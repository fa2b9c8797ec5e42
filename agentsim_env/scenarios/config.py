"""Shared scenario configuration: the base every scenario config extends and its sub-configs.

A scenario config is a frozen dataclass that extends :class:`ScenarioConfig`, so the fields every scenario has
(the agent count, the body, the sensing, the episode, the world switches, rewards and communication) are declared
once. A scenario changes a sub-config's defaults by redeclaring the field with its own default, e.g.
``body: BodyConfig = field(default_factory=lambda: BodyConfig(max_speed=15.0))``; a user's dict for a
sub-config overrides only the fields it names, on top of the scenario's default (``{"body": {"radius": 1.0}}``).
Unknown keys and bad values raise ``ValueError`` naming the field and the allowed values.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.validation import (
    build_config,
    check_choice,
    check_float,
    check_int,
    check_pair,
    coerce_fields,
)
from agentsim_env.scenarios.rewards import RewardConfig
from agentsim_env.sim.config import PHYSICS_MODES

ACTION_MODES = ("velocity", "primitive")
MAX_AGENTS = 1_000_000
"""Most agents a world may hold (memory is also checked against the machine before allocating)."""
MAX_STEPS = 10**9
"""Longest episode, in steps."""
MAX_RINGS = 64
"""Most elevation rings of the proximity sensor."""


@dataclass(frozen=True)
class BodyConfig:
    """An agent's body and motion limits.

    Attributes:
        radius: Collision radius in metres, 0.01..1e4.
        max_speed: Speed limit in m/s, 0.01..1e4.
        max_accel: Acceleration limit in m/s^2, 0.01..1e4.
        altitude: Flight band ``(low, high)`` in metres: ``0 <= low``, ``high <= 1e4``, ``high - low >= 0.1``.
    """

    radius: float = 0.5
    max_speed: float = 5.0
    max_accel: float = 10.0
    altitude: tuple[float, float] = (2.0, 12.0)

    def __post_init__(self) -> None:
        coerce_fields(self, "body.")
        for name in ("radius", "max_speed", "max_accel"):
            check_float(f"body.{name}", getattr(self, name), 0.01, 1e4)
        lo, hi = check_pair("body.altitude", self.altitude, 0.0, 1e4, strict=True)
        if hi - lo < 0.1:
            raise ValueError(
                f"body.altitude must span at least 0.1 m (high - low >= 0.1), got {self.altitude}"
            )


@dataclass(frozen=True)
class SensingConfig:
    """The proximity sensor (a laser-scanner-like fan of rays).

    Attributes:
        range: Ray length in metres, 0.01..1e5.
        n_azimuth: Rays per elevation ring (1..1024); ray 0 points along the heading.
        elevations_deg: Elevation of each ring in degrees (negative looks down), each in [-90, 90]; 1..64
            rings.
    """

    range: float = 10.0
    n_azimuth: int = 16
    elevations_deg: tuple[float, ...] = (0.0, -25.0)

    def __post_init__(self) -> None:
        coerce_fields(self, "sensing.")
        check_float("sensing.range", self.range, 0.01, 1e5)
        check_int("sensing.n_azimuth", self.n_azimuth, 1, 1024)
        if not 1 <= len(self.elevations_deg) <= MAX_RINGS:
            raise ValueError(
                f"sensing.elevations_deg must hold 1..{MAX_RINGS} elevations, got {self.elevations_deg!r}"
            )
        for i, e in enumerate(self.elevations_deg):
            check_float(f"sensing.elevations_deg[{i}]", e, -90.0, 90.0)
        object.__setattr__(self, "elevations_deg", tuple(float(e) for e in self.elevations_deg))


@dataclass(frozen=True)
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

    n_agents: int = 4
    body: BodyConfig = field(default_factory=BodyConfig)
    sensing: SensingConfig = field(default_factory=SensingConfig)
    action_mode: str = "velocity"
    physics: str = "kinematic"
    collisions: bool = True
    dt: float = 0.1
    max_steps: int = 400
    reward: RewardConfig = field(default_factory=RewardConfig)
    comms: CommsConfig | None = None

    def __post_init__(self) -> None:
        self._coerce_nested()
        coerce_fields(self)
        check_int("n_agents", self.n_agents, 1, MAX_AGENTS)
        check_choice("action_mode", self.action_mode, ACTION_MODES)
        check_choice("physics", self.physics, PHYSICS_MODES)
        check_float("dt", self.dt, 1e-3, 10.0)
        check_int("max_steps", self.max_steps, 1, MAX_STEPS)

    def _coerce_nested(self) -> None:
        """Turn dicts given for sub-configs into validated instances (merged over the field's default)."""
        for f in dataclasses.fields(self):
            cls = self.nested.get(f.name)
            if cls is None:
                continue
            value = getattr(self, f.name)
            if isinstance(value, dict):
                base = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
                start = _shallow(base) if isinstance(base, cls) else {}
                value = build_config(cls, {**start, **value}, label=f.name)
                object.__setattr__(self, f.name, value)
            elif not isinstance(value, cls) and not (value is None and "None" in str(f.type)):
                raise ValueError(f"{f.name} must be a {cls.__name__} or a dict of its fields, got {value!r}")


def _shallow(obj: Any) -> dict[str, Any]:
    """A dataclass instance's fields as a dict (sub-dataclasses kept as instances)."""
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


__all__ = ["ACTION_MODES", "BodyConfig", "ScenarioConfig", "SensingConfig", "build_config"]
