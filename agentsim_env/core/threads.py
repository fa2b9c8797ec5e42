"""Opt-in threads for the per-slot kernels: contiguous row ranges run on a small thread pool.

The kernels that loop over slots with independent rows (each slot writes only its own output rows: the
proximity scan, collisions, integration, the scenario observations) take a ``[lo, hi)`` row range and
release the GIL (``numba.njit(nogil=True)``). :class:`RowThreads` splits ``[0, n)`` into at most
``num_threads`` contiguous ranges and runs one per thread, so a slot's result never depends on the thread
count: it is computed by the same code from the same inputs, only on another thread.

With ``num_threads=1`` (the default everywhere) or fewer than ``min_rows`` rows per range nothing is
submitted: the kernel runs once over ``[0, n)`` on the calling thread, at the cost of one Python call.

Threads, not numba's ``parallel=True``: numba's pool size is fixed by ``NUMBA_NUM_THREADS`` when numba is
imported (benchmarks and the test suite pin it to 1) and its setting is process-wide, whereas each env
chooses its own count here.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

from agentsim_env.core.validation import check_int

MAX_THREADS = 256
"""Largest accepted ``num_threads``."""

MIN_ROWS = 4096
"""Default smallest range worth a thread: below it the hand-off costs more than the rows (about 30 us)."""


SCAN_MIN_RANGES = 4
"""Fewest row ranges at which the inbox push counts each range of receivers' messages on its own thread, each
thread reading every message and taking its own receivers' (``comms.inbox``), instead of one serial count. With
two ranges each thread would read everything to take half and mispredict its range test half the time; with
more ranges the test is mostly false and predictable. Read at call time. (The grid build was tried the same way,
each range of cells counting and placing its own slots: on the 16-core machine it took 3.9 ms on 16 threads
against 2.9 ms on one at 100,000 slots, its time going to the fresh per-cell table rather than to the slots.)"""

_POOLS: dict[int, ThreadPoolExecutor] = {}
T = TypeVar("T")


def _pool(n: int) -> ThreadPoolExecutor:
    # One executor per thread count, shared by every env of the process and kept for its lifetime.
    pool = _POOLS.get(n)
    if pool is None:
        pool = _POOLS[n] = ThreadPoolExecutor(max_workers=n, thread_name_prefix=f"agentsim-{n}")
    return pool


def light_min_rows() -> int:
    """Smallest range worth a thread for kernels of a few nanoseconds per row (scoring, reward sums), where a
    hand-off costs as much as ~10,000 rows: ``4 * MIN_ROWS`` (read at call time), for ``RowThreads.run``.

    At 10,000 slots two threads made these kernels slower; at 100,000 slots this still gives 6 ranges.
    """
    return 4 * MIN_ROWS


def check_num_threads(num_threads: object) -> int:
    """Validate a ``num_threads`` argument: an int in ``[1, 256]`` (``ValueError`` naming the field otherwise)."""
    check_int("num_threads", num_threads, 1, MAX_THREADS)
    return int(num_threads)  # type: ignore[call-overload]


def available_cores() -> int:
    """Cores this process may run on (the affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


class RowThreads:
    """Runs a row kernel over ``[0, n)`` in up to ``num_threads`` contiguous ranges.

    Args:
        num_threads: Threads to use, 1..256 (1: everything on the calling thread).
    """

    __slots__ = ("num_threads",)

    def __init__(self, num_threads: int = 1) -> None:
        self.num_threads = check_num_threads(num_threads)

    def ranges(self, n: int, min_rows: int | None = None) -> list[tuple[int, int]]:
        """The contiguous ``[lo, hi)`` ranges ``[0, n)`` is split into (one range below ``2 * min_rows``).

        ``min_rows`` defaults to the module's ``MIN_ROWS`` (read at call time).
        """
        k = max(1, min(self.num_threads, n // max(1, MIN_ROWS if min_rows is None else min_rows)))
        return [(n * i // k, n * (i + 1) // k) for i in range(k)]

    def run(self, fn: Callable[[int, int, int], T], n: int, min_rows: int | None = None) -> list[T]:
        """Call ``fn(lo, hi, part)`` for every range and return the results in range order.

        ``part`` is the range's index (for per-thread scratch buffers). The ranges after the first run on the
        pool while the calling thread runs the first; an exception is raised after every range finished.
        With one thread (or one range) this is a plain call of ``fn(0, n, 0)``.
        """
        if self.num_threads == 1:
            return [fn(0, n, 0)]
        ranges = self.ranges(n, min_rows)
        if len(ranges) == 1:
            return [fn(0, n, 0)]
        pool = _pool(len(ranges) - 1)
        futures: list[Future[T]] = [pool.submit(fn, lo, hi, p) for p, (lo, hi) in enumerate(ranges[1:], 1)]
        error: BaseException | None = None
        results: list[T] = []
        try:
            results.append(fn(ranges[0][0], ranges[0][1], 0))
        except BaseException as exc:  # noqa: BLE001  (re-raised once the other ranges are done)
            error = exc
        for f in futures:
            failed = f.exception()
            if error is None and failed is not None:
                error = failed
            elif failed is None:
                results.append(f.result())
        if error is not None:
            raise error
        return results

    def __repr__(self) -> str:
        return f"RowThreads(num_threads={self.num_threads})"
