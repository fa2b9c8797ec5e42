"""Target and route generators for the scripted release baselines B0-B8 (domain reference 5.2).

Every generator works in offsets from the zone centre and returns landing targets already in visiting
order; the strategies of ``baselines`` call them from their ``pattern`` and ``ReleaseStrategy.plan`` turns
the targets into a compensated ``ReleasePlan`` (``planning.assemble_plan``).

Sectors (domain 5.3). ``n_sensors`` is always the zone total ``N``. With a wedge:

* deterministic patterns (B1-LD, B2, B3, B4, B5, B8) are built for the whole zone and only the points in
  the half-open wedge are kept, so the plans of ``split_sectors`` wedges partition one pattern exactly
  (each wedge gets about ``N * width / 2 pi`` points, not a fixed quota);
* random patterns (B0, B1, B6) and the ergodic trajectory (B7) produce exactly ``sector_quota(N, sector)``
  targets inside the wedge (quotas of ``split_sectors`` wedges add up to ``N``).

All profiles are radially symmetric, so a wedge's mass share is its angle share.

B7 is a real spectral multiscale coverage trajectory (first-order feedback law of Mathew & Mezic 2011
on a cosine basis over the wedge's bounding box, ``phi = rho`` restricted to the wedge), flown at
constant speed with a turn-rate limit; a release is due every ``spacing`` metres of trajectory and is
skipped when the UAV is outside the zone. The plan keeps the release points in trajectory order, so
the flown route is the chord polyline between consecutive releases.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.cluster.vq import kmeans2
from scipy.optimize import brentq
from scipy.spatial import cKDTree

from agentsim_env.policies.release.planning import (
    TWO_PI,
    in_sector,
    normalise_sector,
    plan_tour,
    sector_quota,
)
from agentsim_env.uav.wsn.profiles import RadialProfile

__all__ = [
    "GOLDEN_ANGLE",
    "cvt_points",
    "drop_clusters",
    "ergodic_points",
    "lane_points",
    "orient",
    "polar",
    "random_wedge_points",
    "ring_points",
    "serpentine",
    "spiral_points",
    "tour",
]

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


# ---------------------------------------------------------------------------------------- helpers
def polar(r: NDArray, theta: NDArray) -> NDArray:
    """Offsets ``(n, 2)`` of the polar coordinates ``(r, theta)``."""
    return np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1) if r.size else np.zeros((0, 2))


def _wedge_angles(n: int, sector: tuple[float, float] | None, rng: np.random.Generator) -> NDArray:
    t0, width = normalise_sector(sector)
    return t0 + width * rng.random(n)


def tour(pts: NDArray, start: NDArray, two_opt: bool) -> NDArray:
    """The points in nearest-neighbour tour order from ``start`` (improved by 2-opt when ``two_opt``)."""
    return pts[plan_tour(pts, start, two_opt)]


def orient(pts: NDArray, start: NDArray) -> NDArray:
    """Fly a fixed sequence from whichever end is nearer the start (positions are unchanged)."""
    if pts.shape[0] > 1 and np.hypot(*(pts[-1] - start)) < np.hypot(*(pts[0] - start)):
        return pts[::-1].copy()
    return pts


def serpentine(pts: NDArray, group: NDArray, along: NDArray, start: NDArray) -> NDArray:
    """Order by group (arcs, lanes, turns), alternating direction along each group; nearer end first."""
    if pts.shape[0] == 0:
        return pts
    _, rank = np.unique(group, return_inverse=True)
    sign = np.where(rank % 2 == 0, 1.0, -1.0)
    order = np.lexsort((sign * along, rank))
    return orient(pts[order], start)


def random_wedge_points(
    profile: RadialProfile,
    n: int,
    sector: tuple[float, float] | None,
    rng: np.random.Generator,
    follow_profile: bool = True,
) -> NDArray:
    """``sector_quota(n, sector)`` random offsets in the wedge (B0, B1, B6).

    Args:
        profile: Radial profile.
        n: Sensors of the whole zone.
        sector: Wedge or ``None``.
        rng: Source of the radii, then the angles.
        follow_profile: Radii ``F^-1(u)`` (profile-distributed); else ``R sqrt(u)`` (uniform over the disc).

    Returns:
        ``(quota, 2)`` offsets in draw order.
    """
    nq = sector_quota(n, sector)
    u = rng.random(nq)
    r = np.asarray(profile.inverse_cdf(u)) if follow_profile else float(profile.radius) * np.sqrt(u)
    return polar(r, _wedge_angles(nq, sector, rng))


def drop_clusters(
    pts: NDArray, n_drops: int, start: NDArray, two_opt: bool, rng: np.random.Generator
) -> tuple[NDArray, NDArray, NDArray]:
    """k-means drop points of ``pts`` (B6), toured from ``start``; empty clusters are dropped.

    Args:
        pts: ``(m, 2)`` targets (``m >= 1``).
        n_drops: Clusters wanted (at most ``m`` are made).
        start: Where the tour starts.
        two_opt: Improve the tour with 2-opt.
        rng: Generator of the k-means initialisation.

    Returns:
        ``(targets (m, 2), hover group of each target (m,), sensors per drop (d,))``: every target moved to
        its drop point, in tour order.
    """
    m = pts.shape[0]
    with warnings.catch_warnings():  # an empty cluster is simply dropped below
        warnings.simplefilter("ignore")
        try:
            cent, lab = kmeans2(pts, min(n_drops, m), iter=20, minit="++", rng=rng)
        except TypeError:  # scipy < 1.15 names the generator argument ``seed``
            cent, lab = kmeans2(pts, min(n_drops, m), iter=20, minit="++", seed=rng)
    counts = np.bincount(lab, minlength=cent.shape[0])
    cent, counts = cent[counts > 0], counts[counts > 0]
    order = plan_tour(cent, start, two_opt)
    groups = np.repeat(np.arange(order.size), counts[order])
    return np.repeat(cent[order], counts[order], axis=0), groups, counts[order]


# ---------------------------------------------------------------------------------------- patterns
def _ring_layout(profile: RadialProfile, n: int, n_rings: int | None, radii: str) -> tuple[NDArray, NDArray]:
    """Ring radii and per-ring counts (``sum == n``).

    ``"cdf"``: radii at CDF midpoints ``F^-1((j - 1/2) / J)``, so every ring carries mass ``1 / J`` and
    the same count. ``"isotropic"``: radial spacing ``1 / sqrt(N rho)`` (rings equally spaced in
    ``g(r) = integral sqrt(N rho) dr``) and counts proportional to each ring's annulus mass, which makes
    the along-ring spacing match the radial one.
    """
    if radii == "cdf":
        # Isotropy at a typical ring (along-ring spacing 2 pi r J / N = radial spacing): J ~ sqrt(N / 2 pi).
        j_count = min(int(n_rings) if n_rings else max(1, round(math.sqrt(n / TWO_PI))), n)
        r_j = np.asarray(profile.inverse_cdf((np.arange(j_count) + 0.5) / j_count), dtype=np.float64)
        counts = np.full(j_count, n // j_count, dtype=np.int64)
        counts[j_count - n % j_count :] += 1  # the longest (outermost) rings take the remainder
        return r_j, counts
    if radii != "isotropic":
        raise ValueError(f"options['ring_radii'] must be 'cdf' or 'isotropic', got {radii!r}")
    r = profile.radius * np.linspace(0.0, 1.0, 20001) ** 2
    rm = 0.5 * (r[1:] + r[:-1])
    g = np.concatenate([[0.0], np.cumsum(np.sqrt(n * np.asarray(profile.density(rm))) * np.diff(r))])
    j_count = min(int(n_rings) if n_rings else max(1, round(g[-1])), n)
    levels = g[-1] * np.arange(2 * j_count + 1) / (2 * j_count)  # boundaries (even) and rings (odd)
    at = np.interp(levels, g, r)
    share = n * np.diff(np.asarray(profile.cdf(at[::2]), dtype=np.float64))
    counts = np.floor(share).astype(np.int64)
    extra = np.argsort(-(share - counts), kind="stable")[: n - counts.sum()]  # largest remainders
    counts[extra] += 1
    return at[1::2], counts


def ring_points(profile: RadialProfile, n: int, n_rings: int | None, radii: str) -> tuple[NDArray, NDArray, NDArray]:
    """Concentric rings; returns offsets, ring index and angle of each point (ring by ring, CCW)."""
    if n_rings is not None and int(n_rings) < 1:
        raise ValueError(f"options['n_rings'] must be >= 1, got {n_rings!r}")
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0)
    r_j, counts = _ring_layout(profile, n, n_rings, radii)
    ring = np.repeat(np.arange(r_j.size), counts)
    k = np.arange(n) - np.repeat(np.cumsum(counts) - counts, counts)
    theta = ring * GOLDEN_ANGLE + TWO_PI * k / counts[ring]  # golden phase: no radial alignment
    return polar(r_j[ring], theta), ring, theta


def spiral_points(profile: RadialProfile, n: int, grid: int = 20000) -> tuple[NDArray, NDArray]:
    """Variable-pitch Archimedean spiral, centre outward: pitch = along-track spacing = c / sqrt(rho).

    Local area per release is ``Delta * s = c^2 / rho``, so the count is about ``1 / c^2``; ``c`` is then
    solved exactly so that the arc-length count ``integral ds / s`` equals ``n``, and releases sit at
    counts ``k - 1/2``.

    Args:
        profile: Radial profile.
        n: Number of releases.
        grid: Radial integration nodes (squared spacing, dense near the centre).

    Returns:
        ``(offsets (n, 2), unwrapped spiral angle (n,))``.
    """
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0)
    r = profile.radius * np.linspace(0.0, 1.0, grid + 1) ** 2
    rm, dr = 0.5 * (r[1:] + r[:-1]), np.diff(r)
    sq = np.sqrt(np.asarray(profile.density(rm), dtype=np.float64))

    def count(c: float) -> NDArray:
        dtheta = TWO_PI * sq / c * dr
        return np.sqrt(dr * dr + (rm * dtheta) ** 2) * sq / c

    c0 = 1.0 / math.sqrt(n)
    c = brentq(lambda c: float(count(c).sum()) - n, c0 / 20.0, c0 * 20.0, xtol=1e-14 * c0)
    cum = np.concatenate([[0.0], np.cumsum(count(c))])
    theta = np.concatenate([[0.0], np.cumsum(TWO_PI * sq / c * dr)])
    levels = np.minimum(np.arange(n) + 0.5, cum[-1])
    th = np.interp(levels, cum, theta)
    return polar(np.interp(levels, cum, r), th), th


def lane_points(profile: RadialProfile, n: int, spacing: float | None, samples: int = 2048) -> NDArray:
    """Boustrophedon lanes (along x) over the zone box; release at accumulated mass ``k - 1/2``."""
    big_r = float(profile.radius)
    if n == 0:
        return np.zeros((0, 2))
    delta = float(spacing) if spacing else big_r * math.sqrt(math.pi / n)
    if not delta > 0:
        raise ValueError(f"options['lane_spacing'] must be > 0, got {spacing!r}")
    n_lanes = max(1, math.ceil(2.0 * big_r / delta))
    delta = 2.0 * big_r / n_lanes
    y = -big_r + delta * (np.arange(n_lanes) + 0.5)
    edges = np.linspace(-big_r, big_r, samples + 1)
    dx = edges[1] - edges[0]
    xc = 0.5 * (edges[1:] + edges[:-1])
    w = np.asarray(profile.density(np.hypot(xc[None, :], y[:, None])), dtype=np.float64) * delta * dx
    w[1::2] = w[1::2, ::-1]  # odd lanes are flown right to left
    flat = w.ravel()
    cum = np.cumsum(flat)
    levels = (np.arange(n) + 0.5) * cum[-1] / n
    i = np.minimum(np.searchsorted(cum, levels, side="left"), flat.size - 1)
    frac = np.clip((levels - (cum[i] - flat[i])) / np.maximum(flat[i], 1e-300), 0.0, 1.0)
    lane, cell = i // samples, i % samples
    x = np.where(lane % 2 == 0, edges[cell] + frac * dx, edges[samples - cell] - frac * dx)
    pts = np.stack([x, y[lane]], axis=1)
    # A cell straddling the rim is weighted at its centre; keep interpolated points on the disc.
    return pts * np.minimum(1.0, big_r / np.maximum(np.hypot(pts[:, 0], pts[:, 1]), 1e-300))[:, None]


def cvt_points(profile: RadialProfile, n: int, iters: int = 30, grid: int | None = None) -> NDArray:
    """Density-weighted centroidal Voronoi generators (Lloyd on a grid, ``phi = rho^2``).

    In 2D the CVT generator density goes as ``phi^(1/2)``, so ``phi = rho^2`` makes the generators follow
    ``rho``. Starts from the sunflower set (deterministic, already close) and runs ``iters`` Lloyd steps;
    cells are assigned to generators with a k-d tree.

    Args:
        profile: Radial profile.
        n: Number of generators.
        iters: Lloyd iterations.
        grid: Cells per axis over the zone box (default: about 80 cells per generator, 128-512).

    Returns:
        ``(n, 2)`` offsets from the centre (inside the disc: Voronoi cells of a convex set are convex).
    """
    if n == 0:
        return np.zeros((0, 2))
    big_r = float(profile.radius)
    g = int(grid) if grid else int(np.clip(math.ceil(math.sqrt(n * 80 * 4 / math.pi)), 128, 512))
    xs = -big_r + (np.arange(g) + 0.5) * (2.0 * big_r / g)  # even g: no cell centre at r = 0
    cx, cy = np.meshgrid(xs, xs, indexing="ij")
    rr = np.hypot(cx, cy).ravel()
    keep = rr <= big_r
    cells = np.stack([cx.ravel()[keep], cy.ravel()[keep]], axis=1)
    phi = np.asarray(profile.density(rr[keep]), dtype=np.float64) ** 2
    gen = np.asarray(profile.low_discrepancy(n), dtype=np.float64).copy()
    for _ in range(int(iters)):
        lab = cKDTree(gen).query(cells)[1]
        mass = np.bincount(lab, phi, minlength=n)
        has = mass > 0
        for c in range(2):
            gen[has, c] = np.bincount(lab, phi * cells[:, c], minlength=n)[has] / mass[has]
    return gen


@njit(cache=True)
def _smc_kernel(x0, y0, lx, ly, phik, lam, inv_h, step, max_turn, sub, n_out, n_max, cx, cy, rad, t0, width):
    """First-order SMC feedback (Mathew & Mezic 2011) with releases every ``sub`` steps in the zone.

    Box coordinates ``[0, lx] x [0, ly]``; basis ``f_k = cos(k1 pi x / lx) cos(k2 pi y / ly) / h_k``;
    ``S_k += f_k(x) - phi_k`` each unit time step; desired heading ``-B / |B|`` with
    ``B = sum_k lam_k S_k grad f_k``. The heading turns by at most ``max_turn`` per step: the pure
    first-order law reverses direction from one step to the next near balance (chattering), which would
    stack releases on one spot. Releases outside the disc or wedge are skipped.
    """
    kk = phik.shape[0]
    s = np.zeros((kk, kk))
    out = np.empty((n_out, 2))
    cnt = 0
    x, y = x0, y0
    psi = math.atan2(cy - y, cx - x)
    cxk, sxk, cyk, syk = np.empty(kk), np.empty(kk), np.empty(kk), np.empty(kk)
    for it in range(n_max):
        for k in range(kk):
            cxk[k], sxk[k] = math.cos(k * math.pi * x / lx), math.sin(k * math.pi * x / lx)
            cyk[k], syk[k] = math.cos(k * math.pi * y / ly), math.sin(k * math.pi * y / ly)
        bx, by = 0.0, 0.0
        for k1 in range(kk):
            for k2 in range(kk):
                s[k1, k2] += cxk[k1] * cyk[k2] * inv_h[k1, k2] - phik[k1, k2]
                a = lam[k1, k2] * s[k1, k2] * inv_h[k1, k2]
                bx -= a * (k1 * math.pi / lx) * sxk[k1] * cyk[k2]
                by -= a * (k2 * math.pi / ly) * cxk[k1] * syk[k2]
        nb = math.sqrt(bx * bx + by * by)
        if nb > 1e-12:
            turn = (math.atan2(-by, -bx) - psi + math.pi) % (2.0 * math.pi) - math.pi
            psi += min(max(turn, -max_turn), max_turn)
        x, y = x + step * math.cos(psi), y + step * math.sin(psi)
        # Reflect at the box walls (the cosine basis has zero normal gradient there anyway).
        if x < 0.0 or x > lx:
            x, psi = -x if x < 0.0 else 2.0 * lx - x, math.pi - psi
        if y < 0.0 or y > ly:
            y, psi = -y if y < 0.0 else 2.0 * ly - y, -psi
        x, y = min(max(x, 0.0), lx), min(max(y, 0.0), ly)
        if (it + 1) % sub == 0:
            dx, dy = x - cx, y - cy
            rel = (math.atan2(dy, dx) - t0) % (2.0 * math.pi)
            if dx * dx + dy * dy <= rad * rad and rel < width:
                out[cnt, 0], out[cnt, 1] = x - cx, y - cy
                cnt += 1
                if cnt == n_out:
                    break
    return out[:cnt]


def ergodic_points(
    profile: RadialProfile,
    n: int,
    sector: tuple[float, float] | None,
    start: NDArray,
    modes: int | None = None,
    spacing: float | None = None,
    substeps: int = 4,
    turn_radius: float | None = None,
) -> NDArray:
    """B7: SMC trajectory for ``phi = rho`` restricted to the wedge, over the wedge's bounding box.

    Args:
        profile: Radial profile.
        n: Releases to place in the wedge.
        sector: Wedge or ``None``.
        start: UAV start, offset from the centre.
        modes: Cosine modes per axis (default ``clip(ceil(sqrt(n)), 8, 64)``).
        spacing: Trajectory length between releases (default: the area per release's side).
        substeps: Integration steps per release interval.
        turn_radius: Smallest turn radius (default ``spacing``).

    Returns:
        ``(m, 2)`` release offsets in trajectory order (``m <= n``).
    """
    if n == 0:
        return np.zeros((0, 2))
    big_r = float(profile.radius)
    t0, width = normalise_sector(sector)
    ang = [t0, t0 + width] + [q * math.pi / 2 for q in range(4) if (q * math.pi / 2 - t0) % TWO_PI < width]
    corner = np.vstack([[0.0, 0.0], polar(np.full(len(ang), big_r), np.asarray(ang))])
    lo, hi = corner.min(axis=0), corner.max(axis=0)
    hi = np.maximum(hi, lo + 1e-6 * big_r)
    lx, ly = hi - lo
    kk = int(modes or np.clip(math.ceil(math.sqrt(n)), 8, 64))
    g = 200
    xs, ys = lo[0] + (np.arange(g) + 0.5) * lx / g, lo[1] + (np.arange(g) + 0.5) * ly / g
    px, py = np.meshgrid(xs, ys, indexing="ij")
    off = np.stack([px.ravel(), py.ravel()], axis=1)
    phi = np.asarray(profile.density(np.hypot(px, py)), dtype=np.float64)
    phi *= in_sector(off, sector).reshape(g, g)
    phi /= phi.sum() * (lx / g) * (ly / g)
    k = np.arange(kk)
    hx = np.where(k > 0, lx / 2.0, lx)
    hy = np.where(k > 0, ly / 2.0, ly)
    inv_h = 1.0 / np.sqrt(np.outer(hx, hy))
    cmx = np.cos(np.outer(xs - lo[0], k) * math.pi / lx)
    cmy = np.cos(np.outer(ys - lo[1], k) * math.pi / ly)
    phik = cmx.T @ phi @ cmy * (lx / g) * (ly / g) * inv_h
    lam = (1.0 + np.add.outer((k / lx) ** 2, (k / ly) ** 2) * big_r**2) ** -1.5
    spacing = float(spacing or math.sqrt(0.5 * width * big_r**2 / n))
    sub = int(substeps or 4)
    turn_r = float(turn_radius or spacing)
    if spacing <= 0 or sub < 1 or kk < 2 or turn_r <= 0:
        raise ValueError("options 'spacing', 'turn_radius' must be > 0, 'substeps' >= 1 and 'modes' >= 2")
    st = np.clip(start, lo, hi) - lo
    return _smc_kernel(
        float(st[0]),
        float(st[1]),
        float(lx),
        float(ly),
        phik,
        lam,
        inv_h,
        spacing / sub,
        spacing / sub / turn_r,
        sub,
        n,
        sub * n * 20 + 1000,
        float(-lo[0]),
        float(-lo[1]),
        big_r,
        t0,
        width,
    )
