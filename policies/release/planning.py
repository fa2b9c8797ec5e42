"""Shared geometry for sensor-release plans: tours, angular sectors and release-point compensation.

Everything here is offline planning (run once per UAV and zone), so it favours exactness over speed,
but the O(n^2) parts (nearest-neighbour tour, 2-opt) are numba kernels so that a few thousand targets
plan in well under a second.

Compensation model (domain reference 3.1). A UAV flying a polyline of waypoints at constant speed
arrives at each release point heading along its incoming leg, and the released node inherits that
velocity. Over flat ground the landing offset ("throw", including wind drift) depends only on the
release velocity, so for a heading ``psi`` the release point is ``p = target - throw(psi)``. The
heading itself must point from the previous waypoint to ``p``; this is solved target by target in
visiting order. Where no straight arrival exists (the target lies inside the throw circle of the
previous release point) a lead-in waypoint is inserted so that the UAV approaches along the pattern's
local direction.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "MODES",
    "ReleasePlan",
    "assemble_plan",
    "in_sector",
    "normalise_sector",
    "path_length",
    "plan_tour",
    "sector_quota",
    "split_sectors",
    "throw_table",
]

TWO_PI = 2.0 * math.pi
MODES: tuple[str, ...] = ("waypoints", "hover", "teleport")
# Headings at which the throw is tabulated; the throw varies smoothly with heading, so linear
# interpolation at 0.5 degree steps is far below a centimetre and the final exact correction removes it.
_N_HEADINGS = 720


@dataclass(frozen=True, eq=False)  # array fields: identity equality
class ReleasePlan:
    """What one UAV does over one zone (or one sector of it).

    Attributes:
        strategy: Strategy name (a registered name, ``registry.strategy_names()``).
        mode: ``"waypoints"`` (fly through each release point, release within tolerance), ``"hover"``
            (stop at each waypoint and release the sensors assigned to it) or ``"teleport"`` (oracle
            placement, no flight).
        centre: Zone centre ``(2,)``.
        radius: Zone radius in metres.
        sector: ``(theta0, theta1)`` of the wedge this plan covers, or ``None`` for the whole disc.
        start_xy: Where the UAV is assumed to start ``(2,)`` (first leg of ``path_length``).
        altitude: Flight and release height above flat ground, metres.
        waypoints: ``(m, 3)`` points to fly in order (release points and lead-in points).
        release_wp: ``(n,)`` waypoint index at which each release happens (``-1`` for teleport).
        release_xy: ``(n, 2)`` intended landing targets in release order.
        release_points: ``(n, 3)`` where to release (compensated); for teleport the targets at ``z = 0``.
        release_vel: ``(n, 3)`` UAV velocity at each release, assumed by the compensation.
        release_speed: UAV speed at release (0 for hover and teleport).
        path_length: Length of the polyline ``start_xy -> waypoints`` in metres (horizontal).
        n_lead_in: Number of inserted lead-in waypoints.
        residual: Largest predicted landing error of the compensated plan, metres (0 without a model).
        info: Strategy statistics (e.g. ``n_rings`` for B2, ``drop_counts`` for B6).
    """

    strategy: str
    mode: str
    centre: NDArray[np.float64]
    radius: float
    sector: tuple[float, float] | None
    start_xy: NDArray[np.float64]
    altitude: float
    waypoints: NDArray[np.float64]
    release_wp: NDArray[np.int64]
    release_xy: NDArray[np.float64]
    release_points: NDArray[np.float64]
    release_vel: NDArray[np.float64]
    release_speed: float
    path_length: float
    n_lead_in: int = 0
    residual: float = 0.0
    info: dict = field(default_factory=dict)

    @property
    def n_releases(self) -> int:
        """Number of sensors this plan releases."""
        return int(self.release_xy.shape[0])


# ---------------------------------------------------------------------------------------- tours
@njit(cache=True)
def _nn_order(pts: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Greedy nearest-neighbour visiting order from ``start``; ties go to the lowest index."""
    n = pts.shape[0]
    order = np.empty(n, dtype=np.int64)
    used = np.zeros(n, dtype=np.bool_)
    cx, cy = start[0], start[1]
    for k in range(n):
        best, best_d = -1, np.inf
        for j in range(n):
            if not used[j]:
                d = (pts[j, 0] - cx) ** 2 + (pts[j, 1] - cy) ** 2
                if d < best_d:
                    best_d, best = d, j
        order[k] = best
        used[best] = True
        cx, cy = pts[best, 0], pts[best, 1]
    return order


