"""Rows between the driver's full-length arrays and a shard's compact rows, one row at a time.

The step API moves every acting agent's action row to its shard and every observation row back (~73 MB a step at
100,000 agents in ``navigation`` with comms). numpy's fancy indexing does this through its generic iterator; these
loops copy each row in place, about a third faster for the observation rows and three times for the strided
action columns (measured on the 2-CPU VM: 50,000 rows of 183 float32, 9.2 -> 6.0 ms; 50,000 rows of 3-7 float64
columns of a wider array, 0.8-1.3 -> 0.3-0.4 ms).
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numba as nb
import numpy as np

_SPLIT_ROWS = 8192  # fewer rows than this are copied on one thread whatever ``threads`` says
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="agentsim-rows")
        return _pool


@nb.njit(cache=True, nogil=True)
def _scatter(out, slots, rows):  # type: ignore[no-untyped-def]
    d = rows.shape[1]
    for i in range(slots.shape[0]):
        o = out[slots[i]]
        for j in range(d):
            o[j] = rows[i, j]


@nb.njit(cache=True, nogil=True)
def _gather(src, slots, out):  # type: ignore[no-untyped-def]
    d = src.shape[1]
    for i in range(slots.shape[0]):
        s = slots[i]
        for j in range(d):
            out[i, j] = src[s, j]


def _check(slots: np.ndarray, n_rows: int, n_slots: int, name: str) -> None:
    if slots.ndim != 1 or slots.shape[0] != n_rows:
        raise ValueError(f"{name}: slots must have shape ({n_rows},), got {slots.shape}")
    if slots.size and (int(slots.min()) < 0 or int(slots.max()) >= n_slots):
        raise ValueError(f"{name}: slots must lie in [0, {n_slots}), got {int(slots.min())}..{int(slots.max())}")


def scatter_rows(out: np.ndarray, slots: np.ndarray, rows: np.ndarray, threads: int = 1) -> None:
    """``out[slots] = rows`` for 2-D ``out`` and ``rows`` of one dtype (``slots`` int64, in bounds).

    ``threads``: 2 copies the second half of a large block on a helper thread at the same time (use it when a CPU
    is free: the kernel releases the GIL); the result is the same (each row is written once).
    """
    _check(slots, rows.shape[0], out.shape[0], "scatter_rows")
    if rows.ndim != 2 or rows.shape[1] != out.shape[1] or rows.dtype != out.dtype or slots.dtype != np.int64:
        out[slots] = rows
        return
    n = slots.shape[0]
    if threads < 2 or n < _SPLIT_ROWS:
        _scatter(out, slots, rows)
        return
    h = n // 2
    other = _executor().submit(_scatter, out, slots[h:], rows[h:])
    _scatter(out, slots[:h], rows[:h])
    other.result()


def gather_rows(src: np.ndarray, slots: np.ndarray, out: np.ndarray) -> None:
    """``out[:] = src[slots]`` for 2-D ``src`` (any strides) and ``out`` of one dtype (``slots`` int64)."""
    _check(slots, out.shape[0], src.shape[0], "gather_rows")
    if src.ndim != 2 or out.shape[1:] != src.shape[1:] or src.dtype != out.dtype or slots.dtype != np.int64:
        np.take(src, slots, axis=0, out=out)
        return
    _gather(src, slots, out)


def warm() -> None:
    """Compile the forms the step API hands them: observation rows writable (shared memory) and read-only (Ray's
    object store), slots either way; action columns strided or contiguous into a writable region."""
    out = np.zeros((4, 3), np.float32)
    for ro_slots in (False, True):
        slots = np.array([2, 0], dtype=np.int64)
        slots.flags.writeable = not ro_slots
        for ro_rows in (False, True):
            rows = np.ones((2, 3), np.float32)
            rows.flags.writeable = not ro_rows
            scatter_rows(out, slots, rows)
    wide = np.ones((4, 5))
    for src in (wide[:, 1:4], np.ascontiguousarray(wide[:, 1:4])):
        gather_rows(src, np.array([3, 1], dtype=np.int64), np.zeros((2, 3)))
