"""The release strategy contract: a typed, frozen options class that plans one UAV's releases.

A strategy is a subclass of ``ReleaseStrategy``. Its **options** are dataclass fields (typed, with defaults);
its **behaviour** is class attributes and one method:

* ``name`` (registry name), ``description`` (one line), ``release_speed`` (default fly-through release speed
  in m/s; ``0`` hovers at every release), ``plan_mode`` (the mode of its plans: ``"waypoints"`` fly-through,
  ``"hover"`` or ``"teleport"``, a placement that is not flyable and is flown as hover releases);
* ``bounds``: per option, the allowed range or values, checked at construction with ``option_error``;
* ``pattern(ctx) -> Pattern``: the landing targets (offsets from the zone centre) in visiting order for one
  zone or wedge, from a ``PlanContext``;
* optionally ``layer_altitudes`` (the altitude each UAV works at in each zone).

``plan`` validates the mission inputs, calls ``pattern`` and turns the targets into a compensated
``ReleasePlan`` (``planning.assemble_plan``) with the common options (``mode``, ``min_leg``, ``lead_in``,
``fall_dt``, ``two_opt``). Strategies are found by name in ``registry``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import pydantic
from numpy.typing import ArrayLike, NDArray

from agentsim_env.core.config_model import Flag, Int, Real, Text, describe
from agentsim_env.core.validation import check_choice, check_float
from agentsim_env.policies.release.planning import MODES, ReleasePlan, assemble_plan, normalise_sector
from agentsim_env.uav.wsn.profiles import RadialProfile

__all__ = ["Bound", "Choice", "Pattern", "PlanContext", "ReleaseStrategy"]


@dataclass(frozen=True, slots=True)
class Bound:
    """Numeric range of an option: ``lo <= value <= hi`` (``lo_open``: ``lo < value``); ``None``: unbounded."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False

    def check(self, name: str, value: Any) -> None:
        """Raise ``ValueError`` naming the option unless ``value`` (a number, or None) is in range."""
        if value is not None:
            check_float(name, value, self.lo, self.hi, lo_open=self.lo_open)

    def __str__(self) -> str:
        lo = "" if self.lo is None else f"{'>' if self.lo_open else '>='} {self.lo:g}"
        hi = "" if self.hi is None else f"<= {self.hi:g}"
        return ", ".join(p for p in (lo, hi) if p) or "any"


@dataclass(frozen=True, slots=True)
class Choice:
    """The values an option may take."""

    values: tuple[Any, ...]

    def check(self, name: str, value: Any) -> None:
        """Raise ``ValueError`` naming the option and the allowed values unless ``value`` is one of them."""
        check_choice(name, value, self.values)

    def __str__(self) -> str:
        return " | ".join(repr(v) for v in self.values)


@dataclass(frozen=True, slots=True)
class PlanContext:
    """What a strategy's ``pattern`` sees of one zone (or one wedge of it).

    Attributes:
        profile: Radial density profile of the zone; ``profile.radius`` is the zone radius.
        n_sensors: Sensors of the whole zone (``N``), also when planning one wedge.
        sector: ``(theta0, theta1)`` wedge, or ``None`` for the whole disc.
        start: UAV start as an offset from the zone centre ``(2,)``.
        rng: Source of all randomness of the plan.
    """

    profile: RadialProfile
    n_sensors: int
    sector: tuple[float, float] | None
    start: NDArray[np.float64]
    rng: np.random.Generator

    @property
    def radius(self) -> float:
        """Zone radius (m)."""
        return float(self.profile.radius)

    @property
    def wedge(self) -> tuple[float, float]:
        """``(theta0, width)`` of the wedge (``(0, 2 pi)`` for the whole disc)."""
        return normalise_sector(self.sector)


@dataclass(frozen=True, slots=True)
class Pattern:
    """A strategy's landing targets for one zone or wedge.

    Attributes:
        offsets: ``(m, 2)`` targets as offsets from the zone centre, in visiting order.
        hover_groups: For hover plans, ``(m,)`` nondecreasing ids of consecutive equal targets released from
            one hover (``None``: one hover per target).
        info: Strategy statistics stored in the plan (e.g. ``n_rings``).
    """

    offsets: NDArray[np.float64]
    hover_groups: NDArray[np.int64] | None = None
    info: dict[str, Any] = field(default_factory=dict)


