"""The per-step passes of the env front ends around the pipeline, each one numba kernel.

``prepare_actions`` checks and clips the actions of the live agents (zeros for the others) before a
``BatchedEnv`` step; ``finish_step`` works out truncations, the agents still alive, the zeroed observations of
agents that ended earlier and the worlds to reset after it; ``scatter_part`` puts one stacked action part of
the ParallelEnv's live agents into its slots, checked and clipped. Each replaces a handful of small numpy
passes whose fixed cost dominated small worlds; the numpy statements they replace are in
``tests/reference/batch_kernels.py`` (the tests check that both give the same bits).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _prepare_kernel(a, alive, out):  # type: ignore[no-untyped-def]
    for s in range(a.shape[0]):
        if alive[s]:
            for d in range(a.shape[1]):
                x = a[s, d]
                if not np.isfinite(x):
                    return s
                out[s, d] = -1.0 if x < -1.0 else (1.0 if x > 1.0 else x)
        else:
            for d in range(a.shape[1]):
                out[s, d] = 0.0
    return -1


def prepare_actions(actions: np.ndarray, alive: np.ndarray) -> tuple[np.ndarray, int]:
    """The actions of live slots clipped to [-1, 1], zeros for the others, and the first bad slot.

    Args:
        actions: ``(S, D)`` float64 actions.
        alive: ``(S,)`` bool, the slots whose actions count.

    Returns:
        A fresh ``(S, D)`` float64 array, and the first live slot (in slot order) with a NaN or inf action, or
        -1 when there is none (the array is then incomplete: the caller raises).
    """
    out = np.empty(actions.shape, dtype=np.float64)
    bad = _prepare_kernel(np.ascontiguousarray(actions, dtype=np.float64), alive, out)
    return out, int(bad)


@nb.njit(cache=True)
def _finish_kernel(term, acting, over, alive, trunc, obs, done):  # type: ignore[no-untyped-def]
    n_worlds, n = alive.shape
    n_done = 0
    for w in range(n_worlds):
        left = False
        for i in range(n):
            s = w * n + i
            u = acting[s] and not term[s] and over[w]
            trunc[s] = u
            ended = term[s] or u
            if ended:
                alive[w, i] = False
            elif not alive[w, i]:
                for d in range(obs.shape[1]):
                    obs[s, d] = 0.0
            left = left or alive[w, i]
        done[w] = not left
        n_done += 0 if left else 1
    return n_done


def finish_step(
    term: np.ndarray, acting: np.ndarray, over: np.ndarray, alive: np.ndarray, obs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Truncations, alive mask, zeroed rows and finished worlds after a batched step (in place where noted).

    Args:
        term: ``(S,)`` bool, slots that terminated this step.
        acting: ``(S,)`` bool, slots that acted this step.
        over: ``(B,)`` bool, worlds whose time limit is reached.
        alive: ``(B, N)`` bool, updated: agents that terminated or were truncated are no longer alive.
        obs: ``(S, D)`` observations, updated: rows of agents that ended before this step are zeroed.

    Returns:
        ``trunc`` ``(S,)`` bool, ``done`` ``(B,)`` bool (worlds with no agent left alive) and the number of them.
    """
    trunc = np.empty(term.shape[0], dtype=np.bool_)
    done = np.empty(alive.shape[0], dtype=np.bool_)
    n_done = _finish_kernel(term, acting, over, alive, trunc, obs, done)
    return trunc, done, int(n_done)


@nb.njit(cache=True)
def _scatter_kernel(a, idx, lo, hi, out):  # type: ignore[no-untyped-def]
    for r in range(a.shape[0]):
        s = idx[r]
        for d in range(a.shape[1]):
            x = a[r, d]
            if not np.isfinite(x):
                return False
            m = x if x >= lo else lo  # max then min, as np.clip evaluates it
            out[s, d] = m if m <= hi else hi
    return True


def scatter_part(values: np.ndarray, idx: np.ndarray, n_slots: int, low: float, high: float) -> np.ndarray | None:
    """Rows ``values`` put at slots ``idx`` of a zeroed ``(n_slots, size)`` float64 array, clipped to [low, high].

    Args:
        values: ``(n, size)`` real numbers, one row per live agent.
        idx: ``(n,)`` int64, the agents' slots (distinct).
        n_slots: Rows of the result.
        low: Lower bound.
        high: Upper bound.

    Returns:
        The array, or ``None`` when a value is NaN or inf.
    """
    out = np.zeros((n_slots, values.shape[1]), dtype=np.float64)
    ok = _scatter_kernel(np.ascontiguousarray(values, dtype=np.float64), idx, float(low), float(high), out)
    return out if ok else None
