"""Validation helpers for frozen config dataclasses (every layer validates its configs with these).

Configs reject unknown keys (naming the key and the allowed ones) and bad values (naming the field and the
allowed values) at construction, before any state is touched.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

T = TypeVar("T")


def build_config(cls: type[T], values: Mapping[str, Any], label: str = "config") -> T:
    """Instantiate a config dataclass from keyword values, rejecting unknown keys.

    Args:
        cls: A dataclass type.
        values: Field values; missing fields keep their defaults.
        label: What the keys configure, named in the unknown-key error (e.g. ``"body"``).

    Returns:
        The validated config instance.

    Raises:
        ValueError: On an unknown key (the message lists the allowed keys) or a bad value.
    """
    names = [f.name for f in dataclasses.fields(cls)]  # type: ignore[arg-type]
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise ValueError(f"unknown {label} key(s) {unknown} for {cls.__name__}; allowed keys: {sorted(names)}")
    try:
        return cls(**values)
    except TypeError as exc:  # e.g. a value of the wrong type reaching a comparison
        raise ValueError(f"bad value for {cls.__name__}: {exc}") from exc


def check_choice(name: str, value: Any, allowed: Iterable[Any]) -> None:
    """Raise unless ``value`` is one of ``allowed``."""
    allowed = tuple(allowed)
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}")


def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None) -> None:
    """Raise unless ``value`` is an int (not bool) within ``[lo, hi]``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if lo is not None and value < lo:
        raise ValueError(f"{name} must be >= {lo}, got {value}")
    if hi is not None and value > hi:
        raise ValueError(f"{name} must be <= {hi}, got {value}")


def check_float(
    name: str, value: Any, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False
) -> None:
    """Raise unless ``value`` is a finite real within the bounds (``lo_open`` makes ``lo`` exclusive)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and value > hi:
        raise ValueError(f"{name} must be <= {hi}, got {value}")
