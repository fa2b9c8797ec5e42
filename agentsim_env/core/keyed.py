"""Counter-based random numbers: a draw is a pure function of what it is for, not of who draws it.

A generator stream gives different numbers to the same slot when another process holds a different set of
slots (each draws its own rows in its own order). A keyed draw hashes its key words instead: ``keyed_uniform(key,
tick, slot)`` is the same number in every process that asks for it, in any batch, in any order.

The hash is SplitMix64's finaliser chained over the words (``h = mix(h ^ word)`` for each word after the key),
vectorised over numpy ``uint64`` arrays (every word broadcasts against the others). Uniforms take the top 53 bits
of the hash (float64 in [0, 1)); normals come from two such uniforms through Box-Muller (cosine branch).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 2.0**-53


def _words(value: ArrayLike) -> np.ndarray:
    # Negative ints wrap to their two's complement (-1 -> 2**64 - 1): a distinct, fixed word.
    a = np.asarray(value)
    if a.dtype.kind == "u":
        return a.astype(np.uint64)
    if a.dtype.kind in "ib":
        return a.astype(np.int64).view(np.uint64) if a.ndim else np.asarray(int(a) % 2**64, dtype=np.uint64)
    raise TypeError(f"keyed draws take integer key words, got dtype {a.dtype}")


def _mix(z: np.ndarray) -> np.ndarray:
    # SplitMix64's output function; uint64 arithmetic wraps modulo 2**64 as the algorithm expects.
    z = z + _GOLDEN
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


def keyed_bits(key: ArrayLike, *words: ArrayLike) -> np.ndarray:
    """64 random bits per element, a function of ``key`` and ``words`` only.

    Args:
        key: The stream key (e.g. a world episode's key), an integer or an integer array.
        *words: Further integer words (tick, slot, axis, ...); all arrays broadcast together.

    Returns:
        ``uint64`` array of the broadcast shape.
    """
    with np.errstate(over="ignore"):
        h = _mix(_words(key))
        for w in words:
            h = _mix(h ^ _words(w))
    h = np.asarray(h, dtype=np.uint64)
    shape = np.broadcast_shapes(np.shape(key), *(np.shape(w) for w in words))
    return h if h.shape == shape else np.broadcast_to(h, shape).copy()


def keyed_uniform(key: ArrayLike, *words: ArrayLike) -> np.ndarray:
    """Uniform float64 in [0, 1) keyed by ``key`` and ``words`` (see :func:`keyed_bits`)."""
    return (keyed_bits(key, *words) >> _S11).astype(np.float64) * _TO_UNIT


def keyed_normal(key: ArrayLike, *words: ArrayLike) -> np.ndarray:
    """Standard normal float64 keyed by ``key`` and ``words``: Box-Muller over the uniforms of words + (0,), (1,).

    Args:
        key: The stream key.
        *words: Further integer words; all arrays broadcast together.

    Returns:
        float64 array of the broadcast shape.
    """
    u1 = keyed_uniform(key, *words, 0)
    u2 = keyed_uniform(key, *words, 1)
    # 1 - u1 lies in (0, 1], so the log is finite
    return np.sqrt(-2.0 * np.log1p(-u1)) * np.cos(2.0 * np.pi * u2)
