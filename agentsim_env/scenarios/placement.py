"""Vectorised, seeded placement of agents, goals and obstacles for large maps.

Points are drawn on a jittered grid (one per cell, cells chosen without replacement), which guarantees a
minimum separation without rejection loops, so resets stay cheap at 10,000 agents.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def _cells(n: int, w: float, h: float, min_sep: float) -> tuple[float, int, int]:
    """Cell side and counts of the jittered grid for ``n`` points in a ``w x h`` area (deterministic)."""
    if w <= 0 or h <= 0:
        return max(min_sep, 1.0), 0, 0
    cell = max(float(np.sqrt(w * h / (1.3 * max(n, 1)))), min_sep)  # ~30 % spare cells: the choice stays random
    nx, ny = int(w // cell), int(h // cell)
    while nx * ny < 1.3 * n and cell * 0.95 >= min_sep:  # integer rounding lost cells: shrink them
        cell *= 0.95
        nx, ny = int(w // cell), int(h // cell)
    return cell, nx, ny


def placement_problem(n: int, bounds: tuple[float, float, float, float], min_sep: float) -> str:
    """Why ``n`` points at least ``min_sep`` apart cannot be placed in ``bounds`` ("" when they can).

    The answer depends only on the arguments (never on the random draw), so configs call it at construction:
    a config that passes never fails to place its agents at reset.
    """
    w, h = bounds[1] - bounds[0], bounds[3] - bounds[2]
    _, nx, ny = _cells(n, w, h, min_sep)
    if nx * ny >= n:
        return ""
    return f"cannot place {n} points at least {min_sep:g} m apart in a {max(w, 0):.0f} x {max(h, 0):.0f} m area"


def jittered_points(
    rng: np.random.Generator, n: int, bounds: tuple[float, float, float, float], min_sep: float
) -> np.ndarray:
    """``n`` points in ``bounds``, pairwise at least ``min_sep`` apart.

    Args:
        rng: Random generator.
        n: Number of points.
        bounds: ``(xmin, xmax, ymin, ymax)``.
        min_sep: Minimum distance between any two points.

    Returns:
        Points ``(n, 2)``.

    Raises:
        ValueError: When the area cannot hold ``n`` points that far apart.
    """
    xmin, xmax, ymin, ymax = bounds
    w, h = xmax - xmin, ymax - ymin
    problem = placement_problem(n, bounds, min_sep)
    if problem:
        raise ValueError(problem)
    cell, nx, ny = _cells(n, w, h, min_sep)
    cells = rng.choice(nx * ny, size=n, replace=False)
    cx, cy = cells % nx, cells // nx
    slack = max(cell - min_sep, 0.0)  # jitter that still keeps neighbours min_sep apart
    jx = rng.uniform(0, slack, n) + (cell - slack) / 2.0
    jy = rng.uniform(0, slack, n) + (cell - slack) / 2.0
    ox = xmin + (w - nx * cell) / 2.0
    oy = ymin + (h - ny * cell) / 2.0
    return np.column_stack([ox + cx * cell + jx, oy + cy * cell + jy])


def obstacle_layout(
    rng: np.random.Generator,
    n: int,
    bounds: tuple[float, float, float, float],
    size_range: tuple[float, float],
    height_range: tuple[float, float],
    keep_clear: np.ndarray,
    keep_clear_radius: float,
    clearance: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Non-overlapping ground obstacles (boxes and cylinders) that keep clear of given points.

    Each obstacle gets its own grid cell (so obstacles never overlap); those too close to a keep-clear point
    are dropped, and a map too small for ``n`` holds fewer (halving until they fit, possibly none), so fewer than
    ``n`` may be returned.

    Returns:
        ``(kind (m,) int8, centre (m, 3), half (m, 3))`` ready for ``Scene.add``.
    """
    if n <= 0:
        return np.zeros(0, dtype=np.int8), np.zeros((0, 3)), np.zeros((0, 3))
    xmin, xmax, ymin, ymax = bounds
    smax = size_range[1]
    sep = 2.0 * smax * np.sqrt(2.0) + clearance
    inner = (xmin + smax * 1.5, xmax - smax * 1.5, ymin + smax * 1.5, ymax - smax * 1.5)
    while n > 0 and placement_problem(n, inner, sep):  # a crowded map holds fewer obstacles, never an error
        n //= 2
    if n <= 0:
        return np.zeros(0, dtype=np.int8), np.zeros((0, 3)), np.zeros((0, 3))
    xy = jittered_points(rng, n, inner, sep)
    kind = rng.integers(0, 2, n).astype(np.int8)  # 0 box, 1 cylinder
    hs = rng.uniform(size_range[0], size_range[1], n)
    hh = rng.uniform(height_range[0], height_range[1], n) / 2.0
    foot = np.where(kind == 0, hs * np.sqrt(2.0), hs)
    if keep_clear.shape[0]:
        d, _ = cKDTree(keep_clear[:, :2]).query(xy, k=1)
        ok = d > foot + keep_clear_radius
    else:
        ok = np.ones(n, dtype=bool)
    centre = np.column_stack([xy, hh])[ok]
    half = np.column_stack([hs, hs, hh])[ok]
    return kind[ok], centre, half