@njit(cache=True)
def _dist(p: np.ndarray, a: int, b: int) -> float:
    return math.sqrt((p[a, 0] - p[b, 0]) ** 2 + (p[a, 1] - p[b, 1]) ** 2)


@njit(cache=True)
def _two_opt_open(path: np.ndarray, max_passes: int) -> np.ndarray:
    """2-opt on an open path whose first row is a fixed start and whose end is free.

    A move reverses ``path[i..j]`` (``1 <= i < j``); with ``j`` last, only the edge into ``i`` changes.
    First-improvement sweeps in index order until a full pass finds nothing (deterministic).
    """
    m = path.shape[0]
    idx = np.arange(m)
    for _ in range(max_passes):
        improved = False
        for i in range(1, m - 1):
            a, b = idx[i - 1], idx[i]
            dab = _dist(path, a, b)
            for j in range(i + 1, m):
                c = idx[j]
                if j == m - 1:
                    delta = _dist(path, a, c) - dab
                else:
                    d = idx[j + 1]
                    delta = _dist(path, a, c) + _dist(path, b, d) - dab - _dist(path, c, d)
                if delta < -1e-9:
                    idx[i : j + 1] = idx[i : j + 1][::-1].copy()
                    improved = True
                    b = idx[i]
                    dab = _dist(path, a, b)
        if not improved:
            break
    return idx


