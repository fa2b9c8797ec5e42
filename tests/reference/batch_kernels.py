"""Plain numpy statements of the env front ends' per-step kernels (:mod:`agentsim_env.env.batch_kernels`).

Each replaces one numba kernel by the handful of numpy passes it stands for; the tests check that both give the
same bits.
"""

from __future__ import annotations

import numpy as np


def prepare_actions_reference(actions: np.ndarray, alive: np.ndarray) -> tuple[np.ndarray, int]:
    """Plain numpy statement of :func:`prepare_actions` (same contract)."""
    a = np.asarray(actions, dtype=np.float64)
    bad = ~np.isfinite(a).all(axis=1) & alive
    if bad.any():
        return np.zeros(a.shape), int(np.flatnonzero(bad)[0])
    return np.clip(np.where(alive[:, None], a, 0.0), -1.0, 1.0), -1


def finish_step_reference(
    term: np.ndarray, acting: np.ndarray, over: np.ndarray, alive: np.ndarray, obs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Plain numpy statement of :func:`finish_step` (same contract)."""
    n = alive.shape[1]
    trunc = acting & ~term & np.repeat(over, n)
    ended = (term | trunc).reshape(alive.shape)
    alive &= ~ended
    obs[(~alive & ~ended).reshape(-1)] = 0.0
    done = np.asarray(~alive.any(axis=1))
    return trunc, done, int(done.sum())


def scatter_part_reference(
    values: np.ndarray, idx: np.ndarray, n_slots: int, low: float, high: float
) -> np.ndarray | None:
    """Plain numpy statement of :func:`scatter_part` (same contract)."""
    out = np.zeros((n_slots, values.shape[1]))
    out[idx] = values
    if not np.isfinite(out).all():
        return None
    return np.clip(out, low, high, out=out)
