"""Target and route generators for the scripted release baselines B0-B8 (domain reference 5.2).

Every generator works in offsets from the zone centre and returns landing targets already in visiting
order; ``make_plan`` then turns them into a compensated ``ReleasePlan`` (``planning.assemble_plan``).

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
from collections.abc import Mapping

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.cluster.vq import kmeans2
from scipy.optimize import brentq
from scipy.spatial import cKDTree

from agentsim_env.policies.release.planning import (
    TWO_PI,
    ReleasePlan,
    assemble_plan,
    in_sector,
    normalise_sector,
    plan_tour,
    sector_quota,
)
from agentsim_env.uav.wsn.profiles import RadialProfile

__all__ = ["STRATEGIES", "cvt_points", "make_plan", "spiral_points"]

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))

STRATEGIES: dict[str, str] = {
    "B0_uniform": "uniform random targets r = R sqrt(u) (ignores the profile), NN + 2-opt tour",
    "B1_inverse_cdf": "profile-distributed random targets r = F^-1(u), NN + 2-opt tour",
    "B1LD_sunflower": "sunflower low-discrepancy targets following the profile, NN + 2-opt tour",
    "B2_rings": "concentric rings at CDF midpoints, equal mass per ring, releases evenly spaced on circles",
    "B3_spiral": "Archimedean spiral with variable pitch Delta(r) = s(r) = c / sqrt(rho(r)), N releases",
    "B4_boustrophedon": "lawnmower lanes over the box, release each time accumulated rho*Delta*ds gains 1",
    "B5_cvt": "density-weighted CVT (Lloyd on a grid, phi = rho^2) from the sunflower set, NN + 2-opt tour",
    "B6_drop_clusters": "k-means drop points on B1 targets; hover and release each cluster's sensors",
    "B7_ergodic": "spectral multiscale coverage trajectory for phi = rho, constant-interval in-zone releases",
    "B8_oracle": "teleport placement of the B1-LD (or B5) points: no flight, zero landing error",
}

_COMMON_OPTS = frozenset({"mode", "min_leg", "lead_in", "fall_dt", "two_opt"})
_OPTS: dict[str, frozenset[str]] = {
    "B2_rings": frozenset({"n_rings", "ring_radii"}),
    "B4_boustrophedon": frozenset({"lane_spacing"}),
    "B5_cvt": frozenset({"lloyd_iters", "grid"}),
    "B6_drop_clusters": frozenset({"n_drops"}),
    "B7_ergodic": frozenset({"modes", "spacing", "substeps", "turn_radius"}),
    "B8_oracle": frozenset({"base", "lloyd_iters", "grid"}),
}


# ---------------------------------------------------------------------------------------- helpers
def _polar(r: NDArray, theta: NDArray) -> NDArray:
    return np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1) if r.size else np.zeros((0, 2))


def _wedge_angles(n: int, sector: tuple[float, float] | None, rng: np.random.Generator) -> NDArray:
    t0, width = normalise_sector(sector)
    return t0 + width * rng.random(n)


def _tour(pts: NDArray, start: NDArray, two_opt: bool) -> NDArray:
    return pts[plan_tour(pts, start, two_opt)]


def _orient(pts: NDArray, start: NDArray) -> NDArray:
    """Fly a fixed sequence from whichever end is nearer the start (positions are unchanged)."""
    if pts.shape[0] > 1 and np.hypot(*(pts[-1] - start)) < np.hypot(*(pts[0] - start)):
        return pts[::-1].copy()
    return pts


def _serpentine(pts: NDArray, group: NDArray, along: NDArray, start: NDArray) -> NDArray:
    """Order by group (arcs, lanes, turns), alternating direction along each group; nearer end first."""
    if pts.shape[0] == 0:
        return pts
    _, rank = np.unique(group, return_inverse=True)
    sign = np.where(rank % 2 == 0, 1.0, -1.0)
    order = np.lexsort((sign * along, rank))
    return _orient(pts[order], start)


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


def _rings(
    profile: RadialProfile, n: int, n_rings: int | None, radii: str
) -> tuple[NDArray, NDArray, NDArray]:
    """Concentric rings; returns offsets, ring index and angle of each point (ring by ring, CCW)."""
    if n_rings is not None and int(n_rings) < 1:
        raise ValueError(f"options['n_rings'] must be >= 1, got {n_rings!r}")
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0)
    r_j, counts = _ring_layout(profile, n, n_rings, radii)
    ring = np.repeat(np.arange(r_j.size), counts)
    k = np.arange(n) - np.repeat(np.cumsum(counts) - counts, counts)
    theta = ring * GOLDEN_ANGLE + TWO_PI * k / counts[ring]  # golden phase: no radial alignment
    return _polar(r_j[ring], theta), ring, theta


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
    return _polar(np.interp(levels, cum, r), th), th


def _lanes(profile: RadialProfile, n: int, spacing: float | None, samples: int = 2048) -> NDArray:
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


def _ergodic(profile: RadialProfile, n: int, sector, start: NDArray, opts: Mapping) -> NDArray:
    """B7: SMC trajectory for ``phi = rho`` restricted to the wedge, over the wedge's bounding box."""
    if n == 0:
        return np.zeros((0, 2))
    big_r = float(profile.radius)
    t0, width = normalise_sector(sector)
    ang = [t0, t0 + width] + [q * math.pi / 2 for q in range(4) if (q * math.pi / 2 - t0) % TWO_PI < width]
    corner = np.vstack([[0.0, 0.0], _polar(np.full(len(ang), big_r), np.asarray(ang))])
    lo, hi = corner.min(axis=0), corner.max(axis=0)
    hi = np.maximum(hi, lo + 1e-6 * big_r)
    lx, ly = hi - lo
    kk = int(opts.get("modes") or np.clip(math.ceil(math.sqrt(n)), 8, 64))
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
    spacing = float(opts.get("spacing") or math.sqrt(0.5 * width * big_r**2 / n))
    sub = int(opts.get("substeps") or 4)
    turn_r = float(opts.get("turn_radius") or spacing)
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


