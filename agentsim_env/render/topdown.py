"""A top-down RGB renderer in plain numpy: obstacles, agents shaded by altitude, and scenario markers.

Lighter agents fly higher; obstacles are grey, darker when taller. Offline agents are drawn as dark crosses.
No display or pygame is needed, so it works headless and in tests.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.core.scene import BOX
from agentsim_env.sim.world import World

Markers = tuple[np.ndarray, np.ndarray, np.ndarray]  # xy (m,2), rgb (m,3) uint8, radius (m,) metres


def _disc(img: np.ndarray, cx: float, cy: float, r: float, color: np.ndarray) -> None:
    h, w, _ = img.shape
    x0, x1 = max(int(cx - r), 0), min(int(cx + r) + 1, w)
    y0, y1 = max(int(cy - r), 0), min(int(cy + r) + 1, h)
    if x0 >= x1 or y0 >= y1:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    m = (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 <= r * r
    img[y0:y1, x0:x1][m] = color


def render_topdown(world: World, w: int = 0, markers: Markers | None = None, size: int = 512) -> np.ndarray:
    """Draw world ``w`` seen from above.

    Args:
        world: The world.
        w: Which world to draw.
        markers: Optional scenario markers (goals, zones, landed sensors) drawn under the agents.
        size: Longest image side in pixels.

    Returns:
        An ``(H, W, 3)`` uint8 image (north up).
    """
    xmin, xmax, ymin, ymax = world.config.bounds
    scale = size / max(xmax - xmin, ymax - ymin)
    width, height = max(1, int((xmax - xmin) * scale)), max(1, int((ymax - ymin) * scale))
    img = np.full((height, width, 3), 236, dtype=np.uint8)

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
        if sc.kind[o] == BOX:
            hx, hy = sc.half[o, 0] * scale, sc.half[o, 1] * scale
            img[max(int(cy - hy), 0) : max(int(cy + hy), 0), max(int(cx - hx), 0) : max(int(cx + hx), 0)] = (
                color
            )
        else:
            _disc(img, cx, cy, sc.half[o, 0] * scale, color)
    if markers is not None:
        mxy, mrgb, mr = markers
        for (x, y), c, r in zip(mxy, mrgb, mr):
            cx, cy = px(x, y)
            _disc(img, cx, cy, max(r * scale, 1.5), np.asarray(c, dtype=np.uint8))
    st = world.state
    slots = st.slots_of_world(w)
    zmin, zmax = world.config.z_range
    for s in slots:
        cx, cy = px(st.pos[s, 0], st.pos[s, 1])
        r = max(st.radius[s] * scale, 3.0)
        if not st.online[s]:
            _disc(img, cx, cy, r * 0.6, np.array([90, 30, 30], dtype=np.uint8))
            continue
        a = float(np.clip((st.pos[s, 2] - zmin) / max(zmax - zmin, 1e-9), 0.0, 1.0))
        color = np.array([30 + 120 * a, 80 + 140 * a, 200 + 55 * a], dtype=np.uint8)
        _disc(img, cx, cy, r, color)
        hx, hy = np.cos(st.heading[s]), np.sin(st.heading[s])
        _disc(img, cx + hx * r, cy - hy * r, max(r / 3, 1.0), np.array([20, 20, 60], dtype=np.uint8))
    return img


def save_png(img: np.ndarray, path: str) -> None:
    """Write an RGB array to a PNG file (matplotlib's writer, no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    plt.imsave(path, img)
