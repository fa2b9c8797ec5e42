"""Replay a recorded episode from the store alone: RGB frames, a folder of PNGs, or an MP4 / GIF video.

Nothing is simulated again. Each frame is drawn with numpy from the ``steps`` rows of one step of one episode of
one world: every agent at its recorded position (a disc in its own colour with a heading dot), the trail it has
flown, agents that went offline in grey, agents already done (no row any more) faded at their last position,
collisions from the ``events`` table as red rings for :data:`COLLISION_HOLD` steps, and for ``uav_release`` the
sensors of the ``sensors`` table (released and falling: an orange ring at the release point; landed: a green
dot). A header line names the run, scenario, episode, world and step. Obstacles and goals are not stored, so
they are not drawn.

The map extent comes from the run's scenario and config (the scenario is built again, never stepped), widened to
every recorded position; when the scenario cannot be built from its stored config (a bare ``World``, a config
that no longer validates), the recorded positions give the extent. Every frame of a replay has one size.
"""

from __future__ import annotations

import functools
import json
import os
import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.recorder.schema import connect

__all__ = [
    "BACKGROUND",
    "COLLISION_HOLD",
    "HEADER",
    "Canvas",
    "ReplayInfo",
    "agent_color",
    "replay_frames",
    "replay_info",
    "write_replay",
]

