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


def _cross(img: np.ndarray, cx: float, cy: float, r: float, color: np.ndarray) -> None:
    """Both diagonals of the disc of radius ``r``, ``r / 4`` (at least 1 pixel) thick."""
    win, dx, dy = _mask(img, cx, cy, r)
    half = max(r / 8.0, 0.75)
    on = ((np.abs(dx - dy) <= half * 1.42) | (np.abs(dx + dy) <= half * 1.42)) & (dx**2 + dy**2 <= r * r)
    img[win][on] = color


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
            img[max(int(cy - hy), 0) : max(int(np.ceil(cy + hy)), 0),
                max(int(cx - hx), 0) : max(int(np.ceil(cx + hx)), 0)] = color  # fmt: skip
        else:
            _disc(img, cx, cy, max(sc.half[o, 0] * scale, 0.75), color)
    if markers is not None:
        mxy, mrgb, mr = markers
        floor = min_marker_px(size)
        for (x, y), c, r in zip(mxy, mrgb, mr):
            cx, cy = px(x, y)
            _disc(img, cx, cy, max(r * scale, floor), np.asarray(c, dtype=np.uint8))
    st = world.state
    slots = st.slots_of_world(w)
    colors = agent_colors(len(slots), st.group[slots])
    faded = (colors.astype(np.float32) * 0.55 + BACKGROUND * 0.45).astype(np.uint8)
    zmin, zmax = world.config.z_range
    floor = min_agent_px(size)
    for k, s in enumerate(slots):
        cx, cy = px(st.pos[s, 0], st.pos[s, 1])
        r = max(st.radius[s] * scale, floor)
        if not st.online[s]:
            _disc(img, cx, cy, r * 0.8, faded[k])
            _cross(img, cx, cy, r * 0.8, _CROSS)
            continue
        a = float(np.clip((st.pos[s, 2] - zmin) / max(zmax - zmin, 1e-9), 0.0, 1.0))
        if a * r >= 1.0:
            _disc(img, cx + a * r, cy + a * r, r, _SHADOW)
        _disc(img, cx, cy, r, _RIM)
        _disc(img, cx, cy, r - max(1.0, r / 6), colors[k])
        hx, hy = np.cos(st.heading[s]), np.sin(st.heading[s])
        _disc(img, cx + hx * r * 0.7, cy - hy * r * 0.7, max(r / 3, 1.0), _HEADING)
    return img


def save_png(img: np.ndarray, path: str) -> None:
    """Write an RGB array to a PNG file (matplotlib's writer, no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    plt.imsave(path, img)
