"""Gymnasium spaces from scenario parts, in Dict and flat-Box formats, and action decoding."""

from __future__ import annotations

import itertools
import operator
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from agentsim_env.core.pipeline import Part

FORMATS = ("dict", "flat")


def observation_space_for(parts: dict[str, Part], fmt: str) -> spaces.Space:
    """A Dict of float32 Boxes (one per part) or one flat Box (parts concatenated in order)."""
    if fmt == "dict":
        return spaces.Dict({k: spaces.Box(p.low, p.high, shape=p.shape, dtype=np.float32) for k, p in parts.items()})
    low = np.concatenate([np.full(p.size, p.low, dtype=np.float32) for p in parts.values()])
    high = np.concatenate([np.full(p.size, p.high, dtype=np.float32) for p in parts.values()])
    return spaces.Box(low, high, dtype=np.float32)


def action_space_for(parts: dict[str, Part], fmt: str) -> spaces.Space:
    """Action space: a Dict of Boxes in [-1, 1] or one flat Box."""
    return observation_space_for(parts, fmt)


def flat_layout(parts: dict[str, Part]) -> dict[str, slice]:
    """Where each part sits in the flat vector."""
    out, start = {}, 0
    for k, p in parts.items():
        out[k] = slice(start, start + p.size)
        start += p.size
    return out


def split_action(action: Any, parts: dict[str, Part], fmt: str, agent: str) -> dict[str, np.ndarray]:
    """Check one agent's action and split it into parts (values are clipped to the part bounds).

    Every part follows ``ACTION_RULE``: real numbers (ints or floats), exactly the part's shape.

    Raises:
        ValueError: Wrong shape or type, missing or unknown part, or a non-finite value; the message names the
            agent.
    """
    if fmt == "dict":
        if not isinstance(action, dict):
            raise ValueError(f"action of {agent!r} must be a dict with keys {list(parts)}, got {type(action).__name__}")
        unknown = set(action) - set(parts)
        missing = set(parts) - set(action)
        if unknown or missing:
            raise ValueError(
                f"action of {agent!r}: unknown parts {sorted(unknown)}, missing parts {sorted(missing)}; "
                f"expected {list(parts)}"
            )
        out = {}
        for k, p in parts.items():
            out[k] = _check(action[k], p, f"action[{k!r}] of {agent!r}")
        return out
    total = sum(p.size for p in parts.values())
    flat = _check(action, Part((total,), -1.0, 1.0), f"action of {agent!r}")
    return {k: flat[s] for k, s in flat_layout(parts).items()}


REAL_KINDS = "iuf"
"""numpy dtype kinds an action may have: signed and unsigned integers, floats (not bool, complex or strings)."""

_REAL_KIND_SET = frozenset(REAL_KINDS)
_KIND = operator.attrgetter("dtype.kind")
_NDARRAY = {np.ndarray}
_SEQUENCES = frozenset({list, tuple})
_PLAIN_NUMBERS = frozenset({float, int})  # Python numbers; bool is a type of its own here

ACTION_RULE = "an action part takes real numbers (ints or floats) in exactly the part's shape"
"""The one rule every action obeys, quoted in the errors: an array or sequence of real numbers (not bools,
complex numbers or strings) whose shape is exactly the part's (a ``(3,)`` part refuses ``(3, 1)`` and ``(1, 3)``
alike); values outside the bounds are clipped, NaN and inf are refused."""


def as_array(value: Any) -> np.ndarray:
    """``value`` as a numpy array; a tensor is read as the values it holds, wherever it lives.

    A tensor is anything with ``detach`` and ``cpu`` methods (torch's, without importing torch): it is read
    through ``.detach().cpu()``, so neither ``requires_grad`` nor an accelerator device stops it. A floating
    dtype numpy lacks (``bfloat16``) is read through ``.float()`` (float32 holds it exactly); other dtypes
    numpy lacks raise ``TypeError``.

    Args:
        value: An array, a (nested) sequence of numbers, a number or a tensor.

    Returns:
        The array (``value`` itself when it is one; no copy is made where none is needed).

    Raises:
        TypeError: Numpy cannot read ``value`` (or a tensor's dtype).
        ValueError: A ragged sequence.
    """
    if type(value) is np.ndarray:
        return value
    if hasattr(value, "detach") and hasattr(value, "cpu"):
        value = value.detach().cpu()
        try:
            return np.asarray(value)
        except TypeError:
            is_float = getattr(value, "is_floating_point", None)
            if is_float is None or not is_float():
                raise
            return np.asarray(value.float())
    return np.asarray(value)


def stack_rows(rows: Sequence[Any]) -> np.ndarray:
    """One array of every agent's value of a part (row ``i`` is ``rows[i]``), each row checked for real numbers.

    Checking the stacked array's dtype alone is not enough: numpy casts one agent's bools (or ints) up to
    the others' floats. Numpy arrays, the common case, have their dtypes read in one pass, and lists of plain
    Python ints and floats their element types; anything else (bools, numpy scalars, tensors, nesting) is
    converted row by row first (:func:`as_array`).

    Args:
        rows: One value per agent.

    Returns:
        The stacked array.

    Raises:
        ValueError: A row is not real numbers, or the rows differ in shape (the caller then checks agent by
            agent to name the one at fault).
        TypeError: Numpy cannot read a row.
    """
    types = set(map(type, rows))
    if types != _NDARRAY:
        if types <= _SEQUENCES and set(map(type, itertools.chain.from_iterable(rows))) <= _PLAIN_NUMBERS:
            return np.asarray(rows)  # every row is ints and floats: nothing numpy could cast up
        rows = list(map(as_array, rows))
    if not _REAL_KIND_SET.issuperset(set(map(_KIND, rows))):
        raise ValueError("an action part that is not real numbers")
    return np.asarray(rows)


def _check(value: Any, part: Part, what: str) -> np.ndarray:
    try:
        arr = as_array(value)
    except (TypeError, ValueError, RuntimeError) as exc:  # ragged sequences, objects numpy cannot read
        raise ValueError(f"{what} must be real numbers of shape {part.shape} ({ACTION_RULE})") from exc
    if arr.dtype.kind not in REAL_KINDS:
        raise ValueError(f"{what} must be real numbers, got dtype {arr.dtype} ({ACTION_RULE})")
    if arr.shape != part.shape:
        raise ValueError(f"{what} must have shape {part.shape}, got {arr.shape} ({ACTION_RULE})")
    arr = arr.astype(np.float64).reshape(-1)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} contains NaN or inf: {arr}")
    return np.clip(arr, part.low, part.high)