#: The declared type (``core.config_model``) that checks an option annotated with a plain Python type.
_DECLARED: dict[Any, Any] = {int: Int, float: Real, bool: Flag, str: Text}


def _declared(tp: Any) -> Any:
    """``tp`` with ``int``/``float``/``bool``/``str`` replaced by the declared types, inside unions and tuples."""
    if tp in _DECLARED:
        return _DECLARED[tp]
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return typing.Union[tuple(_declared(a) for a in args)]  # noqa: UP007 - built from a tuple
    if origin is tuple:
        return tuple[tuple(a if a is Ellipsis else _declared(a) for a in args)]  # type: ignore[misc]
    return tp


@functools.cache
def _adapters(cls: type) -> dict[str, pydantic.TypeAdapter[Any]]:
    """One pydantic adapter per option field of strategy class ``cls``, from its annotations."""
    hints = typing.get_type_hints(cls)
    return {f.name: pydantic.TypeAdapter(_declared(hints[f.name])) for f in dataclasses.fields(cls)}


@dataclass(frozen=True, kw_only=True)
class ReleaseStrategy(ABC):
    """Base of every release strategy: the common options, validation and the plan assembly.

    Subclasses are frozen dataclasses too (``@dataclass(frozen=True, kw_only=True)``) that add their options
    as fields, set the class attributes and implement ``pattern``.

    Args:
        mode: ``None`` (the strategy's own ``plan_mode``) or ``"hover"`` (a fly-through plan becomes hover
            releases); the strategy's own mode is accepted too.
        min_leg: Shortest straight arrival (m) before a lead-in leg is inserted.
        lead_in: Length of an inserted lead-in leg (m).
        fall_dt: Integration step (s) of the landing prediction used by the compensation.
        two_opt: Improve nearest-neighbour tours with 2-opt.

    Raises:
        ValueError: An option of the wrong type or out of its bounds (naming the option, the value and the
            allowed values).
    """

    #: Registry name (``"B5_cvt"``).
    name: ClassVar[str] = ""
    #: One line saying what the strategy does.
    description: ClassVar[str] = ""
    #: Default release speed of fly-through plans (m/s); 0 hovers at every release.
    release_speed: ClassVar[float] = 4.0
    #: Mode of the plans ``pattern`` makes: ``"waypoints"``, ``"hover"`` or ``"teleport"``.
    plan_mode: ClassVar[str] = "waypoints"
    #: Allowed range or values per option (options not listed: any value of the field's type).
    bounds: ClassVar[Mapping[str, Bound | Choice]] = {
        "min_leg": Bound(0.0),
        "lead_in": Bound(0.0),
        "fall_dt": Bound(0.0, lo_open=True),
    }

    mode: str | None = None
    min_leg: float = 2.0
    lead_in: float = 10.0
    fall_dt: float = 0.01
    two_opt: bool = True

    def __post_init__(self) -> None:
        try:
            for opt, adapter in _adapters(type(self)).items():  # declared types: no str for an int, ...
                try:
                    value = adapter.validate_python(getattr(self, opt))
                except pydantic.ValidationError as exc:
                    raise ValueError(f"{opt} {describe(exc.errors(include_url=False)[0])}") from None
                object.__setattr__(self, opt, value)  # numpy numbers stored as Python ones
            for opt in self.options():
                rule = self.option_rule(opt)
                if rule is not None:
                    rule.check(opt, getattr(self, opt))
            check_choice("mode", self.mode, (None, "hover", self.plan_mode))
        except ValueError as exc:
            raise ValueError(f"{self.name or type(self).__name__} option {exc}") from None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if cls.plan_mode not in MODES:
            raise ValueError(f"{cls.__name__}.plan_mode must be one of {MODES}, got {cls.plan_mode!r}")

    # ------------------------------------------------------------------ behaviour
    @classmethod
    def options(cls) -> dict[str, dataclasses.Field[Any]]:
        """The option fields of the strategy, by name (common options first)."""
        return {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]

    @classmethod
    def option_rule(cls, option: str) -> Bound | Choice | None:
        """The range or values declared for ``option`` (the most derived class's), or None."""
        for klass in cls.__mro__:
            rules = vars(klass).get("bounds", {})
            if option in rules:
                return rules[option]  # type: ignore[no-any-return]
        return None

    @property
    def hovers(self) -> bool:
        """Whether every release is made from a hover (hover or teleport plans, or ``mode="hover"``)."""
        return self.plan_mode != "waypoints" or self.mode == "hover"

    def layer_altitudes(
        self,
        zone_altitudes: NDArray[np.float64],
        n_uavs: int,
        layer_spacing: float,
        band: tuple[float, float],
    ) -> NDArray[np.float64]:
        """Working altitude ``(n_uavs, K)`` of each UAV in each zone: the zone's altitude plus one layer per UAV.

        Args:
            zone_altitudes: ``(K,)`` release altitude of each zone (m).
            n_uavs: Fleet size.
            layer_spacing: Altitude step between UAV layers (m).
            band: ``(lo, hi)`` allowed altitudes.
        """
        lo, hi = band
        return np.clip(zone_altitudes[None, :] + layer_spacing * np.arange(n_uavs)[:, None], lo, hi)

    @abstractmethod
    def pattern(self, ctx: PlanContext) -> Pattern:
        """The landing targets of one zone or wedge in visiting order (every strategy implements it).

        Args:
            ctx: The zone (profile, ``N``), the wedge, the UAV's start (offset from the centre) and the
                generator of all randomness.

        Returns:
            The targets as offsets from the zone centre, with hover groups and statistics if any.
        """

    # ------------------------------------------------------------------ planning
    def plan(
        self,
        centre: ArrayLike,
        profile: RadialProfile,
        n_sensors: int,
        altitude: float,
        speed: float,
        rng: np.random.Generator,
        sector: tuple[float, float] | None = None,
        start_xy: ArrayLike | None = None,
        fall: Any = None,
        wind_mean: Any = None,
    ) -> ReleasePlan:
        """Plan one UAV's releases over one zone (or one wedge of it).

        Args:
            centre: Zone centre ``(2,)`` in world metres.
            profile: Radial density profile (``RadialProfile``); its ``radius`` is the zone radius.
            n_sensors: Sensors for the whole zone (``N``); see ``targets`` for wedges.
            altitude: Release height above flat ground (> 0).
            speed: Cruise speed (>= 0), also the release speed of fly-through plans.
            rng: Source of all randomness.
            sector: ``(theta0, theta1)`` wedge for this UAV, or ``None`` for the whole disc.
            start_xy: UAV start; default: the rim at the wedge's mid-angle (angle 0 for the whole disc).
            fall: ``FallParams`` for release-point compensation, or ``None`` (release over the target).
            wind_mean: Mean wind ``(2,)`` (or callable of height) used by the compensation.

        Returns:
            The ``ReleasePlan``.

        Raises:
            ValueError: On invalid inputs (naming the argument).
        """
        if isinstance(n_sensors, bool) or not isinstance(n_sensors, (int, np.integer)) or n_sensors < 0:
            raise ValueError(f"n_sensors must be an integer >= 0, got {n_sensors!r}")
        if not (math.isfinite(altitude) and altitude > 0):
            raise ValueError(f"altitude must be a finite number > 0, got {altitude!r}")
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed must be a finite number >= 0, got {speed!r}")
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        c = np.asarray(centre, dtype=np.float64).reshape(2)
        big_r = float(profile.radius)
        t0, width = normalise_sector(sector)
        if start_xy is None:
            a = t0 + 0.5 * width if sector is not None else 0.0
            start_xy = c + big_r * np.array([math.cos(a), math.sin(a)])
        start = np.asarray(start_xy, dtype=np.float64).reshape(2) - c
        pat = self.pattern(PlanContext(profile, int(n_sensors), sector, start, rng))
        mode = "hover" if self.mode == "hover" and self.plan_mode == "waypoints" else self.plan_mode
        return assemble_plan(
            self.name,
            mode,
            pat.offsets + c,
            c,
            big_r,
            sector,
            start + c,
            altitude,
            speed,
            fall,
            wind_mean,
            hover_groups=pat.hover_groups,
            min_leg=self.min_leg,
            lead_in=self.lead_in,
            fall_dt=self.fall_dt,
            info=pat.info,
        )
