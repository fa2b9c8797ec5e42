"""A top-down RGB renderer in plain numpy: obstacles, scenario markers and agents.

Obstacles are grey, darker when taller; the scenario's markers (goals, targets, zones, sensors) lie under the
agents. Each agent is a disc in its own colour (``render.palette``: one per agent up to a dozen, per group beyond)
with a dark rim and a heading dot, never smaller than a few pixels whatever the map's size; its grey shadow is
offset down and right by its altitude (the higher, the farther, up to one radius). Offline agents are faded discs
with a dark cross. No display or pygame is needed, so it works headless and in tests.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.core.scene import BOX
from agentsim_env.render.palette import agent_colors, min_agent_px, min_marker_px
from agentsim_env.sim.world import World

Markers = tuple[np.ndarray, np.ndarray, np.ndarray]  # xy (m,2), rgb (m,3) uint8, radius (m,) metres

BACKGROUND = 236
"""Grey level of the map background."""
_RIM = np.array([30, 30, 40], dtype=np.uint8)
_HEADING = np.array([20, 20, 60], dtype=np.uint8)
_SHADOW = np.array([175, 175, 175], dtype=np.uint8)
_CROSS = np.array([40, 40, 40], dtype=np.uint8)


def _mask(img: np.ndarray, cx: float, cy: float, r: float) -> tuple[tuple[slice, slice], np.ndarray, np.ndarray]:
    """The window around ``(cx, cy)`` of reach ``r`` and its pixel-centre offsets ``(dx, dy)`` from it."""
    h, w, _ = img.shape
    x0, x1 = max(int(cx - r), 0), min(int(cx + r) + 1, w)
    y0, y1 = max(int(cy - r), 0), min(int(cy + r) + 1, h)
    if x0 >= x1 or y0 >= y1:
        return (slice(0, 0), slice(0, 0)), np.zeros((0, 0)), np.zeros((0, 0))
    yy, xx = np.mgrid[y0:y1, x0:x1]
    return (slice(y0, y1), slice(x0, x1)), xx + 0.5 - cx, yy + 0.5 - cy


def _disc(img: np.ndarray, cx: float, cy: float, r: float, color: np.ndarray) -> None:
    win, dx, dy = _mask(img, cx, cy, r)
    img[win][dx**2 + dy**2 <= r * r] = color


_CHUNK = 8192  # discs stamped per numpy pass (bounds the index arrays to a few tens of MB)


def _stamp(img: np.ndarray, cx: np.ndarray, cy: np.ndarray, r: float, colors: np.ndarray, cross: bool = False) -> None:
    """Discs of radius ``r`` pixels (or their diagonals, ``cross``) at ``(cx, cy)``, ``colors`` ``(k, 3)``.

    Every disc is stamped from one pixel mask (its centre snapped to the pixel it falls in), all of them in a few
    numpy passes: a per-disc Python loop costs ~0.1 ms an agent, too much for thousands of agents every frame.
    """
    h, w, _ = img.shape
    reach = int(np.ceil(r))
    dy, dx = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    on = dx**2 + dy**2 <= r * r
    if cross:
        half = max(r / 8.0, 0.75) * 1.42
        on &= (np.abs(dx - dy) <= half) | (np.abs(dx + dy) <= half)
    oy, ox = dy[on], dx[on]
    for k0 in range(0, len(cx), _CHUNK):
        sl = slice(k0, k0 + _CHUNK)
        ok_centre = np.isfinite(cx[sl]) & np.isfinite(cy[sl])
        rows = np.floor(np.where(ok_centre, cy[sl], -1e9)).astype(np.int64)[:, None] + oy[None]
        cols = np.floor(np.where(ok_centre, cx[sl], -1e9)).astype(np.int64)[:, None] + ox[None]
        ok = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
        which = np.broadcast_to(np.arange(rows.shape[0])[:, None], rows.shape)
        img[rows[ok], cols[ok]] = colors[sl][which[ok]]  # overlapping discs: the later one is on top


def _stamp_sized(
    img: np.ndarray, cx: np.ndarray, cy: np.ndarray, r: np.ndarray, colors: np.ndarray, cross: bool = False
) -> None:
    """:func:`_stamp` for discs of several radii (rounded to a quarter pixel; one pass per radius)."""
    q = np.round(np.asarray(r, dtype=float) * 4.0) / 4.0
    for radius in np.unique(q):
        m = q == radius
        _stamp(img, cx[m], cy[m], float(radius), colors[m], cross)


def render_topdown(world: World, w: int = 0, markers: Markers | None = None, size: int = 512) -> np.ndarray:
    """Draw world ``w`` seen from above.

    Args:
        world: The world.
        w: Which world to draw.
        markers: Optional scenario markers (goals, zones, landed sensors) drawn under the agents, each at least
            ``render.palette.min_marker_px(size)`` pixels in radius.
        size: Longest image side in pixels.

    Returns:
        An ``(H, W, 3)`` uint8 image (north up).
    """
    xmin, xmax, ymin, ymax = world.config.bounds
    scale = size / max(xmax - xmin, ymax - ymin)
    width, height = max(1, int((xmax - xmin) * scale)), max(1, int((ymax - ymin) * scale))
    img = np.full((height, width, 3), BACKGROUND, dtype=np.uint8)

    def px(x: float, y: float) -> tuple[float, float]:
        return float((x - xmin) * scale), float((ymax - y) * scale)

    sc = world.scene
    mine = np.flatnonzero(sc.world == w)
    ztop = max(world.config.z_range[1], 1.0)
    for o in mine:
        top = sc.centre[o, 2] + sc.half[o, 2]
        shade = np.uint8(np.clip(170 - 110 * top / ztop, 40, 170))
        color = np.array([shade, shade, shade], dtype=np.uint8)
        cx, cy = px(sc.centre[o, 0], sc.centre[o, 1])
        # an obstacle smaller than a pixel still shows as one
        if sc.kind[o] == BOX:
            hx, hy = max(sc.half[o, 0] * scale, 0.5), max(sc.half[o, 1] * scale, 0.5)
            img[
                max(int(cy - hy), 0) : max(int(np.ceil(cy + hy)), 0),
                max(int(cx - hx), 0) : max(int(np.ceil(cx + hx)), 0),
            ] = color
        else:
            _disc(img, cx, cy, max(sc.half[o, 0] * scale, 0.75), color)
    if markers is not None:
        mxy, mrgb, mr = (np.asarray(a) for a in markers)
        if len(mxy):
            mx, my = (mxy[:, 0] - xmin) * scale, (ymax - mxy[:, 1]) * scale
            mcol = np.asarray(mrgb, dtype=np.uint8).reshape(-1, 3)
            _stamp_sized(img, mx, my, np.maximum(mr.astype(float) * scale, min_marker_px(size)), mcol)
    st = world.state
    slots = st.slots_of_world(w)
    colors = agent_colors(len(slots), st.group[slots])
    faded = (colors.astype(np.float32) * 0.55 + BACKGROUND * 0.45).astype(np.uint8)
    zmin, zmax = world.config.z_range
    cx, cy = (st.pos[slots, 0] - xmin) * scale, (ymax - st.pos[slots, 1]) * scale
    r = np.maximum(st.radius[slots] * scale, min_agent_px(size))
    off = ~np.asarray(st.online[slots], dtype=bool)
    on = ~off
    _stamp_sized(img, cx[off], cy[off], r[off] * 0.8, faded[off])
    _stamp_sized(img, cx[off], cy[off], r[off] * 0.8, np.broadcast_to(_CROSS, (int(off.sum()), 3)), cross=True)
    a = np.clip((st.pos[slots, 2] - zmin) / max(zmax - zmin, 1e-9), 0.0, 1.0)
    shadow = on & (a * r >= 1.0)
    _stamp_sized(
        img,
        cx[shadow] + (a * r)[shadow],
        cy[shadow] + (a * r)[shadow],
        r[shadow],
        np.broadcast_to(_SHADOW, (int(shadow.sum()), 3)),
    )
    n_on = int(on.sum())
    _stamp_sized(img, cx[on], cy[on], r[on], np.broadcast_to(_RIM, (n_on, 3)))
    _stamp_sized(img, cx[on], cy[on], r[on] - np.maximum(1.0, r[on] / 6), colors[on])
    hx, hy = np.cos(st.heading[slots][on]), np.sin(st.heading[slots][on])
    _stamp_sized(
        img,
        cx[on] + hx * r[on] * 0.7,
        cy[on] - hy * r[on] * 0.7,
        np.maximum(r[on] / 3, 1.0),
        np.broadcast_to(_HEADING, (n_on, 3)),
    )
    return img


def save_png(img: np.ndarray, path: str) -> None:
    """Write an RGB array to a PNG file (matplotlib's writer, no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    plt.imsave(path, img)
