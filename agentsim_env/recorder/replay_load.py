"""What a replay draws, read from the store and checked: the episode, its steps, the map's extent and the
frames' geometry (:func:`replay_info`), shared by the frame replay (``replay``) and the web replay
(``web_replay``).

The map extent comes from the run's scenario and config (the scenario is built again, never stepped), widened to
every recorded position; when the scenario cannot be built from its stored config (a bare ``World``, a scenario
not registered here), the recorded positions give the extent. Before anything is drawn the store is checked
(``checks``): the run's row, the config (by the scenario's config classes; keys of another version are left
out), and the episode's ``steps``, ``events`` and ``sensors`` rows (types, finite positions within
±:data:`~agentsim_env.recorder.checks.POSITION_LIMIT` m, agents within the run's count).
"""

from __future__ import annotations

import os
import sqlite3
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agentsim_env.recorder.checks import (
    POSITION_LIMIT,
    RUN_RULES,
    check_values,
    integer_within,
    number_within,
    open_read,
    stored_config,
)

HEADER = 20
"""Height in pixels of the header line above the map."""


@dataclass(frozen=True)
class Canvas:
    """Pixel geometry of replay frames: the map ``bounds`` scaled so its longest side is ``size`` pixels, north
    up, under a header of :data:`HEADER` pixels.

    Attributes:
        bounds: ``(xmin, xmax, ymin, ymax)`` in metres.
        size: Longest side of the map in pixels.
    """

    bounds: tuple[float, float, float, float]
    size: int

    @property
    def scale(self) -> float:
        """Pixels per metre."""
        xmin, xmax, ymin, ymax = self.bounds
        return self.size / max(xmax - xmin, ymax - ymin)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(H, W, 3)`` of every frame (header included)."""
        xmin, xmax, ymin, ymax = self.bounds
        s = self.scale
        return HEADER + max(1, int((ymax - ymin) * s)), max(1, int((xmax - xmin) * s)), 3

    def px(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """Frame coordinates ``(column, row)`` (floats; pixel ``(r, c)`` covers ``[c, c+1) x [r, r+1)``)."""
        xmin, _, _, ymax = self.bounds
        s = self.scale
        return (np.asarray(x, float) - xmin) * s, (ymax - np.asarray(y, float)) * s + HEADER


@dataclass(frozen=True)
class ReplayInfo:
    """What a replay draws, checked against the store.

    Attributes:
        path: The store.
        run, episode, world: The episode replayed.
        scenario: The run's scenario name.
        n_agents: Agents per world.
        steps: The recorded step numbers of the episode, ascending (step 0 first).
        canvas: The frames' geometry.
        dt: Seconds per step (None when the config does not say).
        radius: Agent radius in metres used for drawing.
        config: The run's config as validated (keys of another version left out).
        rows: The episode's ``steps`` rows.
    """

    path: str
    run: int
    episode: int
    world: int
    scenario: str
    n_agents: int
    steps: tuple[int, ...]
    canvas: Canvas
    dt: float | None
    radius: float
    config: dict[str, Any] = field(default_factory=dict, compare=False)
    rows: int = 0

    def frame_steps(self, every: int = 1) -> list[int]:
        """The steps drawn with ``every``: every ``every``-th recorded step from the first, and the last."""
        picked = list(self.steps[::every])
        if picked[-1] != self.steps[-1]:
            picked.append(self.steps[-1])
        return picked

    def fps(self, every: int = 1) -> float:
        """The frame rate that plays the replay in real time (10 when ``dt`` is unknown)."""
        return 10.0 / every if not self.dt else 1.0 / (self.dt * every)


# --------------------------------------------------------------------------------------------- loading
def _ranges(values: list[int]) -> str:
    """``[0, 1, 2, 5]`` -> ``"0-2, 5"``."""
    spans: list[list[int]] = []
    for v in sorted(set(values)):
        if spans and v == spans[-1][1] + 1:
            spans[-1][1] = v
        else:
            spans.append([v, v])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)


def _check_int(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _scenario_bounds(name: str, config: dict[str, Any]) -> tuple[float, float, float, float] | None:
    """The map bounds of scenario ``name`` built from its stored config (the world is made, never stepped).

    A config that no longer validates as a whole is retried without each sub-config in turn (the map rarely
    depends on them); None when nothing builds.
    """
    try:
        from agentsim_env.scenarios.registry import make_scenario
    except ImportError:  # pragma: no cover
        return None
    attempts = [config] + [
        {k: v for k, v in config.items() if k != drop} for drop, sub in config.items() if isinstance(sub, dict)
    ]
    for cfg in attempts:
        try:  # build() checks the memory the world needs before allocating it
            world = make_scenario(name, **cfg).build(1)
        except Exception:  # noqa: BLE001 - any failure means: not buildable from this config
            continue
        return tuple(float(b) for b in world.config.bounds)  # type: ignore[return-value]
    return None


def _extent(con: sqlite3.Connection, run: int, episode: int, world: int) -> tuple[float, ...] | None:
    """``(xmin, xmax, ymin, ymax)`` of the recorded agent and sensor positions of the episode."""
    key = (run, episode, world)
    a = con.execute(
        "SELECT min(x), max(x), min(y), max(y) FROM steps WHERE run = ? AND episode = ? AND world = ?", key
    ).fetchone()
    b = con.execute(
        "SELECT min(min(release_x, coalesce(land_x, release_x))), "
        "max(max(release_x, coalesce(land_x, release_x))), "
        "min(min(release_y, coalesce(land_y, release_y))), "
        "max(max(release_y, coalesce(land_y, release_y))) "
        "FROM sensors WHERE run = ? AND episode = ? AND world = ?",
        key,
    ).fetchone()
    boxes = [r for r in (a, b) if r is not None and None not in r]
    if not boxes:
        return None
    return (
        min(r[0] for r in boxes),
        max(r[1] for r in boxes),
        min(r[2] for r in boxes),
        max(r[3] for r in boxes),
    )


def _bounds(
    scenario: tuple[float, float, float, float] | None, data: tuple[float, ...] | None
) -> tuple[float, float, float, float]:
    """The scenario's bounds widened to the data, or the data's extent with a margin."""
    if scenario is not None:
        xmin, xmax, ymin, ymax = scenario
        if data is not None:
            xmin, xmax = min(xmin, data[0]), max(xmax, data[1])
            ymin, ymax = min(ymin, data[2]), max(ymax, data[3])
        if xmax > xmin and ymax > ymin:
            return xmin, xmax, ymin, ymax
    if data is None:
        return 0.0, 1.0, 0.0, 1.0
    pad = max(0.05 * max(data[1] - data[0], data[3] - data[2]), 1.0)
    return data[0] - pad, data[1] + pad, data[2] - pad, data[3] + pad


def replay_info(
    path: str | os.PathLike[str], run: int | None = None, episode: int = 0, world: int = 0, size: int = 512
) -> ReplayInfo:
    """Check that the store holds the episode and work out what its replay draws.

    Args:
        path: The store.
        run: The run (None: the last one recorded).
        episode: The episode within the run (0: the first).
        world: The world of a batched run (0 for a ParallelEnv run).
        size: Longest side of the map in pixels.

    Raises:
        ValueError: Missing store, no such run, world or episode (the message lists those that exist), an
            episode without recorded steps, or bad arguments.
        StoreError: A damaged store (a ValueError): a table or column missing, a value of the run or of the
            episode's rows that is of the wrong type or out of range (positions within ±:data:`POSITION_LIMIT`
            m, agents within the run's count), or a config value the scenario's config class refuses.
    """
    from agentsim_env.scenarios.config import MAX_AGENTS

    episode = _check_int("episode", episode, 0)
    world = _check_int("world", world, 0)
    size = _check_int("size", size, 32)
    con = open_read(path)
    try:
        runs = [r for (r,) in con.execute("SELECT run FROM runs WHERE typeof(run) = 'integer' ORDER BY run")]
        if not runs:
            raise ValueError(f"{path}: the store holds no runs")
        if run is None:
            run = runs[-1]
        elif _check_int("run", run, 0) not in runs:
            raise ValueError(f"{path}: no run {run}; runs in the store: {_ranges(runs)}")
        check_values(con, path, "runs", "run = ?", (run,), {**RUN_RULES, "n_agents": integer_within(1, MAX_AGENTS)})
        name, config_text, n_worlds, n_agents = con.execute(
            "SELECT scenario, config, n_worlds, n_agents FROM runs WHERE run = ?", (run,)
        ).fetchone()
        if world >= n_worlds:
            worlds = "0" if n_worlds == 1 else f"0-{n_worlds - 1}"
            raise ValueError(f"{path}: run {run} has no world {world}; its worlds: {worlds}")
        check_values(con, path, "episodes", "run = ? AND world = ?", (run, world))
        episodes = [e for (e,) in con.execute("SELECT episode FROM episodes WHERE run = ? AND world = ?", (run, world))]
        if episode not in episodes:
            have = _ranges(episodes) if episodes else "none"
            raise ValueError(f"{path}: run {run} world {world} has no episode {episode}; recorded episodes: {have}")
        key, where = (run, episode, world), "run = ? AND episode = ? AND world = ?"
        position = number_within(POSITION_LIMIT)
        check_values(
            con,
            path,
            "steps",
            where,
            key,
            {
                "step": integer_within(0),
                "agent": integer_within(0, n_agents - 1),
                "x": position,
                "y": position,
                "z": position,
                **{c: number_within() for c in ("vx", "vy", "vz", "heading")},
            },
        )
        check_values(con, path, "events", where, key)
        check_values(
            con,
            path,
            "sensors",
            where,
            key,
            {c: position for c in ("release_x", "release_y", "release_z", "land_x", "land_y")},
        )
        steps = tuple(s for (s,) in con.execute(f"SELECT DISTINCT step FROM steps WHERE {where} ORDER BY step", key))
        if not steps:
            raise ValueError(f"{path}: run {run} world {world} episode {episode} has no recorded steps")
        (rows,) = con.execute(f"SELECT count(*) FROM steps WHERE {where}", key).fetchone()
        config, cfg = stored_config(path, run, name, config_text)
        bounds = _bounds(_scenario_bounds(name, config), _extent(con, run, episode, world))
    finally:
        con.close()
    return ReplayInfo(
        path=str(path),
        run=int(run),
        episode=episode,
        world=world,
        scenario=str(name),
        n_agents=int(n_agents),
        steps=steps,
        canvas=Canvas(bounds, size),
        dt=float(cfg.dt) if "dt" in config else None,
        radius=float(cfg.body.radius),
        config=config,
        rows=int(rows),
    )


__all__ = ["HEADER", "Canvas", "ReplayInfo", "replay_info"]
