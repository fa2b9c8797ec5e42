"""Release strategies by name: the shipped B0-B8 and those registered later or installed as plug-ins.

``strategy_names()`` and ``strategy_class(name)`` are the only readers of the registry (a later plugin
registry can plug in there); ``register`` / ``unregister`` add and remove classes. ``B8_oracle`` is the
deprecated former name of ``B8_teleport``: it is still accepted (with a ``DeprecationWarning``) for one release.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from agentsim_env.core.plugins import STRATEGIES
from agentsim_env.policies.release.baselines import SHIPPED
from agentsim_env.policies.release.planning import ReleasePlan
from agentsim_env.policies.release.strategy import ReleaseStrategy
from agentsim_env.uav.wsn.profiles import RadialProfile

__all__ = [
    "DEPRECATED_NAMES",
    "make_plan",
    "make_strategy",
    "register",
    "strategy_class",
    "strategy_names",
    "unregister",
]

#: Former names still accepted for one release: old name -> current name.
DEPRECATED_NAMES: Mapping[str, str] = {"B8_oracle": "B8_teleport"}
_SHIPPED_NAMES = tuple(cls.name for cls in SHIPPED)


def strategy_names() -> list[str]:
    """The strategy names: the shipped B0 ... B8 in order, then the registered and installed ones, sorted."""
    return [*_SHIPPED_NAMES, *(n for n in STRATEGIES.names() if n not in _SHIPPED_NAMES)]


def strategy_class(name: str) -> type[ReleaseStrategy]:
    """The strategy class registered as ``name`` (``core.plugins.STRATEGIES``: shipped, registered, plug-ins).

    Args:
        name: A registered name, or a deprecated former name (warns with ``DeprecationWarning``).

    Returns:
        The class.

    Raises:
        ValueError: On an unknown name (the message lists the known names), or when what is registered under
            ``name`` is not a concrete ``ReleaseStrategy`` subclass whose ``name`` is ``name``.
    """
    if isinstance(name, str) and name in DEPRECATED_NAMES:
        new = DEPRECATED_NAMES[name]
        warnings.warn(
            f"release strategy {name!r} is deprecated and will be removed; use {new!r}",
            DeprecationWarning,
            stacklevel=3,
        )
        name = new
    if not isinstance(name, str) or name not in STRATEGIES:
        raise ValueError(f"strategy must be one of {strategy_names()}, got {name!r}")
    cls = STRATEGIES.get(name)
    if not _concrete(cls):
        raise ValueError(
            f"strategy {name!r} ({STRATEGIES.origin(name)}) must be a concrete ReleaseStrategy subclass, got {cls!r}"
        )
    if cls.name != name:
        raise ValueError(
            f"strategy {name!r} ({STRATEGIES.origin(name)}) is class {cls.__name__} whose name is "
            f"{cls.name!r}: a strategy is registered under its own name"
        )
    return cls


def _concrete(cls: Any) -> bool:
    """Whether ``cls`` is a ``ReleaseStrategy`` subclass with no abstract method left."""
    return isinstance(cls, type) and issubclass(cls, ReleaseStrategy) and not getattr(cls, "__abstractmethods__", ())


def make_strategy(name: str, **options: Any) -> ReleaseStrategy:
    """The strategy ``name`` with ``options`` (each checked against its field's type and bounds).

    Args:
        name: A registered strategy name.
        **options: Option values; options not given keep their defaults.

    Returns:
        The strategy instance.

    Raises:
        ValueError: On an unknown name, an unknown option (listing the allowed ones) or a bad option value
            (naming the option, the value and the allowed values).
    """
    cls = strategy_class(name)
    allowed = sorted(cls.options())
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise ValueError(f"options for {cls.name} must be among {allowed}, got unknown option(s) {unknown}")
    return cls(**options)


def register(cls: type[ReleaseStrategy], *, replace: bool = False) -> type[ReleaseStrategy]:
    """Register a strategy class under its ``name`` (usable as a class decorator).

    The same as ``agentsim_env.register_strategy(cls.name, cls)``, with the class checked at once.

    Args:
        cls: A concrete ``ReleaseStrategy`` subclass with a non-empty ``name``.
        replace: Allow replacing a class already registered under that name.

    Returns:
        ``cls``.

    Raises:
        ValueError: ``cls`` is not a concrete ``ReleaseStrategy`` subclass, has no name, or its name is taken
            (without ``replace``) or is a deprecated name.
    """
    if not _concrete(cls):
        raise ValueError(f"cls must be a concrete ReleaseStrategy subclass, got {cls!r}")
    name = cls.name
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"{cls.__name__}.name must be a non-empty identifier, got {name!r}")
    if name in DEPRECATED_NAMES or (name in STRATEGIES and not replace):
        raise ValueError(f"strategy name {name!r} is taken; registered: {strategy_names()}")
    STRATEGIES.register(name, cls, replace=replace)
    return cls


def unregister(name: str) -> None:
    """Remove a strategy registered with :func:`register` (shipped and installed ones stay).

    Raises:
        ValueError: ``name`` was not registered (the message lists the registered names).
    """
    STRATEGIES.unregister(name)


def make_plan(
    strategy: str,
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
    options: Mapping[str, Any] | None = None,
) -> ReleasePlan:
    """Plan one UAV's releases over one zone (or wedge) with a registered strategy and its options.

    ``make_strategy(strategy, **options).plan(...)``; see ``ReleaseStrategy.plan`` for the arguments.

    Raises:
        ValueError: On an unknown strategy or option, a bad option value, or invalid inputs.
    """
    return make_strategy(strategy, **dict(options or {})).plan(
        centre, profile, n_sensors, altitude, speed, rng, sector, start_xy, fall, wind_mean
    )
