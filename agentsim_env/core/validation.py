"""Validation helpers for frozen config dataclasses (every layer validates its configs with these).

Configs reject unknown keys (naming the key and the allowed ones) and bad values (naming the field and the
allowed values) at construction, before any state is touched.

Every field is also checked against its annotation (``coerce_fields``): a ``bool`` field takes ``True`` or
``False`` only (never a truthy string or number), ``int`` and ``float`` fields take numpy scalars too (stored as
Python numbers), ``str`` fields take printable text (``check_text``: no control characters, bidirectional
overrides or unpaired surrogates).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import sys
import types
import typing
from collections.abc import Iterable, Mapping
from typing import Any, TypeVar

import numpy as np

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
        raise ValueError(
            f"unknown {label} key(s) {unknown} for {cls.__name__}; allowed keys: {sorted(names)}"
        )
    try:
        return cls(**values)
    except TypeError as exc:  # e.g. a value of the wrong type reaching a comparison
        raise ValueError(f"bad value for {cls.__name__}: {exc}") from exc


#: Characters no text field takes: C0 controls, DEL and C1 controls (a terminal acts on them), the
#: bidirectional embeddings, overrides and isolates (they reorder what is shown), and surrogates (in a Python
#: string they are always unpaired, and no UTF-8 encoder writes them).
_BAD_TEXT = re.compile("[\x00-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")
_BAD_TEXT_OR_NEWLINE = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069\ud800-\udfff]")


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
        ValueError: Naming the field, the first refused character (as ``U+XXXX``) and its position; the
            message never contains the character itself.
    """
    if not isinstance(value, str):
        raise ValueError(f"{name} must be a string, got {short_repr(value)}")
    bad = (_BAD_TEXT_OR_NEWLINE if allow_newlines else _BAD_TEXT).search(value)
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
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def check_bool(name: str, value: Any) -> None:
    """Raise unless ``value`` is ``True`` or ``False`` (a bool or numpy bool; truthy values are refused)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False (a bool), got {short_repr(value)}")


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
    if (
        not is_real(value)
        or (is_int(value) and abs(int(value)) > sys.float_info.max)
        or not math.isfinite(value)
    ):
        raise ValueError(f"{name} must be a finite number, got {short_repr(value)}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo}, got {value}")
    if hi is not None and value > hi:
        raise ValueError(f"{name} must be <= {hi}, got {value}")


def check_pair(
    name: str, value: Any, lo: float | None = None, hi: float | None = None, *, strict: bool = False
) -> tuple[float, float]:
    """Validate a ``(low, high)`` pair with ``lo <= low <= high <= hi`` (``low < high`` when ``strict``).

    Returns:
        The pair as two Python floats.
    """
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 2:
        raise ValueError(f"{name} must be a pair (low, high), got {short_repr(value)}")
    check_float(f"{name}[0]", value[0], lo, hi)
    check_float(f"{name}[1]", value[1], value[0], hi, lo_open=strict)
    return float(value[0]), float(value[1])


@functools.cache
def _field_types(cls: type) -> tuple[tuple[str, Any], ...]:
    """``(name, annotation)`` of every init field of a dataclass, annotations resolved."""
    hints = typing.get_type_hints(cls)
    return tuple((f.name, hints.get(f.name, Any)) for f in dataclasses.fields(cls) if f.init)


def _check_type(name: str, value: Any, tp: Any) -> Any:
    """``value`` checked against annotation ``tp`` (numbers normalised to Python types); raises ValueError."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            return _check_type(name, value, rest[0])
        return value  # a wider union: the config's own validator decides
    if tp is bool:
        check_bool(name, value)
        return bool(value)
    if tp is int:
        if not is_int(value):
            raise ValueError(f"{name} must be an integer, got {short_repr(value)}")
        return int(value)
    if tp is float:
        if not is_real(value):
            raise ValueError(f"{name} must be a number, got {short_repr(value)}")
        return float(value)
    if tp is str:
        return check_text(name, value)
    if origin is tuple:
        args = typing.get_args(tp)
        if isinstance(value, np.ndarray):
            value = tuple(value.tolist())
        if not isinstance(value, (tuple, list)):
            raise ValueError(f"{name} must be a sequence (a tuple or list), got {short_repr(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_check_type(f"{name}[{i}]", v, args[0]) for i, v in enumerate(value))
        if args and len(value) != len(args):
            kind = "a pair (low, high)" if len(args) == 2 else f"{len(args)} values"
            raise ValueError(f"{name} must be {kind}, got {short_repr(value)}")
        return tuple(_check_type(f"{name}[{i}]", v, a) for i, (v, a) in enumerate(zip(value, args)))
    return value  # Any, sub-configs and other classes: the config's own validator decides


def coerce_fields(obj: Any, prefix: str = "") -> None:
    """Check every field of a frozen dataclass instance against its annotation, in place.

    ``bool`` fields must hold a bool, ``int`` fields an integer, ``float`` fields a real number (numpy scalars
    are stored as Python numbers), ``str`` fields a string, ``tuple[...]`` fields a sequence of the right length
    (stored as a tuple); ``X | None`` also takes ``None``. Other annotations are left to the config's validator.

    Args:
        obj: A dataclass instance (frozen or not).
        prefix: Prepended to field names in errors (e.g. ``"body."``).

    Raises:
        ValueError: Naming the first field whose value has the wrong type.
    """
    for name, tp in _field_types(type(obj)):  # type: ignore[arg-type]  # classes are hashable
        value = getattr(obj, name)
        new = _check_type(prefix + name, value, tp)
        if new is not value:
            object.__setattr__(obj, name, new)
