"""Replay a recorded episode from the store alone: RGB frames, a folder of PNGs, or an MP4 / GIF video.

Nothing is simulated again. Each frame is drawn with numpy from the ``steps`` rows of one step of one episode of
one world: every agent at its recorded position (a disc in its own colour, one per agent up to a dozen and per
group beyond: ``render.palette``, at least a few pixels wide, with a dark rim and a heading dot), the trail it has
flown, agents that went offline in grey, agents already done (no row any more) faded at their last position,
collisions from the ``events`` table as red rings for :data:`COLLISION_HOLD` steps, and for ``uav_release`` the
sensors of the ``sensors`` table (released and falling: an orange ring at the release point; landed: a green
dot). Under them lie the obstacles (grey, darker when taller) and the scenario's markers as they were after the
reset (goals, targets, zones), which are not stored but rebuilt from the run's config and the episode's seed
(``replay_scene``; not for batched runs or episodes without a recorded seed). A header line names the run,
scenario, episode, world and step.

The map extent comes from the run's scenario and config, widened to every recorded position, and the store is
checked before anything is drawn (``replay_load``). Every frame of a replay has one size.
"""

from __future__ import annotations

import functools
import os
import sqlite3
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.core.budget import check_memory
from agentsim_env.recorder.checks import open_read
from agentsim_env.recorder.replay_load import HEADER, Canvas, ReplayInfo, _check_int, replay_info
from agentsim_env.recorder.replay_scene import StaticScene, static_scene
from agentsim_env.render.palette import PALETTE, agent_colors, min_agent_px, min_marker_px

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

BACKGROUND = 236
"""Grey level of the map background."""
COLLISION_HOLD = 10
"""Steps a collision ring stays around an agent."""
_OFFLINE = np.array([150, 150, 150], dtype=np.uint8)
_HEADING = np.array([20, 20, 60], dtype=np.uint8)
_RIM = np.array([30, 30, 40], dtype=np.uint8)
_COLLISION = np.array([220, 20, 20], dtype=np.uint8)
_FALLING = np.array([240, 150, 20], dtype=np.uint8)
_LANDED = np.array([20, 130, 40], dtype=np.uint8)
_HEADER_BG = np.array([40, 44, 52], dtype=np.uint8)
_FETCH = 20_000  # steps rows read per batch


def agent_color(agent: int, n_agents: int = 1, group: int = 0) -> np.ndarray:
    """The RGB colour (uint8) of agent ``agent`` (its index within the world) in replay frames.

    Args:
        agent: The agent's index within its world.
        n_agents: Agents per world: beyond ``render.palette.MAX_DISTINCT`` the colour is the group's.
        group: The agent's group at its first recorded step (used only then).
    """
    if n_agents > len(PALETTE):
        return PALETTE[max(group, 0) % len(PALETTE)].copy()
    return PALETTE[agent % len(PALETTE)].copy()


def _check_frame_memory(info: ReplayInfo) -> None:
    """The drawing's memory fits the limit (``core.budget``): per-agent state and a few frames' worth of pixels."""
    h, w, _ = info.canvas.shape
    check_memory(
        f"{info.path}: the replay of run {info.run} episode {info.episode} (runs.n_agents={info.n_agents}, "
        f"{w} x {h} pixels)",
        128 * info.n_agents + 4 * h * w * 3 + 64 * _FETCH * 6,
        "lower --size, or the store's runs.n_agents is damaged",
    )


def _step_rows(con: sqlite3.Connection, info: ReplayInfo) -> Iterator[tuple[int, np.ndarray]]:
    """``(step, rows)`` per recorded step, ``rows`` an ``(k, 5)`` array of agent, x, y, heading, online."""
    cur = con.execute(
        "SELECT step, agent, x, y, heading, online FROM steps WHERE run = ? AND episode = ? AND world = ? "
        "ORDER BY step",
        (info.run, info.episode, info.world),
    )
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
def _discs(img: np.ndarray, cx: np.ndarray, cy: np.ndarray, r: float, colors: np.ndarray, hole: float = 0.0) -> None:
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


def _segments(
    img: np.ndarray, p0: tuple[np.ndarray, np.ndarray], p1: tuple[np.ndarray, np.ndarray], colors: np.ndarray
) -> None:
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


def _draw_scene(img: np.ndarray, scene: StaticScene, cv: Canvas) -> None:
    """Obstacles (grey, darker when taller; at least a pixel) and markers (at least a few pixels) into ``img``."""
    s = cv.scale
    shade = np.clip(170 - 110 * scene.top / max(scene.z_top, 1.0), 40, 170).astype(np.uint8)
    cx, cy = cv.px(scene.centre[:, 0], scene.centre[:, 1])
    h, w, _ = img.shape
    for k in np.flatnonzero(scene.box):
        hx, hy = max(scene.half[k, 0] * s, 0.5), max(scene.half[k, 1] * s, 0.5)
        r0, r1 = max(int(cy[k] - hy), HEADER), min(int(np.ceil(cy[k] + hy)), h)
        c0, c1 = max(int(cx[k] - hx), 0), min(int(np.ceil(cx[k] + hx)), w)
        if r0 < r1 and c0 < c1:
            img[r0:r1, c0:c1] = shade[k]
    for k in np.flatnonzero(~scene.box):
        _discs(img, cx[k : k + 1], cy[k : k + 1], max(scene.half[k, 0] * s, 0.75), np.repeat(shade[k], 3))
    if scene.markers is not None:
        mxy, rgb, rad = scene.markers
        mx, my = cv.px(np.asarray(mxy)[:, 0], np.asarray(mxy)[:, 1])
        floor = min_marker_px(cv.size)
        for m in range(len(mx)):
            _discs(img, mx[m : m + 1], my[m : m + 1], max(float(rad[m]) * s, floor), np.asarray(rgb[m], np.uint8))