# ---------------------------------------------------------------------------------------- entry point
def make_plan(
    strategy: str,
    centre: ArrayLike,
    profile: RadialProfile,
    n_sensors: int,
    altitude: float,
    speed: float,
    rng: np.random.Generator,
    sector: tuple[float, float] | None = None,
    start_xy: ArrayLike | None = None,
    fall=None,
    wind_mean=None,
    options: Mapping | None = None,
) -> ReleasePlan:
    """Plan one UAV's releases over one zone (or one wedge of it) with a B0-B8 strategy.

    Args:
        strategy: A key of ``STRATEGIES``.
        centre: Zone centre ``(2,)`` in world metres.
        profile: Radial density profile (``RadialProfile``); its ``radius`` is the zone radius.
        n_sensors: Sensors for the whole zone (``N``); see the module docstring for wedges.
        altitude: Release height above flat ground (> 0).
        speed: Cruise speed (>= 0), also the release speed of fly-through plans.
        rng: Source of all randomness (B0, B1, B6).
        sector: ``(theta0, theta1)`` wedge for this UAV, or ``None`` for the whole disc.
        start_xy: UAV start; default: the rim at the wedge's mid-angle (angle 0 for the whole disc).
        fall: ``FallParams`` for release-point compensation, or ``None`` (release over the target).
        wind_mean: Mean wind ``(2,)`` (or callable of height) used by the compensation.
        options: Extra knobs. Common: ``mode`` (``"hover"`` turns a fly-through plan into hovers),
            ``min_leg`` (2 m), ``lead_in`` (10 m), ``fall_dt`` (0.01 s), ``two_opt`` (True). B2
            ``n_rings``, ``ring_radii`` (``"cdf"`` or ``"isotropic"``); B4 ``lane_spacing``; B5/B8
            ``lloyd_iters`` (30), ``grid``; B6 ``n_drops`` (N/10); B7 ``modes``, ``spacing``,
            ``substeps``, ``turn_radius``; B8 ``base`` (``"B1LD_sunflower"`` or ``"B5_cvt"``).

    Returns:
        The ``ReleasePlan``.

    Raises:
        ValueError: On an unknown strategy or option, or invalid numbers.
    """
    if strategy not in STRATEGIES:
        raise ValueError(f"strategy must be one of {tuple(STRATEGIES)}, got {strategy!r}")
    opts = dict(options or {})
    allowed = _COMMON_OPTS | _OPTS.get(strategy, frozenset())
    if set(opts) - allowed:
        raise ValueError(f"options for {strategy} must be among {sorted(allowed)}, got {sorted(opts)}")
    if isinstance(n_sensors, bool) or not isinstance(n_sensors, (int, np.integer)) or n_sensors < 0:
        raise ValueError(f"n_sensors must be an integer >= 0, got {n_sensors!r}")
    if not (math.isfinite(altitude) and altitude > 0):
        raise ValueError(f"altitude must be a finite number > 0, got {altitude!r}")
    if not (math.isfinite(speed) and speed >= 0):
        raise ValueError(f"speed must be a finite number >= 0, got {speed!r}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    c = np.asarray(centre, dtype=np.float64).reshape(2)
    big_r = float(profile.radius)
    t0, width = normalise_sector(sector)
    n = int(n_sensors)
    if start_xy is None:
        a = t0 + 0.5 * width if sector is not None else 0.0
        start_xy = c + big_r * np.array([math.cos(a), math.sin(a)])
    start = np.asarray(start_xy, dtype=np.float64).reshape(2) - c
    two_opt = bool(opts.get("two_opt", True))
    mode = "waypoints"
    groups = None
    info: dict = {}

    if strategy in ("B0_uniform", "B1_inverse_cdf", "B6_drop_clusters"):
        nq = sector_quota(n, sector)
        u = rng.random(nq)
        r = big_r * np.sqrt(u) if strategy == "B0_uniform" else np.asarray(profile.inverse_cdf(u))
        pts = _polar(r, _wedge_angles(nq, sector, rng))
        if strategy != "B6_drop_clusters":
            pts = _tour(pts, start, two_opt)
        elif nq:
            m = int(opts.get("n_drops") or max(1, round(nq / 10)))
            if m < 1:
                raise ValueError(f"options['n_drops'] must be >= 1, got {opts.get('n_drops')!r}")
            with warnings.catch_warnings():  # an empty cluster is simply dropped below
                warnings.simplefilter("ignore")
                try:
                    cent, lab = kmeans2(pts, min(m, nq), iter=20, minit="++", rng=rng)
                except TypeError:  # scipy < 1.15 names the generator argument ``seed``
                    cent, lab = kmeans2(pts, min(m, nq), iter=20, minit="++", seed=rng)
            counts = np.bincount(lab, minlength=cent.shape[0])
            cent, counts = cent[counts > 0], counts[counts > 0]
            order = plan_tour(cent, start, two_opt)
            pts = np.repeat(cent[order], counts[order], axis=0)
            groups = np.repeat(np.arange(order.size), counts[order])
            mode = "hover"
            info["drop_counts"] = counts[order]
    elif strategy in ("B1LD_sunflower", "B5_cvt", "B8_oracle"):
        base = "B5_cvt" if strategy == "B5_cvt" else opts.get("base", "B1LD_sunflower")
        if base == "B5_cvt":
            pts = cvt_points(profile, n, int(opts.get("lloyd_iters", 30)), opts.get("grid"))
        elif base == "B1LD_sunflower":
            pts = np.asarray(profile.low_discrepancy(n), dtype=np.float64)
        else:
            raise ValueError(f"options['base'] must be 'B1LD_sunflower' or 'B5_cvt', got {base!r}")
        pts = pts[in_sector(pts, sector)]
        if strategy == "B8_oracle":
            mode = "teleport"
        else:
            pts = _tour(pts, start, two_opt)
    elif strategy == "B2_rings":
        pts, ring, theta = _rings(profile, n, opts.get("n_rings"), opts.get("ring_radii", "cdf"))
        keep = in_sector(pts, sector)
        rel = np.mod(theta - t0, TWO_PI)
        # Outer ring first when starting outside: groups sorted by decreasing radius.
        pts = _serpentine(pts[keep], -ring[keep], rel[keep], start)
        info["n_rings"] = int(np.unique(ring).size)
    elif strategy == "B3_spiral":
        pts, th = spiral_points(profile, n)
        keep = in_sector(pts, sector)
        if sector is None:
            pts = _orient(pts, start)
        else:
            turn = np.floor((th[keep] - t0) / TWO_PI)
            pts = _serpentine(pts[keep], -turn, th[keep], start)
    elif strategy == "B4_boustrophedon":
        pts = _lanes(profile, n, opts.get("lane_spacing"))
        pts = _orient(pts[in_sector(pts, sector)], start)
    else:  # B7_ergodic
        pts = _ergodic(profile, sector_quota(n, sector), sector, start, opts)

    if opts.get("mode", mode) == "hover" and mode == "waypoints":
        mode = "hover"
    elif opts.get("mode", mode) != mode:
        raise ValueError(f"options['mode'] for {strategy} must be {mode!r} or 'hover', got {opts['mode']!r}")
    return assemble_plan(
        strategy,
        mode,
        pts + c,
        c,
        big_r,
        sector,
        start + c,
        altitude,
        speed,
        fall,
        wind_mean,
        hover_groups=groups,
        min_leg=float(opts.get("min_leg", 2.0)),
        lead_in=float(opts.get("lead_in", 10.0)),
        fall_dt=float(opts.get("fall_dt", 0.01)),
        info=info,
    )