HEADER = 20
"""Height in pixels of the header line above the map."""
BACKGROUND = 236
"""Grey level of the map background."""
COLLISION_HOLD = 10
"""Steps a collision ring stays around an agent."""
_PALETTE = np.array(
    [[31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
     [140, 86, 75], [227, 119, 194], [23, 190, 207], [188, 189, 34], [60, 60, 160]],
    dtype=np.uint8,
)  # fmt: skip
_OFFLINE = np.array([150, 150, 150], dtype=np.uint8)
_HEADING = np.array([20, 20, 60], dtype=np.uint8)
_COLLISION = np.array([220, 20, 20], dtype=np.uint8)
_FALLING = np.array([240, 150, 20], dtype=np.uint8)
_LANDED = np.array([20, 130, 40], dtype=np.uint8)
_HEADER_BG = np.array([40, 44, 52], dtype=np.uint8)
_FETCH = 20_000  # steps rows read per batch


def agent_color(agent: int) -> np.ndarray:
    """The RGB colour (uint8) of agent ``agent`` (its index within the world) in replay frames."""
    return _PALETTE[agent % len(_PALETTE)].copy()


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
    attempts = [config] + [{k: v for k, v in config.items() if k != drop}
                           for drop, sub in config.items() if isinstance(sub, dict)]  # fmt: skip
    for cfg in attempts:
        try:
            world = make_scenario(name, **cfg).make_world(1)
        except Exception:  # noqa: BLE001 - any failure means: not buildable from this config
            continue
        return tuple(float(b) for b in world.config.bounds)  # type: ignore[return-value]
    return None


def _extent(con: sqlite3.Connection, run: int, episode: int, world: int) -> tuple[float, ...] | None:
    """``(xmin, xmax, ymin, ymax)`` of the recorded agent and sensor positions of the episode."""
    key = (run, episode, world)
    a = con.execute("SELECT min(x), max(x), min(y), max(y) FROM steps WHERE run = ? AND episode = ? AND world = ?",
                    key).fetchone()  # fmt: skip
    b = con.execute("SELECT min(min(release_x, coalesce(land_x, release_x))), "
                    "max(max(release_x, coalesce(land_x, release_x))), "
                    "min(min(release_y, coalesce(land_y, release_y))), "
                    "max(max(release_y, coalesce(land_y, release_y))) "
                    "FROM sensors WHERE run = ? AND episode = ? AND world = ?", key).fetchone()  # fmt: skip
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
    """
    episode = _check_int("episode", episode, 0)
    world = _check_int("world", world, 0)
    size = _check_int("size", size, 32)
    con = connect(path, create=False)
    try:
        runs = [r for (r,) in con.execute("SELECT run FROM runs ORDER BY run")]
        if not runs:
            raise ValueError(f"{path}: the store holds no runs")
        if run is None:
            run = runs[-1]
        elif _check_int("run", run, 0) not in runs:
            raise ValueError(f"{path}: no run {run}; runs in the store: {_ranges(runs)}")
        name, config_text, n_worlds, n_agents = con.execute(
            "SELECT scenario, config, n_worlds, n_agents FROM runs WHERE run = ?", (run,)
        ).fetchone()
        if world >= n_worlds:
            worlds = _ranges(list(range(n_worlds)))
            raise ValueError(f"{path}: run {run} has no world {world}; its worlds: {worlds}")
        episodes = [e for (e,) in con.execute("SELECT episode FROM episodes WHERE run = ? AND world = ?",
                                              (run, world))]  # fmt: skip
        if episode not in episodes:
            have = _ranges(episodes) if episodes else "none"
            raise ValueError(
                f"{path}: run {run} world {world} has no episode {episode}; recorded episodes: {have}"
            )
        steps = tuple(s for (s,) in con.execute(
            "SELECT DISTINCT step FROM steps WHERE run = ? AND episode = ? AND world = ? ORDER BY step",
            (run, episode, world)))  # fmt: skip
        if not steps:
            raise ValueError(f"{path}: run {run} world {world} episode {episode} has no recorded steps")
        try:
            config = json.loads(config_text)
        except ValueError:
            config = {}
        config = config if isinstance(config, dict) else {}
        bounds = _bounds(_scenario_bounds(name, config), _extent(con, run, episode, world))
    finally:
        con.close()
    dt = config.get("dt")
    body = config.get("body")
    radius = body.get("radius") if isinstance(body, dict) else None
    return ReplayInfo(
        path=str(path), run=int(run), episode=episode, world=world, scenario=str(name), n_agents=int(n_agents),
        steps=steps, canvas=Canvas(bounds, size), dt=float(dt) if isinstance(dt, (int, float)) and dt > 0 else None,
        radius=float(radius) if isinstance(radius, (int, float)) and radius > 0 else 0.5,
    )  # fmt: skip


def _step_rows(con: sqlite3.Connection, info: ReplayInfo) -> Iterator[tuple[int, np.ndarray]]:
    """``(step, rows)`` per recorded step, ``rows`` an ``(k, 5)`` array of agent, x, y, heading, online."""
    cur = con.execute(
        "SELECT step, agent, x, y, heading, online FROM steps WHERE run = ? AND episode = ? AND world = ? "
        "ORDER BY step", (info.run, info.episode, info.world))  # fmt: skip
    pending: np.ndarray | None = None
    while True:
        batch = cur.fetchmany(_FETCH)
        if not batch:
            break
        a = np.array(batch, dtype=float)
        if pending is not None:
            a = np.concatenate([pending, a])
        groups = np.split(a, np.flatnonzero(np.diff(a[:, 0])) + 1)
        for g in groups[:-1]:
            yield int(g[0, 0]), g[:, 1:]
        pending = groups[-1]
    if pending is not None and len(pending):
        yield int(pending[0, 0]), pending[:, 1:]


# --------------------------------------------------------------------------------------------- drawing
def _discs(
    img: np.ndarray, cx: np.ndarray, cy: np.ndarray, r: float, colors: np.ndarray, hole: float = 0.0
) -> None:
    """Filled discs (or rings, inner radius ``hole``) of radius ``r`` pixels; ``colors`` ``(k, 3)`` or ``(3,)``."""
    h, w, _ = img.shape
    colors = np.broadcast_to(colors, (len(cx), 3))
    for x, y, c in zip(np.asarray(cx, float), np.asarray(cy, float), colors):
        if not (np.isfinite(x) and np.isfinite(y)):
            continue
        x0, x1 = max(int(x - r), 0), min(int(x + r) + 1, w)
        y0, y1 = max(int(y - r), HEADER), min(int(y + r) + 1, h)
        if x0 >= x1 or y0 >= y1:
            continue
        yy, xx = np.mgrid[y0:y1, x0:x1]
        d2 = (xx + 0.5 - x) ** 2 + (yy + 0.5 - y) ** 2
        m = (d2 <= r * r) & (d2 >= hole * hole)
        img[y0:y1, x0:x1][m] = c


def _segments(img: np.ndarray, p0: tuple[np.ndarray, np.ndarray], p1: tuple[np.ndarray, np.ndarray],
              colors: np.ndarray) -> None:  # fmt: skip
    """One-pixel lines from ``p0`` to ``p1`` (``(columns, rows)``), one colour per segment."""
    (x0, y0), (x1, y1) = p0, p1
    ok = np.isfinite(x0) & np.isfinite(y0) & np.isfinite(x1) & np.isfinite(y1)
    if not ok.any():
        return
    x0, y0, x1, y1, colors = x0[ok], y0[ok], x1[ok], y1[ok], colors[ok]
    n = np.minimum(np.ceil(2 * np.hypot(x1 - x0, y1 - y0)).astype(np.int64), 4 * max(img.shape)) + 1
    seg = np.repeat(np.arange(len(n)), n)
    t = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.maximum(np.repeat(n, n) - 1, 1)
    c = (x0[seg] + t * (x1 - x0)[seg]).astype(np.int64)
    r = (y0[seg] + t * (y1 - y0)[seg]).astype(np.int64)
    inside = (c >= 0) & (c < img.shape[1]) & (r >= HEADER) & (r < img.shape[0])
    img[r[inside], c[inside]] = colors[seg[inside]]


@functools.lru_cache(maxsize=1)
def _font() -> Any:
    """Matplotlib's FreeType face of DejaVu Sans Mono (None when unavailable: headers without text)."""
    try:
        from matplotlib import font_manager
        from matplotlib.ft2font import FT2Font

        return FT2Font(font_manager.findfont("DejaVu Sans Mono"))
    except Exception:  # noqa: BLE001 - text is a nicety; frames are drawn without it
        return None


def _header(img: np.ndarray, text: str) -> None:
    """Fill the header band and write ``text`` in it (white, antialiased)."""
    img[:HEADER] = _HEADER_BG
    font = _font()
    if font is None:
        return
    try:
        font.clear()
        font.set_size(10, 72)
        font.set_text(text, 0.0)
        font.draw_glyphs_to_bitmap(antialiased=True)
        glyphs = np.asarray(font.get_image(), dtype=np.float32) / 255.0
    except Exception:  # noqa: BLE001 - see _font
        return
    h, w = min(glyphs.shape[0], HEADER - 4), min(glyphs.shape[1], img.shape[1] - 6)
    if h <= 0 or w <= 0:
        return
    band = img[4 : 4 + h, 6 : 6 + w].astype(np.float32)
    a = glyphs[:h, :w, None]
    img[4 : 4 + h, 6 : 6 + w] = (band * (1 - a) + 255.0 * a).astype(np.uint8)


class _Replay:
    """The state carried from step to step while frames are drawn."""

    def __init__(self, info: ReplayInfo, con: sqlite3.Connection) -> None:
        self.info = info
        cv = info.canvas
        n = info.n_agents
        self.base = np.full(cv.shape, BACKGROUND, dtype=np.uint8)  # background and trails
        self.colors = _PALETTE[np.arange(n) % len(_PALETTE)]
        self.trail_colors = (self.colors.astype(np.float32) * 0.45 + BACKGROUND * 0.55).astype(np.uint8)
        self.done_colors = (self.colors.astype(np.float32) * 0.3 + BACKGROUND * 0.7).astype(np.uint8)
        self.xy = np.full((n, 2), np.nan)  # last known position (pixels)
        self.heading = np.zeros(n)
        self.online = np.ones(n, dtype=bool)
        self.present = np.zeros(n, dtype=bool)
        self.r = max(info.radius * cv.scale, 3.0)
        key = (info.run, info.episode, info.world)
        col = np.array(con.execute("SELECT step, agent FROM events WHERE run = ? AND episode = ? AND world = ? "
                                   "AND event = 'collision' AND agent >= 0", key).fetchall(),
                       dtype=np.int64).reshape(-1, 2)  # fmt: skip
        self.col_step, self.col_agent = col[:, 0], col[:, 1]
        sen = np.array(con.execute("SELECT release_step, release_x, release_y, land_step, land_x, land_y FROM "
                                   "sensors WHERE run = ? AND episode = ? AND world = ?", key).fetchall(),
                       dtype=float).reshape(-1, 6)  # fmt: skip
        self.rel_step, self.land_step = sen[:, 0], sen[:, 3]
        self.rel_px, self.land_px = cv.px(sen[:, 1], sen[:, 2]), cv.px(sen[:, 4], sen[:, 5])
        self.last_step = info.steps[-1]

    def advance(self, rows: np.ndarray) -> None:
        """Take one step's rows (agent, x, y, heading, online); extend the trails."""
        a = rows[:, 0].astype(np.int64)
        ok = (a >= 0) & (a < len(self.xy))
        a, rows = a[ok], rows[ok]
        cx, cy = self.info.canvas.px(rows[:, 1], rows[:, 2])
        prev = self.xy[a]
        _segments(self.base, (prev[:, 0], prev[:, 1]), (cx, cy), self.trail_colors[a])
        self.xy[a, 0], self.xy[a, 1] = cx, cy
        self.heading[a] = np.nan_to_num(rows[:, 3])
        self.online[a] = np.nan_to_num(rows[:, 4], nan=1.0) != 0
        self.present[:] = False
        self.present[a] = True

    def frame(self, step: int) -> np.ndarray:
        """The frame of ``step`` (after :meth:`advance` with its rows)."""
        img = self.base.copy()
        # sensors: falling (ring at the release point), landed (dot at the landing point)
        rel = self.rel_step <= step
        landed = rel & (self.land_step <= step)
        falling = rel & ~landed
        _discs(img, self.rel_px[0][falling], self.rel_px[1][falling], 3.0, _FALLING, hole=1.6)
        _discs(img, self.land_px[0][landed], self.land_px[1][landed], 2.2, _LANDED)
        seen = np.isfinite(self.xy[:, 0])
        done = seen & ~self.present
        off = self.present & ~self.online
        live = self.present & self.online
        r = self.r
        _discs(img, self.xy[done, 0], self.xy[done, 1], r * 0.8, self.done_colors[done])
        _discs(img, self.xy[off, 0], self.xy[off, 1], r, _OFFLINE)
        _discs(img, self.xy[live, 0], self.xy[live, 1], r, self.colors[live])
        hx, hy = np.cos(self.heading[live]), np.sin(self.heading[live])
        _discs(img, self.xy[live, 0] + hx * r, self.xy[live, 1] - hy * r, max(r / 3, 1.0), _HEADING)
        recent = (self.col_step <= step) & (self.col_step > step - COLLISION_HOLD)
        hit = np.unique(self.col_agent[recent])
        hit = hit[hit < len(self.xy)]
        _discs(img, self.xy[hit, 0], self.xy[hit, 1], r + 3.0, _COLLISION, hole=r + 1.5)
        i = self.info
        n_col = int((self.col_step <= step).sum())
        text = (
            f"run {i.run}  {i.scenario}  episode {i.episode}  world {i.world}  step {step}/{self.last_step}"
        )
        if off.any():
            text += f"  offline {int(off.sum())}"
        if n_col:
            text += f"  collisions {n_col}"
        if len(self.rel_step):
            text += f"  landed {int(landed.sum())}/{int(rel.sum())}"
        _header(img, text)
        return img


def _frames(info: ReplayInfo, every: int) -> Iterator[np.ndarray]:
    wanted = set(info.frame_steps(every))
    con = connect(info.path, create=False)
    try:
        rp = _Replay(info, con)
        for step, rows in _step_rows(con, info):
            rp.advance(rows)
            if step in wanted:
                yield rp.frame(step)
    finally:
        con.close()


def replay_frames(
    path: str | os.PathLike[str],
    run: int | None = None,
    episode: int = 0,
    world: int = 0,
    every: int = 1,
    size: int = 512,
) -> Iterator[np.ndarray]:
    """The frames of a recorded episode, drawn from the store alone (see the module docstring).

    The store and the arguments are checked when this is called; frames are drawn as they are taken, reading the
    store step by step (memory does not grow with the episode).

    Args:
        path: The store.
        run: The run (None: the last one recorded).
        episode: The episode within the run.
        world: The world of a batched run.
        every: Draw every ``every``-th recorded step (step 0 first; the last step is always drawn), >= 1.
        size: Longest side of the map in pixels (frames are :data:`HEADER` pixels taller).

    Returns:
        An iterator of ``(H, W, 3)`` uint8 frames, all of one size: ``len(replay_info(...).frame_steps(every))``
        of them.

    Raises:
        ValueError: See :func:`replay_info`; also ``every`` < 1.
    """
    every = _check_int("every", every, 1)
    return _frames(replay_info(path, run, episode, world, size), every)


def write_replay(
    path: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    run: int | None = None,
    episode: int = 0,
    world: int = 0,
    every: int = 1,
    size: int = 512,
    fps: float | None = None,
) -> list[Path]:
    """Replay a recorded episode to a video file or a folder of PNG frames.

    Args:
        path: The store.
        out: ``*.mp4`` or ``*.gif``: a video (its folder is created); anything else: a folder (created) of
            ``frame_00000.png``, ``frame_00001.png``, ... (frames of an earlier replay there are removed first).
        run, episode, world, every, size: As for :func:`replay_frames`.
        fps: Video frame rate (None: real time, ``1 / (dt * every)`` from the run's config).

    Returns:
        ``[video]``, or the PNG files in order.

    Raises:
        ValueError: See :func:`replay_frames`; also a bad ``fps`` or an ``out`` that cannot be written.
        ImportError: For a video without the ``video`` extra (``pip install "agentsim-env[video]"``).
    """
    from agentsim_env.render.topdown import save_png
    from agentsim_env.render.video import check_video_support, video_format, write_video

    every = _check_int("every", every, 1)
    info = replay_info(path, run, episode, world, size)
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0):
        raise ValueError(f"fps must be a number > 0, got {fps!r}")
    target = Path(out)
    fmt = video_format(target)
    if fmt is not None:
        check_video_support(fmt)
    folder = target.parent if fmt is not None else target
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{str(folder)!r} cannot hold the replay: it is a file")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{str(folder)!r} cannot be created: {exc.strerror or exc}") from None
    frames = _frames(info, every)
    try:
        if fmt is not None:
            return [write_video(frames, target, fps or info.fps(every))]
        for old in target.glob("frame_[0-9][0-9][0-9][0-9][0-9]*.png"):
            old.unlink()
        written = []
        for k, frame in enumerate(frames):
            p = target / f"frame_{k:05d}.png"
            save_png(frame, str(p))
            written.append(p)
        return written
    except OSError as exc:
        raise ValueError(f"{str(target)!r} cannot be written: {exc.strerror or exc}") from None
