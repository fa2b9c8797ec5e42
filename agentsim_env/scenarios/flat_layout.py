"""The flat observation layout: every part of a slot's observation in one float32 row, the scenario's and
sensors' parts first, then the inbox and its counters (with comms). ``Scenario.flat_observation`` and
``flat_observation_rows`` build it with these helpers; the env front ends hand it out.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.core.threads import RowThreads
from agentsim_env.sim.world import World

INBOX_CLIP = 1e4
"""Bound of the inbox features in observations: each is clipped to ``[-INBOX_CLIP, INBOX_CLIP]``."""


def comms_width(world: World) -> int:
    """Columns of the inbox and counter parts in a flat observation row (0 without comms)."""
    if world.comms is None:
        return 0
    inbox = world.comms.bus.inbox
    return inbox.size * inbox.n_features + 2


def write_comms(world: World, out: np.ndarray, col: int) -> None:
    """The inbox (clipped to ``INBOX_CLIP``) and counter parts of every slot into ``out[:, col:]``, as
    ``Scenario.observation`` gives them (the flat layout ends with them)."""
    assert world.comms is not None
    world.comms.observe_flat(world.state.pos, max(world.tick - 1, 0), out, col, INBOX_CLIP)


def check_rows_at(slots: np.ndarray, at: np.ndarray | None, out: np.ndarray, width: int) -> np.ndarray:
    """The rows of ``out`` the observation rows of ``slots`` go to (``at``; ``None``: ``0..len(slots)-1``), as
    contiguous int64, after checking ``out`` (a writable float32 ``(rows, width)`` array) and that ``at`` names one
    of its rows per slot.

    Raises:
        ValueError: Naming ``out`` or ``at`` and what they must be.
    """
    n = int(slots.shape[0])
    rows = n if at is None else None
    if (
        out.ndim != 2
        or out.shape[1] != width
        or (rows is not None and out.shape[0] != rows)
        or out.dtype != np.float32
        or not out.flags.writeable
    ):
        want = f"({n}, {width})" if rows is not None else f"(rows, {width})"
        raise ValueError(f"out must be a writable float32 array {want}, got {out.dtype} {out.shape}")
    if at is None:
        return np.arange(n, dtype=np.int64)
    a = np.ascontiguousarray(at, dtype=np.int64)
    if a.shape != (n,) or (n and not 0 <= int(a.min()) <= int(a.max()) < out.shape[0]):
        raise ValueError(f"at must give each of the {n} slots a row of out in [0, {out.shape[0]}), got {a.shape} {a}")
    return a


def flat_parts(
    parts: dict[str, np.ndarray],
    n_slots: int,
    out: np.ndarray | None = None,
    threads: RowThreads | None = None,
) -> np.ndarray:
    """Observation parts ``{part: (S, ...)}`` concatenated per slot into ``(S, obs_dim)`` float32: ``out`` when
    given, else a fresh array; with ``threads``, row ranges are copied on them (numpy copies without the GIL)."""
    cols = [p.reshape(n_slots, int(np.prod(p.shape[1:], dtype=np.int64))) for p in parts.values()]
    if out is None:
        if threads is None or threads.num_threads == 1:
            return np.concatenate(cols, axis=1, dtype=np.float32)
        out = np.empty((n_slots, sum(c.shape[1] for c in cols)), dtype=np.float32)
    if threads is None or threads.num_threads == 1:
        return np.concatenate(cols, axis=1, out=out)
    threads.run(lambda lo, hi, _: np.concatenate([c[lo:hi] for c in cols], axis=1, out=out[lo:hi]), n_slots)
    return out
