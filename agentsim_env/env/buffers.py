"""Output arrays that an env hands out every step, reused only when nobody holds them any more.

An observation array of a large batch is hundreds of kilobytes; allocating a fresh one every step makes the
allocator hand pages back to the system and fault them in again (a few hundred microseconds a step at 2,000
agents). ``Recycled.get`` returns the previous step's array when the only reference left to it is the
recycler's own (CPython reference count: no caller kept it, nor a view of it), else a fresh one, so an array
returned to a caller is never written again while the caller can still see it.
"""

from __future__ import annotations

import sys
from typing import Any, Protocol

import numpy as np


class ArraySource(Protocol):
    """Where an env takes the array a step returns (``Recycled``, or a front end's own source)."""

    def get(self) -> np.ndarray:
        """An array the caller may fill and return (uninitialised)."""


class Recycled:
    """One output array of fixed shape and dtype, reused when no one else references it."""

    __slots__ = ("_arr", "_dtype", "_shape")

    def __init__(self, shape: tuple[int, ...], dtype: Any) -> None:
        self._shape = tuple(shape)
        self._dtype = np.dtype(dtype)
        self._arr: np.ndarray | None = None

    def get(self) -> np.ndarray:
        """An array of the shape and dtype (uninitialised): the last one when unreferenced, else a fresh one."""
        a = self._arr
        # three references when free: the slot, the local name and getrefcount's argument
        if a is not None and sys.getrefcount(a) == 3:
            return a
        a = self._arr = np.empty(self._shape, dtype=self._dtype)
        return a