def _first_groups(con: sqlite3.Connection, info: ReplayInfo) -> np.ndarray:
    """Each agent's group at its first recorded step (-1 when not recorded)."""
    groups = np.full(info.n_agents, -1, dtype=np.int64)
    rows = con.execute(
        "SELECT agent, grp FROM steps WHERE run = ? AND episode = ? AND world = ? AND step = ? AND grp IS NOT NULL",
        (info.run, info.episode, info.world, info.steps[0]),
    ).fetchall()
    for a, g in rows:
        if isinstance(a, int) and isinstance(g, int) and 0 <= a < info.n_agents:
            groups[a] = g
    return groups


class _Replay:
    """The state carried from step to step while frames are drawn."""

    def __init__(self, info: ReplayInfo, con: sqlite3.Connection, scene: StaticScene | None) -> None:
        self.info = info
        cv = info.canvas
        n = info.n_agents
        self.base = np.full(cv.shape, BACKGROUND, dtype=np.uint8)  # background, the static scene and trails
        if scene is not None:
            _draw_scene(self.base, scene, cv)
        self.colors = agent_colors(n, _first_groups(con, info) if n > len(PALETTE) else None)
        self.trail_colors = (self.colors.astype(np.float32) * 0.45 + BACKGROUND * 0.55).astype(np.uint8)
        self.done_colors = (self.colors.astype(np.float32) * 0.5 + BACKGROUND * 0.5).astype(np.uint8)
        self.xy = np.full((n, 2), np.nan)  # last known position (pixels)
        self.heading = np.zeros(n)
        self.online = np.ones(n, dtype=bool)
        self.present = np.zeros(n, dtype=bool)
        self.r = max(info.radius * cv.scale, min_agent_px(cv.size))
        key = (info.run, info.episode, info.world)
        col = np.array(
            con.execute(
                "SELECT step, agent FROM events WHERE run = ? AND episode = ? AND world = ? "
                "AND event = 'collision' AND agent >= 0",
                key,
            ).fetchall(),
            dtype=np.int64,
        ).reshape(-1, 2)
        self.col_step, self.col_agent = col[:, 0], col[:, 1]
        sen = np.array(
            con.execute(
                "SELECT release_step, release_x, release_y, land_step, land_x, land_y FROM "
                "sensors WHERE run = ? AND episode = ? AND world = ?",
                key,
            ).fetchall(),
            dtype=float,
        ).reshape(-1, 6)
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
        _discs(img, self.xy[live, 0], self.xy[live, 1], r, _RIM)
        _discs(img, self.xy[live, 0], self.xy[live, 1], r - max(1.0, r / 6), self.colors[live])
        hx, hy = np.cos(self.heading[live]), np.sin(self.heading[live])
        _discs(img, self.xy[live, 0] + hx * r * 0.7, self.xy[live, 1] - hy * r * 0.7, max(r / 3, 1.0), _HEADING)
        recent = (self.col_step <= step) & (self.col_step > step - COLLISION_HOLD)
        hit = np.unique(self.col_agent[recent])
        hit = hit[hit < len(self.xy)]
        _discs(img, self.xy[hit, 0], self.xy[hit, 1], r + 3.0, _COLLISION, hole=r + 1.5)
        i = self.info
        n_col = int((self.col_step <= step).sum())
        text = f"run {i.run}  {i.scenario}  episode {i.episode}  world {i.world}  step {step}/{self.last_step}"
        if off.any():
            text += f"  offline {int(off.sum())}"
        if n_col:
            text += f"  collisions {n_col}"
        if len(self.rel_step):
            text += f"  landed {int(landed.sum())}/{int(rel.sum())}"
        _header(img, text)
        return img


def _frames(info: ReplayInfo, every: int, scene: StaticScene | None) -> Iterator[np.ndarray]:
    wanted = set(info.frame_steps(every))
    con = open_read(info.path)
    try:
        rp = _Replay(info, con, scene)
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
        StoreError: Also an ``episodes.seed`` of the world that is not an integer (``replay_scene``).
    """
    every = _check_int("every", every, 1)
    info = replay_info(path, run, episode, world, size)
    _check_frame_memory(info)
    scene, _ = static_scene(info)
    return _frames(info, every, scene)


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
    _check_frame_memory(info)
    scene, _ = static_scene(info)
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
    frames = _frames(info, every, scene)
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
