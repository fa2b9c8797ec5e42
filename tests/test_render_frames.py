"""What the 2D frames show: ``render_mode="rgb_array"`` frames (``render.topdown``), trajectory PNGs
(``render.trajectories``) and the store's replay frames (``recorder.replay``): agents a few pixels wide on any
map, one colour per agent up to a dozen (per group beyond), goals and obstacles where the env has them."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.core.scene import BOX
from agentsim_env.policies.registry import make_policy
from agentsim_env.policies.rollout import run_episode
from agentsim_env.recorder import record
from agentsim_env.recorder.replay import replay_frames, replay_info
from agentsim_env.render.trajectories import TrajectoryRecorder, plot_trajectories

Image = pytest.importorskip("PIL.Image")
SIZE = 512  # render_topdown's default longest side
BIG_MAP = 5000.0  # metres: an agent of radius 0.5 m is a tenth of a pixel at true size


def _frame(**config: Any) -> tuple[Any, np.ndarray]:
    env = agentsim_env.make("navigation", render_mode="rgb_array", **config)
    env.reset(seed=0)
    frame = env.render()
    assert frame is not None
    return env, frame


def _px(env: Any, frame: np.ndarray, x: float, y: float) -> tuple[float, float]:
    """Frame ``(column, row)`` of world point ``(x, y)`` (north up, the longest side ``SIZE`` pixels)."""
    xmin, xmax, ymin, ymax = env.world.config.bounds
    scale = max(frame.shape[:2]) / max(xmax - xmin, ymax - ymin)
    return (x - xmin) * scale, (ymax - y) * scale


def _blob(frame: np.ndarray, cx: float, cy: float, reach: int = 20) -> tuple[np.ndarray, int]:
    """The colour at ``(cx, cy)`` and how many pixels of exactly that colour lie within ``reach`` pixels."""
    color = frame[int(cy), int(cx)]
    r0, r1 = max(int(cy) - reach, 0), int(cy) + reach + 1
    c0, c1 = max(int(cx) - reach, 0), int(cx) + reach + 1
    return color, int((frame[r0:r1, c0:c1] == color).all(axis=2).sum())


def _agent_centres(env: Any, frame: np.ndarray) -> list[tuple[float, float]]:
    st = env.world.state
    return [_px(env, frame, *st.pos[s, :2]) for s in st.slots_of_world(0)]


def test_agents_cover_many_pixels_on_a_large_map() -> None:
    env, frame = _frame(n_agents=6, map_size=BIG_MAP, obstacle_density=0.0)
    assert max(frame.shape[:2]) == SIZE
    for k, (cx, cy) in enumerate(_agent_centres(env, frame)):
        color, n = _blob(frame, cx, cy)
        assert not (color == frame[0, 0]).all(), f"agent {k}: background at its position"
        assert n >= 60, f"agent {k}: only {n} pixels of its colour {color} around its position"


def test_a_dozen_agents_have_a_dozen_distinct_colours() -> None:
    env, frame = _frame(n_agents=12, map_size=BIG_MAP, obstacle_density=0.0)
    colors = np.array([frame[int(cy), int(cx)] for cx, cy in _agent_centres(env, frame)], dtype=float)
    gaps = np.sqrt(((colors[:, None] - colors[None]) ** 2).sum(axis=2))
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= 60, f"two agents look alike: RGB distance {gaps.min():.0f}\n{colors}"


def test_beyond_a_dozen_agents_one_colour_per_group() -> None:
    env, frame = _frame(n_agents=30, n_groups=3, map_size=BIG_MAP, obstacle_density=0.0)
    group = env.world.state.group[env.world.state.slots_of_world(0)]
    centres = _agent_centres(env, frame)
    # agents whose discs overlap no other agent's
    alone = [
        i
        for i, (x, y) in enumerate(centres)
        if all(np.hypot(x - u, y - v) > 30 for j, (u, v) in enumerate(centres) if j != i)
    ]
    by_group: dict[int, set[tuple[int, ...]]] = {}
    for i in alone:
        by_group.setdefault(int(group[i]), set()).add(
            tuple(int(c) for c in frame[int(centres[i][1]), int(centres[i][0])])
        )
    assert len(by_group) == 3 and all(len(c) == 1 for c in by_group.values()), by_group
    assert len(set().union(*by_group.values())) == 3


def test_goals_drawn_at_the_env_goal_positions_on_a_large_map() -> None:
    env, frame = _frame(n_agents=4, map_size=BIG_MAP, obstacle_density=0.0)
    xy, rgb, _ = env.scenario.markers(env.world, 0)
    centres = _agent_centres(env, frame)
    for k, ((x, y), c) in enumerate(zip(xy, rgb)):
        gx, gy = _px(env, frame, x, y)
        if any(np.hypot(gx - u, gy - v) < 20 for u, v in centres):
            continue  # an agent drawn over its goal
        color, n = _blob(frame, gx, gy)
        assert (color == c).all(), f"goal {k}: {color} at its position, the scenario says {c}"
        assert n >= 20, f"goal {k}: only {n} pixels wide"


def _trajectory_png(tmp_path: Path, n_agents: int) -> np.ndarray:
    env = agentsim_env.make("navigation", n_agents=n_agents, max_steps=20)
    rec = TrajectoryRecorder()
    run_episode(env, make_policy("navigation", env), 0, on_step=rec)
    path = plot_trajectories(rec.result(env), tmp_path / "t.png", "test")
    return np.asarray(Image.open(path).convert("RGB")).astype(int)


def test_trajectory_png_draws_each_agent_in_its_own_colour(tmp_path: Path) -> None:
    from agentsim_env.render.palette import agent_colors

    img = _trajectory_png(tmp_path, 4)
    for k, c in enumerate(agent_colors(4)):
        near = (np.abs(img - c.astype(int)).sum(axis=2) <= 30).sum()
        assert near >= 40, f"agent {k}: its colour {c} covers {near} pixels of the figure"


def test_replay_frames_show_the_obstacles_and_goals_of_the_episode(tmp_path: Path) -> None:
    path = tmp_path / "run.db"
    env = record(agentsim_env.make("navigation", n_agents=3, max_steps=3, obstacle_density=0.004), path)
    seen: list[Any] = []

    def at_reset(e: Any, infos: dict[str, Any]) -> None:
        if not seen:  # the scene and the goals right after the reset
            sc = e.world.scene
            seen.append(
                [(sc.centre[o, 0], sc.centre[o, 1]) for o in np.flatnonzero(sc.world == 0) if sc.kind[o] == BOX]
            )
            seen.append([np.array(a) for a in e.scenario.markers(e.world, 0)])

    run_episode(env, make_policy("navigation", env), 5, on_step=at_reset)
    env.close()
    boxes, (goals, goal_rgb, _) = seen
    info = replay_info(path)
    first = next(iter(replay_frames(path)))
    background = first[-1, -1]
    assert len(boxes) >= 3
    drawn = [not (first[int(cy), int(cx)] == background).all() for cx, cy in (info.canvas.px(x, y) for x, y in boxes)]
    assert sum(drawn) >= len(boxes) - 1, f"{sum(drawn)} of {len(boxes)} obstacles drawn"
    hits = [
        (first[int(cy), int(cx)] == c).all() for (cx, cy), c in zip((info.canvas.px(x, y) for x, y in goals), goal_rgb)
    ]
    assert sum(hits) >= 2, f"{sum(hits)} of {len(goals)} goals drawn in their colour"


def test_replay_of_a_damaged_seed_fails_when_called_and_names_the_column(tmp_path: Path) -> None:
    from agentsim_env.recorder.schema import StoreError
    from tests.store_helpers import small_store

    path = small_store(tmp_path / "run.db")
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE episodes SET seed = 'x1'")
    con.close()
    with pytest.raises(StoreError, match=r"episodes\.seed holds 'x1'"):
        replay_frames(path)  # before any frame is taken


def test_replay_frames_colour_agents_by_group_beyond_a_dozen(tmp_path: Path) -> None:
    from agentsim_env.recorder.replay import agent_color

    path = tmp_path / "run.db"
    env = record(
        agentsim_env.make("navigation", n_agents=16, n_groups=2, max_steps=2, map_size=400.0, obstacle_density=0.0),
        path,
    )
    run_episode(env, make_policy("navigation", env), 0)
    group = np.array(env.world.state.group[env.world.state.slots_of_world(0)])
    env.close()
    info = replay_info(path)
    first = next(iter(replay_frames(path)))
    con = sqlite3.connect(path)
    rows = con.execute("SELECT agent, x, y FROM steps WHERE step = 0").fetchall()
    con.close()
    centres = {a: info.canvas.px(x, y) for a, x, y in rows}
    seen = set()
    for a, (cx, cy) in centres.items():
        if any(np.hypot(cx - u, cy - v) < 20 for b, (u, v) in centres.items() if b != a):
            continue  # overlapping discs
        assert (first[int(cy), int(cx)] == agent_color(a, 16, int(group[a]))).all(), a
        seen.add(tuple(first[int(cy), int(cx)]))
    assert len(seen) == 2


def test_a_goal_per_agent_of_a_big_world_leaves_the_paths_visible(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 12,000 agents with a goal each on a 1 km map: an even sample of the goals is drawn, small enough that they
    # cover a few percent of the map, and the legend says how many of them
    import matplotlib.axes
    import matplotlib.collections

    import agentsim_env.render.trajectories as tr

    n, side = 12_000, 1_000.0
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, side, (2, n, 2))
    markers = (
        rng.uniform(0, side, (n, 2)),
        np.tile(np.array([[40, 170, 60]], np.uint8), (n, 1)),
        np.full(n, 1.0),
    )
    traj = tr.Trajectories(
        [f"agent_{i}" for i in range(n)],
        xy,
        np.ones(n, np.int64),
        ["active"] * n,
        (0.0, side, 0.0, side),
        markers=markers,
        steps=1,
    )
    drawn: list[Any] = []
    real = matplotlib.collections.PatchCollection

    def spy(patches: Any, **kw: Any) -> Any:
        drawn.append(list(patches))
        return real(patches, **kw)

    labels: list[str] = []
    real_legend = matplotlib.axes.Axes.legend

    def legend_spy(ax: Any, *a: Any, **kw: Any) -> Any:
        labels.extend(str(h.get_label()) for h in kw.get("handles", []))
        return real_legend(ax, *a, **kw)

    monkeypatch.setattr(matplotlib.collections, "PatchCollection", spy)  # imported when the plot is drawn
    monkeypatch.setattr(matplotlib.axes.Axes, "legend", legend_spy)
    plot_trajectories(traj, tmp_path / "big.png", "big")
    discs = drawn[-1]
    assert len(discs) == tr.MAX_PATHS
    covered = sum(np.pi * d.radius**2 for d in discs) / side**2
    assert covered < 0.05, covered
    assert any(f"{tr.MAX_PATHS:,} of {n:,}" in lab for lab in labels), labels
    assert (tmp_path / "big.png").stat().st_size > 10_000
