"""Gymnasium spaces from scenario parts, in Dict and flat-Box formats, and action decoding."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from agentsim_env.core.pipeline import Part

FORMATS = ("dict", "flat")


def observation_space_for(parts: dict[str, Part], fmt: str) -> spaces.Space:
    """A Dict of float32 Boxes (one per part) or one flat Box (parts concatenated in order)."""
    if fmt == "dict":
        return spaces.Dict(
            {k: spaces.Box(p.low, p.high, shape=p.shape, dtype=np.float32) for k, p in parts.items()}
        )
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
            raise ValueError(
                f"action of {agent!r} must be a dict with keys {list(parts)}, got {type(action).__name__}"
            )
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

ACTION_RULE = "an action part takes real numbers (ints or floats) in exactly the part's shape"
"""The one rule every action obeys, quoted in the errors: an array or sequence of real numbers (not bools,
complex numbers or strings) whose shape is exactly the part's (a ``(3,)`` part refuses ``(3, 1)`` and ``(1, 3)``
alike); values outside the bounds are clipped, NaN and inf are refused."""


def _check(value: Any, part: Part, what: str) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged sequences
        raise ValueError(f"{what} must be real numbers of shape {part.shape} ({ACTION_RULE})") from exc
    if arr.dtype.kind not in REAL_KINDS:
        raise ValueError(f"{what} must be real numbers, got dtype {arr.dtype} ({ACTION_RULE})")
    if arr.shape != part.shape:
        raise ValueError(f"{what} must have shape {part.shape}, got {arr.shape} ({ACTION_RULE})")
    arr = arr.astype(np.float64).reshape(-1)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} contains NaN or inf: {arr}")
    return np.clip(arr, part.low, part.high)
