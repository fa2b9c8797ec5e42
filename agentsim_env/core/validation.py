"""Checks of run-time arguments that are not config fields (env options, zone files, function arguments).

Config classes declare their fields instead (``agentsim_env.core.config_model``); these helpers check values
given elsewhere with the same wording: the name, the value (a short ``repr``) and what is allowed.
``build_config`` builds a config from keyword values, naming unknown keys.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

import numpy as np

from agentsim_env.core.config_model import BAD_TEXT, BAD_TEXT_OR_NEWLINE
from agentsim_env.core.short_text import short_repr  # re-exported: every message builder uses this one

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


def check_text(name: str, value: Any, *, allow_newlines: bool = False) -> str:
    """Raise unless ``value`` is a string that is safe to print, log, plot and encode as UTF-8.

    Refused: C0 and C1 control characters and DEL (U+0000-001F, U+007F-009F), the bidirectional embeddings,
    overrides and isolates (U+202A-202E, U+2066-2069) and unpaired surrogates (U+D800-DFFF).

    Args:
        name: The field, named in the error.
        value: The value to check.
        allow_newlines: Also accept tab and line feed (free text such as a description).

    Returns:
        ``value`` unchanged.

    Raises:
        ValueError: Naming the field, the first refused character (its code point, e.g. ``U+202E``) and its
            position; the message never contains the character itself.
    """
    if not isinstance(value, str):
        raise ValueError(f"{name} must be a string, got {short_repr(value)}")
    bad = (BAD_TEXT_OR_NEWLINE if allow_newlines else BAD_TEXT).search(value)
    if bad is not None:
        raise ValueError(
            f"{name} must be printable text without control characters, bidirectional overrides or unpaired "
            f"surrogates; found U+{ord(bad.group()):04X} at position {bad.start()}"
        )
    return value


def check_choice(name: str, value: Any, allowed: Iterable[Any]) -> None:
    """Raise unless ``value`` is one of ``allowed``."""
    allowed = tuple(allowed)
    if value not in allowed:
        raise ValueError(f"{name} must be one of {allowed}, got {short_repr(value)}")


def is_int(value: Any) -> bool:
    """Whether ``value`` is an integer (a Python or numpy integer, never a bool)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (Python or numpy int or float, never a bool or complex)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def check_int(name: str, value: Any, lo: int | None = None, hi: int | None = None) -> None:
    """Raise unless ``value`` is an integer (not bool; numpy integers accepted) within ``[lo, hi]``."""
    if not is_int(value):
        raise ValueError(f"{name} must be an integer, got {short_repr(value)}")
    if lo is not None and value < lo:
        raise ValueError(f"{name} must be >= {lo}, got {short_repr(value)}")  # an int may have 10**6 digits
    if hi is not None and value > hi:
        raise ValueError(f"{name} must be <= {hi}, got {short_repr(value)}")


def check_float(
    name: str, value: Any, lo: float | None = None, hi: float | None = None, *, lo_open: bool = False
) -> None:
    """Raise unless ``value`` is a finite real within the bounds (``lo_open`` makes ``lo`` exclusive)."""
    # an integer past the float range (400 digits in a config file) is no finite number: math.isfinite overflows
    if not is_real(value) or (is_int(value) and abs(int(value)) > sys.float_info.max) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {short_repr(value)}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and value > hi:
        raise ValueError(f"{name} must be <= {hi}, got {value}")
