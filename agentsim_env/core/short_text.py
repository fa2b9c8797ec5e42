"""``short_repr``: the ``repr`` of a value for an error message, built with work bounded by its length.

``repr(value)`` followed by a cut costs as much as the whole ``repr``: a list holding itself ten levels deep
through shared references (what a few hundred bytes of YAML anchors make) has a ``repr`` of billions of
characters, and an integer past 4,300 digits has none at all (``repr`` raises). ``short_repr`` walks the value
instead and stops as soon as it has ``limit`` characters, so its work is proportional to ``limit`` whatever the
value. Lists, tuples, dicts, sets, strings, bytes, integers, numpy arrays and dataclasses are walked; any other
object's own ``repr`` is used.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any

import numpy as np

__all__ = ["short_repr"]

#: Containers nested deeper than this are shown as ``[...]`` (every level costs a few characters anyway).
MAX_DEPTH = 12
#: Integers with more bits than this are described by their number of digits (``repr`` refuses 4,300 digits).
MAX_INT_BITS = 1000
#: Arrays larger than this (or with more dimensions than ``MAX_ARRAY_DIMS``) are shown by shape and dtype.
MAX_ARRAY_SIZE = 1000
MAX_ARRAY_DIMS = 4

_BRACKETS: dict[type, tuple[str, str]] = {
    list: ("[", "]"),
    tuple: ("(", ")"),
    set: ("{", "}"),
    frozenset: ("frozenset({", "})"),
    dict: ("{", "}"),
}
_EMPTY: dict[type, str] = {list: "[]", tuple: "()", set: "set()", frozenset: "frozenset()", dict: "{}"}


class _Full(Exception):
    """The text reached its limit: the walk stops."""


class _Text:
    """Pieces of text with a character budget; adding past it raises ``_Full``."""

    def __init__(self, budget: int) -> None:
        self.parts: list[str] = []
        self.left = budget
        self.on_path: set[int] = set()  # containers being written (a container inside itself shows as [...])

    def add(self, piece: str) -> None:
        self.parts.append(piece)
        self.left -= len(piece)
        if self.left < 0:
            raise _Full


def short_repr(value: Any, limit: int = 120) -> str:
    """``repr(value)`` cut to about ``limit`` characters, built without ever building the whole ``repr``.

    A value whose ``repr`` fits in ``limit`` characters gets exactly its ``repr`` (for the types walked here);
    a longer one gets its first ``limit - 20`` characters, ``...`` and its size where it has one
    (``(a list of 10 items)``), so an error message stays short and cheap whatever the input.

    Args:
        value: Any value.
        limit: Most characters of the ``repr`` shown (at least 20).

    Returns:
        The short text.
    """
    limit = max(int(limit), 20)
    out = _Text(limit)
    try:
        _walk(value, out, 0)
    except _Full:
        text = "".join(out.parts)[: limit - 20]
        return f"{text}... ({_size(value)})" if _size(value) else f"{text}..."
    return "".join(out.parts)


def _size(value: Any) -> str:
    """The size of a value in words, when it has one (``a list of 10 items``), else ``""``."""
    if isinstance(value, (str, bytes, bytearray)):
        return f"a {type(value).__name__} of {len(value):,} {'characters' if isinstance(value, str) else 'bytes'}"
    if isinstance(value, (list, tuple, dict, set, frozenset)):
        return f"a {type(value).__name__} of {len(value):,} items"
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape}"
    return ""


def _walk(value: Any, out: _Text, depth: int) -> None:
    """Write the ``repr`` of ``value`` into ``out`` (raises ``_Full`` when the budget is spent)."""
    if isinstance(value, bytearray):
        out.add(f"bytearray({bytes(value[: out.left + 1])!r})")
        return
    if isinstance(value, (str, bytes)):
        out.add(repr(value[: out.left + 1]))  # a piece one longer than the budget is enough to fill it
        return
    if isinstance(value, int) and not isinstance(value, bool):
        bits = abs(int(value)).bit_length()
        out.add(repr(value) if bits <= MAX_INT_BITS else f"<int of {_digits(int(value))} digits>")
        return
    if value is None or isinstance(value, (bool, float, complex, np.generic)):
        out.add(repr(value))
        return
    if isinstance(value, np.ndarray):
        _array(value, out, depth)
        return
    base = next((b for b in _BRACKETS if isinstance(value, b)), None)
    if base is not None:
        _container(value, base, out, depth)
        return
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        _dataclass(value, out, depth)
        return
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not replace the error being reported
        text = f"<{type(value).__name__} object>"
    out.add(text[: out.left + 1])


def _digits(value: int) -> str:
    """The number of decimal digits of a large integer, without converting it to text."""
    digits = int(math.log10(abs(value))) + 1
    if abs(value).bit_length() > 1_000_000:
        return f"about {digits:,}"
    if 10 ** (digits - 1) > abs(value):  # log10 rounds near powers of ten
        digits -= 1
    elif 10**digits <= abs(value):
        digits += 1
    return f"{digits:,}"


def _container(value: Any, base: type, out: _Text, depth: int) -> None:
    """Lists, tuples, sets, frozensets and dicts (subclasses with their own repr shown as ``Name(...)``)."""
    open_, close = _BRACKETS[base]
    own = type(value) is not base and type(value).__repr__ is not base.__repr__
    if own:
        out.add(f"{type(value).__name__}(")
    if not value:
        out.add(_EMPTY[base])
    elif id(value) in out.on_path or depth >= MAX_DEPTH:
        out.add(f"{open_}...{close}")
    else:
        out.on_path.add(id(value))
        out.add(open_)
        # islice: never more items than the budget can show (each one costs at least one character)
        items = itertools.islice(value.items() if base is dict else value, out.left + 1)
        for i, item in enumerate(items):
            if i:
                out.add(", ")
            if base is dict:
                _walk(item[0], out, depth + 1)
                out.add(": ")
                _walk(item[1], out, depth + 1)
            else:
                _walk(item, out, depth + 1)
        out.add("," + close if base is tuple and len(value) == 1 else close)
        out.on_path.discard(id(value))
    if own:
        out.add(")")


def _array(value: np.ndarray, out: _Text, depth: int) -> None:
    """Small arrays by numpy's own repr (object arrays walked); large ones by shape and dtype."""
    if value.size > MAX_ARRAY_SIZE or value.ndim > MAX_ARRAY_DIMS:
        out.add(f"<array of shape {value.shape}, dtype {value.dtype}>")
    elif value.dtype == object:  # the elements may be anything: walk them
        out.add("array(")
        _walk(value.tolist(), out, depth + 1)
        out.add(", dtype=object)")
    else:
        out.add(repr(value))


def _dataclass(value: Any, out: _Text, depth: int) -> None:
    """A dataclass instance as ``Name(field=value, ...)``, its fields walked."""
    out.add(f"{type(value).__qualname__}(")
    shown = [f for f in dataclasses.fields(value) if f.repr]
    for i, f in enumerate(shown):
        out.add(f"{', ' if i else ''}{f.name}=")
        if depth >= MAX_DEPTH:
            out.add("...")
        else:
            _walk(getattr(value, f.name, None), out, depth + 1)
    out.add(")")