def plan_tour(points: ArrayLike, start_xy: ArrayLike, two_opt: bool = True, max_passes: int = 200) -> NDArray:
    """Visiting order of ``points`` for an open route from ``start_xy``: nearest neighbour, then 2-opt.

    Args:
        points: ``(n, 2)`` targets.
        start_xy: ``(2,)`` start position (fixed first node; the route ends anywhere).
        two_opt: Improve the nearest-neighbour order with 2-opt (never lengthens it).
        max_passes: Cap on 2-opt sweeps.

    Returns:
        ``(n,)`` int64 permutation of ``range(n)``.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    start = np.ascontiguousarray(start_xy, dtype=np.float64).reshape(2)
    if pts.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    order = _nn_order(pts, start)
    if not two_opt or pts.shape[0] < 3:
        return order
    path = np.vstack([start[None, :], pts[order]])
    idx = _two_opt_open(path, int(max_passes))
    return order[idx[1:] - 1]


def path_length(points: ArrayLike, start_xy: ArrayLike | None = None) -> float:
    """Horizontal length of the polyline through ``points`` (from ``start_xy`` when given).

    Args:
        points: ``(n, 2)`` or ``(n, 3)`` vertices in order (only x, y are used).
        start_xy: Optional ``(2,)`` first vertex.

    Returns:
        Length in metres.
    """
    p = np.asarray(points, dtype=np.float64)
    p = p.reshape(-1, p.shape[-1])[:, :2] if p.size else np.zeros((0, 2))
    if start_xy is not None:
        p = np.vstack([np.asarray(start_xy, dtype=np.float64).reshape(1, 2), p])
    if p.shape[0] < 2:
        return 0.0
    return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))


# ---------------------------------------------------------------------------------------- sectors
def normalise_sector(sector: tuple[float, float] | None) -> tuple[float, float]:
    """``(theta0 mod 2 pi, width)`` of a sector; ``None`` is the full circle ``(0, 2 pi)``.

    Raises:
        ValueError: If the angles are not finite or the width ``theta1 - theta0`` is not in (0, 2 pi].
    """
    if sector is None:
        return 0.0, TWO_PI
    try:
        t0, t1 = (float(v) for v in sector)
    except (TypeError, ValueError):
        raise ValueError(f"sector must be None or a pair (theta0, theta1), got {sector!r}") from None
    width = t1 - t0
    if not (math.isfinite(t0) and math.isfinite(t1) and 0.0 < width <= TWO_PI + 1e-12):
        raise ValueError(f"sector must satisfy 0 < theta1 - theta0 <= 2 pi, got {sector!r}")
    return t0 % TWO_PI, min(width, TWO_PI)


def in_sector(offsets: ArrayLike, sector: tuple[float, float] | None) -> NDArray[np.bool_]:
    """Which offsets (from the zone centre) lie in the half-open wedge ``[theta0, theta1)``.

    Args:
        offsets: ``(n, 2)`` positions relative to the zone centre.
        sector: ``(theta0, theta1)`` or ``None`` (everything).

    Returns:
        ``(n,)`` boolean mask.
    """
    off = np.asarray(offsets, dtype=np.float64).reshape(-1, 2)
    t0, width = normalise_sector(sector)
    if width >= TWO_PI:
        return np.ones(off.shape[0], dtype=bool)
    rel = np.mod(np.arctan2(off[:, 1], off[:, 0]) - t0, TWO_PI)
    return rel < width


def sector_quota(n: int, sector: tuple[float, float] | None) -> int:
    """Sensors of a zone total ``n`` that belong to a wedge, proportional to its mass (its angle).

    Cumulative rounding ``round(n F(theta1)) - round(n F(theta0))`` with ``F = theta / 2 pi``, so the
    quotas of contiguous sectors covering the circle (``split_sectors``) add up to ``n`` exactly.
    """
    t0, width = normalise_sector(sector)
    f0, f1 = t0 / TWO_PI, (t0 + width) / TWO_PI
    return int(math.floor(n * f1 + 0.5) - math.floor(n * f0 + 0.5))


def split_sectors(n_uavs: int, capacities: ArrayLike | None = None, theta0: float = 0.0) -> list[tuple[float, float]]:
    """Contiguous wedges covering the circle, angle proportional to each UAV's capacity (domain 5.3).

    Args:
        n_uavs: Number of UAVs (>= 1).
        capacities: ``(n_uavs,)`` payload capacities (> 0); ``None`` means equal.
        theta0: Angle where the first wedge starts (radians).

    Returns:
        ``[(theta0_j, theta1_j)]`` with ``theta1_j == theta0_{j+1}`` and the last ending at
        ``theta0 + 2 pi`` exactly. Radially symmetric profiles give every wedge the mass share of its
        angle.
    """
    if isinstance(n_uavs, bool) or not isinstance(n_uavs, (int, np.integer)) or n_uavs < 1:
        raise ValueError(f"n_uavs must be an integer >= 1, got {n_uavs!r}")
    cap = np.ones(n_uavs) if capacities is None else np.asarray(capacities, dtype=np.float64).reshape(-1)
    if cap.shape[0] != n_uavs or not np.all(np.isfinite(cap)) or np.any(cap <= 0):
        raise ValueError(f"capacities must be {n_uavs} finite numbers > 0, got {capacities!r}")
    edges = theta0 + TWO_PI * np.concatenate([[0.0], np.cumsum(cap) / cap.sum()])
    edges[-1] = theta0 + TWO_PI  # exact closure despite rounding in the cumulative sum
    return [(float(edges[j]), float(edges[j + 1])) for j in range(n_uavs)]


# ---------------------------------------------------------------------------------------- compensation
def _predict(fall, p0: NDArray, v0: NDArray, wind, dt: float) -> NDArray:
    """Landing points from the ballistic model (imported lazily: payloads is optional here)."""
    from agentsim_env.payloads.ballistic import predict_landing

    xy, _ = predict_landing(p0, v0, fall, wind, dt)
    return xy


def throw_table(altitude: float, speed: float, fall, wind, dt: float, k: int = _N_HEADINGS) -> NDArray:
    """Landing offset (throw + drift) ``(k, 2)`` for headings ``2 pi i / k`` at ``speed``.

    Args:
        altitude: Release height (> 0).
        speed: Horizontal UAV speed (>= 0).
        fall: ``FallParams`` or ``None`` (no model: all zeros).
        wind: Mean wind ``(2,)``, a callable ``z -> (n, 3)``, or ``None``.
        dt: Integration step for ``predict_landing``.
        k: Number of headings.

    Returns:
        ``(k, 2)`` offsets from release point to landing point.
    """
    if fall is None:
        return np.zeros((k, 2))
    psi = TWO_PI * np.arange(k) / k
    p0 = np.zeros((k, 3))
    p0[:, 2] = altitude
    v0 = np.zeros((k, 3))
    v0[:, 0], v0[:, 1] = speed * np.cos(psi), speed * np.sin(psi)
    return _predict(fall, p0, v0, wind, dt)


@njit(cache=True)
def _throw_at(table: np.ndarray, psi: float) -> tuple[float, float]:
    k = table.shape[0]
    f = (psi % (2.0 * math.pi)) / (2.0 * math.pi) * k
    i0 = int(math.floor(f)) % k
    w = f - math.floor(f)
    i1 = (i0 + 1) % k
    return (1 - w) * table[i0, 0] + w * table[i1, 0], (1 - w) * table[i0, 1] + w * table[i1, 1]


@njit(cache=True)
def _cross_dot(table, psi, tx, ty, px, py):
    """Cross and dot of the heading ``e_psi`` with ``target - throw(psi) - previous``."""
    ox, oy = _throw_at(table, psi)
    ax, ay = tx - ox - px, ty - oy - py
    c, s = math.cos(psi), math.sin(psi)
    return c * ay - s * ax, c * ax + s * ay


@njit(cache=True)
def _solve_headings(tgt, start, table, min_leg, lead_in):
    """Release point and arrival heading for each target in order (see module docstring).

    The heading solves ``cross(e_psi, target - throw(psi) - previous) = 0`` with a positive leg of at
    least ``min_leg``: every sign change over the tabulated headings is bracketed and bisected, and the
    root nearest the pattern's local direction wins (without wind there is exactly one valid root).
    Plain fixed-point iteration is not used because it only contracts when the leg exceeds the throw.

    Returns ``(release (n,2), heading (n,), lead (n,) bool, lead_pts (n,2))``.
    """
    n = tgt.shape[0]
    k = table.shape[0]
    step = 2.0 * math.pi / k
    rel = np.empty((n, 2))
    head = np.empty(n)
    lead = np.zeros(n, dtype=np.bool_)
    lead_pts = np.zeros((n, 2))
    cr = np.empty(k + 1)
    px, py = start[0], start[1]
    qx, qy = start[0], start[1]  # previous target: the pattern direction
    psi_prev = 0.0
    for i in range(n):
        tx, ty = tgt[i, 0], tgt[i, 1]
        dx, dy = tx - qx, ty - qy
        pat = math.atan2(dy, dx) if dx * dx + dy * dy > 1e-24 else psi_prev
        for j in range(k):
            cr[j] = _cross_dot(table, j * step, tx, ty, px, py)[0]
        cr[k] = cr[0]
        best, best_score = pat, np.inf
        for j in range(k):
            if cr[j] != 0.0 and cr[j] * cr[j + 1] > 0.0:
                continue
            lo, hi, clo = j * step, (j + 1) * step, cr[j]
            if clo != 0.0:
                for _ in range(50):
                    mid = 0.5 * (lo + hi)
                    cm = _cross_dot(table, mid, tx, ty, px, py)[0]
                    if cm * clo > 0.0:
                        lo, clo = mid, cm
                    else:
                        hi = mid
            root = 0.5 * (lo + hi) if clo != 0.0 else lo
            if _cross_dot(table, root, tx, ty, px, py)[1] < min_leg:
                continue
            score = abs((root - pat + math.pi) % (2.0 * math.pi) - math.pi)
            if score < best_score:
                best, best_score = root, score
        psi = best
        ox, oy = _throw_at(table, psi)
        rx, ry = tx - ox, ty - oy
        if best_score == np.inf:
            # No straight arrival: approach along the pattern's own direction from a lead-in point.
            lead[i] = True
            lead_pts[i, 0] = rx - lead_in * math.cos(psi)
            lead_pts[i, 1] = ry - lead_in * math.sin(psi)
        rel[i, 0], rel[i, 1] = rx, ry
        head[i] = psi
        psi_prev = psi
        px, py = rx, ry
        qx, qy = tx, ty
    return rel, head, lead, lead_pts


def assemble_plan(
    strategy: str,
    mode: str,
    targets: ArrayLike,
    centre: ArrayLike,
    radius: float,
    sector: tuple[float, float] | None,
    start_xy: ArrayLike,
    altitude: float,
    speed: float,
    fall=None,
    wind_mean=None,
    hover_groups: ArrayLike | None = None,
    min_leg: float = 2.0,
    lead_in: float = 10.0,
    fall_dt: float = 0.01,
    info: dict | None = None,
) -> ReleasePlan:
    """Turn ordered landing targets into a flyable, compensated ``ReleasePlan``.

    Args:
        strategy: Strategy name stored in the plan.
        mode: One of ``MODES``.
        targets: ``(n, 2)`` world landing targets in visiting order.
        centre: Zone centre ``(2,)``.
        radius: Zone radius.
        sector: Wedge or ``None``.
        start_xy: UAV start ``(2,)``.
        altitude: Release height (> 0).
        speed: Cruise speed (>= 0); the release speed in ``"waypoints"`` mode.
        fall: ``FallParams`` for compensation, or ``None`` (release points = targets).
        wind_mean: Mean wind for compensation (``(2,)``, callable or ``None``).
        hover_groups: For ``"hover"``: ``(n,)`` nondecreasing group ids, consecutive targets sharing an
            id share one hover waypoint (they must be equal points). ``None``: one hover per target.
        min_leg: Shortest straight arrival (m) accepted before a lead-in is inserted.
        lead_in: Length of an inserted lead-in leg (m).
        fall_dt: Integration step passed to ``predict_landing``.
        info: Extra strategy statistics to store.

    Returns:
        The plan.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    tgt = np.ascontiguousarray(targets, dtype=np.float64).reshape(-1, 2)
    n = tgt.shape[0]
    start = np.asarray(start_xy, dtype=np.float64).reshape(2)
    make_plan = functools.partial(
        ReleasePlan,
        strategy=strategy,
        mode=mode,
        centre=np.asarray(centre, dtype=np.float64).reshape(2),
        radius=float(radius),
        sector=sector,
        start_xy=start,
        altitude=float(altitude),
        info=dict(info or {}),
    )
    if mode == "teleport":
        pts = np.hstack([tgt, np.zeros((n, 1))])
        return make_plan(
            waypoints=np.zeros((0, 3)),
            release_wp=np.full(n, -1, dtype=np.int64),
            release_xy=tgt,
            release_points=pts,
            release_vel=np.zeros((n, 3)),
            release_speed=0.0,
            path_length=0.0,
        )
    v_rel = float(speed) if mode == "waypoints" else 0.0
    table = throw_table(altitude, v_rel, fall, wind_mean, fall_dt)
    lead = np.zeros(n, dtype=bool)
    lead_pts = np.zeros((n, 2))
    if mode == "waypoints":
        has_throw = bool(np.any(table != 0.0))
        rel, head, lead, lead_pts = _solve_headings(
            tgt, start, table, float(min_leg) if has_throw else 0.0, float(lead_in)
        )
        vel = np.zeros((n, 3))
        vel[:, 0], vel[:, 1] = v_rel * np.cos(head), v_rel * np.sin(head)
    else:
        rel = tgt - table[0]
        vel = np.zeros((n, 3))
    residual = 0.0
    if fall is not None and n:
        # Exact correction: over flat ground a shift of the release point shifts the landing equally.
        p3 = np.hstack([rel, np.full((n, 1), float(altitude))])
        for _ in range(2):
            err = tgt - _predict(fall, p3, vel, wind_mean, fall_dt)
            p3[:, :2] += err
            lead_pts[lead] += err[lead]
        rel = p3[:, :2]
        residual = float(np.max(np.hypot(*(tgt - _predict(fall, p3, vel, wind_mean, fall_dt)).T)))
    if mode == "hover":
        groups = np.arange(n) if hover_groups is None else np.asarray(hover_groups).reshape(n)
        first = np.ones(n, dtype=bool)
        first[1:] = groups[1:] != groups[:-1]
        wp_xy = rel[first]
        release_wp = np.cumsum(first) - 1
    else:
        per = 1 + lead.astype(np.int64)
        release_wp = np.cumsum(per) - 1
        wp_xy = np.empty((int(per.sum()), 2))
        wp_xy[release_wp] = rel
        wp_xy[release_wp[lead] - 1] = lead_pts[lead]
    waypoints = np.hstack([wp_xy, np.full((wp_xy.shape[0], 1), float(altitude))])
    release_points = np.hstack([rel, np.full((n, 1), float(altitude))])
    return make_plan(
        waypoints=waypoints,
        release_wp=release_wp.astype(np.int64),
        release_xy=tgt,
        release_points=release_points,
        release_vel=vel,
        release_speed=v_rel,
        path_length=path_length(wp_xy, start),
        n_lead_in=int(lead.sum()),
        residual=residual,
    )
