"""Per-agent dicts built from arrays: the ParallelEnv builds several of them per step, for thousands of agents."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np


@functools.lru_cache(maxsize=64)
def _builder(keys: tuple[str, ...]) -> Callable[..., dict[str, Any]]:
    """A function ``f(v0, v1, ...) -> {keys[0]: v0, ...}`` for a fixed key tuple.

    A dict display over closure keys builds each small dict about twice as fast as ``dict(zip(keys, values))``,
    which matters when thousands of per-agent dicts are built every step. Written out for up to eight keys
    (every observation and info layout of the shipped scenarios); longer tuples fall back to ``zip``.
    """
    n = len(keys)
    k0, k1, k2, k3, k4, k5, k6, k7 = (*keys, *[""] * 8)[:8]  # padding keys are never used
    builders: dict[int, Callable[..., dict[str, Any]]] = {
        1: lambda a: {k0: a},
        2: lambda a, b: {k0: a, k1: b},
        3: lambda a, b, c: {k0: a, k1: b, k2: c},
        4: lambda a, b, c, d: {k0: a, k1: b, k2: c, k3: d},
        5: lambda a, b, c, d, e: {k0: a, k1: b, k2: c, k3: d, k4: e},
        6: lambda a, b, c, d, e, f: {k0: a, k1: b, k2: c, k3: d, k4: e, k5: f},
        7: lambda a, b, c, d, e, f, g: {k0: a, k1: b, k2: c, k3: d, k4: e, k5: f, k6: g},
        8: lambda a, b, c, d, e, f, g, h: {k0: a, k1: b, k2: c, k3: d, k4: e, k5: f, k6: g, k7: h},
    }
    return builders.get(n, lambda *vals: dict(zip(keys, vals)))


def per_agent(agents: list[str], keys: tuple[str, ...], columns: list[Any]) -> dict[str, dict[str, Any]]:
    """``{agents[j]: {keys[i]: columns[i][j]}}``: one small dict per agent, built in a single pass.

    A dict comprehension with the keys as locals for up to four keys (every observation and info layout of the
    plain scenarios), :func:`_builder` beyond.

    Args:
        agents: The agent ids, one per row.
        keys: The inner dicts' keys, one per column.
        columns: One sequence per key, each as long as ``agents``.

    Returns:
        The dict of dicts.
    """
    if len(keys) == 3:
        k0, k1, k2 = keys
        c0, c1, c2 = columns
        return {a: {k0: x, k1: y, k2: z} for a, x, y, z in zip(agents, c0, c1, c2)}
    if len(keys) == 4:
        k0, k1, k2, k3 = keys
        c0, c1, c2, c3 = columns
        return {a: {k0: x, k1: y, k2: z, k3: u} for a, x, y, z, u in zip(agents, c0, c1, c2, c3)}
    if len(keys) == 2:
        k0, k1 = keys
        c0, c1 = columns
        return {a: {k0: x, k1: y} for a, x, y in zip(agents, c0, c1)}
    if len(keys) == 1:
        k0 = keys[0]
        return {a: {k0: x} for a, x in zip(agents, columns[0])}
    return dict(zip(agents, map(_builder(keys), *columns)))


def rows(values: np.ndarray, idx: np.ndarray | None) -> list[Any]:
    """``values[idx]`` (every row when ``idx`` is None) as a list of Python scalars.

    Args:
        values: One value per slot.
        idx: The slots to read, or None for all.

    Returns:
        The list.
    """
    return (values if idx is None else values[idx]).tolist()  # type: ignore[no-any-return]


def stay_dicts(
    agents: list[str],
    acting: np.ndarray,
    rewards: np.ndarray,
    terminated: np.ndarray,
    truncated: np.ndarray,
    info: dict[str, np.ndarray],
) -> tuple[dict[str, float], dict[str, bool], dict[str, bool], dict[str, dict[str, Any]]]:
    """Rewards, flags and infos of a step over every agent of the episode (``ended_agents="stay"``).

    An agent that ended in an earlier step gets reward 0 and every info key at 0 (in the key's dtype: False for
    a flag); the flags are the ones it ended with.

    Args:
        agents: Every agent of the episode, one per slot.
        acting: ``(S,)`` the slots that acted this step.
        rewards: ``(S,)`` this step's rewards.
        terminated: ``(S,)`` whether each agent has terminated so far in the episode.
        truncated: ``(S,)`` whether each agent has been truncated so far.
        info: ``{key: (S,) values}`` of this step.

    Returns:
        ``(rewards, terminated, truncated, infos)`` dicts keyed by agent.
    """
    gone = ~acting
    rew = dict(zip(agents, np.where(acting, np.asarray(rewards, dtype=np.float64), 0.0).tolist()))
    cols = []
    for values in info.values():
        col = np.array(values, copy=True)
        col[gone] = 0
        cols.append(col.tolist())
    infos = per_agent(agents, tuple(info), cols) if cols else {a: {} for a in agents}
    return rew, dict(zip(agents, terminated.tolist())), dict(zip(agents, truncated.tolist())), infos
