"""How well the landed sensors of each zone follow the zone's target radial density (domain reference 2.5).

Per zone, with ``r_i = ||p_i - c||`` for the sensors assigned to the zone and ``F`` the profile's radial CDF
(1 beyond the zone radius ``R``):

* radial KS: ``sup_r |F_hat(r) - F(r)|`` and the ``scipy.stats.kstest`` p-value;
* radial W1: ``int_0^inf |F_hat - F| dr / R`` (the Wasserstein-1 distance of the radial laws over ``R``; equal
  to ``int_0^R`` when every sensor lies inside the zone, and it also charges sensors that land outside);
* inner/outer density ratio: sensors per m^2 in ``r < R/3`` over sensors per m^2 in ``2R/3 < r < R``, and the
  same ratio for the target profile;
* monotonicity: Spearman correlation between ``r_i`` and the k-NN density ``k / (pi d_k,i^2)`` (neighbours
  among the zone's sensors), and the same for the profile's low-discrepancy set of equal size;
* centroid bias ``||mean(p_i) - c|| / R``; containment (fraction with ``r_i <= R``);
* landing error ``||p_land - p_intended||`` (mean and 95th percentile) when intended points are given.

Sensors are assigned to the zone they were meant for (``zone_of``) or, where that is -1, to the nearest zone
by distance to its disc (``||p - c_k|| - R_k``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats
from scipy.spatial import cKDTree

from agentsim_env.uav.wsn.coverage import check_discs, check_points

__all__ = [
    "ZoneFidelity",
    "assign_zones",
    "density_ratio",
    "fidelity_per_zone",
    "knn_monotonicity",
    "radial_ks",
    "radial_w1",
    "target_density_ratio",
    "zone_fidelity",
]


class CdfProfile(Protocol):
    """Anything with a vectorised radial CDF ``cdf(r)`` that is 1 beyond the zone radius (e.g. ``RadialProfile``)."""

    def cdf(self, r: ArrayLike, /) -> ArrayLike:
        """Fraction of the mass within distances ``r`` of the centre."""
        ...


# Quadrature nodes for W1 between sample radii: |F_hat - F| is smooth there, so the trapezoid rule on this
# many extra nodes is accurate to ~1e-7.
_W1_NODES = 4097


def assign_zones(
    points: ArrayLike, centres: ArrayLike, radii: ArrayLike, zone_of: ArrayLike | None = None
) -> NDArray[np.int64]:
    """Zone of each sensor: its intended zone, or the nearest disc where that is -1 or not given.

    Args:
        points: ``(n, 2)`` landing positions.
        centres: ``(K, 2)`` zone centroids.
        radii: ``(K,)`` zone radii.
        zone_of: ``(n,)`` intended zone indices in ``[-1, K)``; ``None`` means all -1.

    Returns:
        ``(n,)`` int64 zone indices in ``[0, K)``.
    """
    p = check_points(points, "land_xy")
    c, r = check_discs(centres, radii)
    n, n_zones = p.shape[0], c.shape[0]
    zone = np.full(n, -1, dtype=np.int64) if zone_of is None else np.asarray(zone_of).astype(np.int64).reshape(-1)
    if zone.shape != (n,):
        raise ValueError(f"zone_of must have shape (n,) = ({n},), got {zone.shape}")
    if zone.size and (zone.min() < -1 or zone.max() >= n_zones):
        raise ValueError(f"zone_of values must be in [-1, {n_zones}), got range [{zone.min()}, {zone.max()}]")
    missing = zone < 0
    if missing.any():
        gap = np.linalg.norm(p[missing, None, :] - c[None, :, :], axis=2) - r[None, :]
        zone[missing] = np.argmin(gap, axis=1)
    return zone


def _radii(points: NDArray[np.float64], centre: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distances to the centre."""
    return np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1])


def radial_ks(r: NDArray[np.float64], profile: CdfProfile) -> tuple[float, float]:
    """Kolmogorov-Smirnov distance between the empirical radial CDF and ``profile.cdf``.

    Args:
        r: ``(m,)`` distances from the zone centre.
        profile: Object with a vectorised ``cdf(r)`` (1 beyond its radius).

    Returns:
        ``(statistic, p_value)``; NaNs when ``m == 0``.
    """
    m = r.size
    if m == 0:
        return math.nan, math.nan
    f = np.asarray(profile.cdf(np.sort(r)), dtype=np.float64)
    i = np.arange(1, m + 1)
    stat = float(max(np.max(i / m - f), np.max(f - (i - 1) / m)))
    pvalue = float(stats.kstest(r, profile.cdf).pvalue)
    return stat, pvalue


def radial_w1(r: NDArray[np.float64], profile: CdfProfile, radius: float) -> float:
    """``int_0^inf |F_hat(s) - F(s)| ds / radius``, F being ``profile.cdf``.

    Args:
        r: ``(m,)`` distances from the zone centre.
        profile: Object with a vectorised ``cdf(r)``.
        radius: Zone radius ``R`` in metres.

    Returns:
        The normalised distance (NaN when ``m == 0``).
    """
    if r.size == 0:
        return math.nan
    srt = np.sort(r)
    top = max(float(radius), float(srt[-1]))
    # Sample radii are nodes, so F_hat is constant on every sub-interval and only F varies inside it.
    nodes = np.union1d(np.linspace(0.0, top, _W1_NODES), srt)
    level = np.searchsorted(srt, nodes[:-1], side="right") / srt.size
    f = np.asarray(profile.cdf(nodes), dtype=np.float64)
    gap = 0.5 * (np.abs(level - f[:-1]) + np.abs(level - f[1:]))
    return float(np.sum(gap * np.diff(nodes)) / radius)


def density_ratio(r: NDArray[np.float64], radius: float) -> float:
    """Areal density in ``r < R/3`` over areal density in ``2R/3 < r < R``.

    Args:
        r: ``(m,)`` distances from the zone centre.
        radius: Zone radius ``R``.

    Returns:
        The ratio; ``inf`` when the outer ring is empty but the core is not, NaN when both are empty.
    """
    inner = np.count_nonzero(r < radius / 3.0) / (math.pi * (radius / 3.0) ** 2)
    outer = np.count_nonzero((r > 2.0 * radius / 3.0) & (r < radius)) / (math.pi * radius**2 * (1.0 - 4.0 / 9.0))
    if outer == 0.0:
        return math.inf if inner > 0.0 else math.nan
    return float(inner / outer)


def target_density_ratio(profile: CdfProfile, radius: float) -> float:
    """The inner/outer density ratio of the target profile itself (from its radial CDF).

    Args:
        profile: Object with a vectorised ``cdf(r)``.
        radius: Zone radius ``R``.

    Returns:
        ``(F(R/3) / A_in) / ((F(R) - F(2R/3)) / A_out)``.
    """
    f = np.asarray(profile.cdf(np.array([radius / 3.0, 2.0 * radius / 3.0, radius])), dtype=np.float64)
    inner = f[0] / (math.pi * (radius / 3.0) ** 2)
    outer = (f[2] - f[1]) / (math.pi * radius**2 * (1.0 - 4.0 / 9.0))
    return float(inner / outer) if outer > 0.0 else math.inf


def knn_monotonicity(points: NDArray[np.float64], centre: NDArray[np.float64], k: int = 5) -> float:
    """Spearman correlation between distance to the centre and k-NN density ``k / (pi d_k^2)``.

    Args:
        points: ``(m, 2)`` positions of one zone's sensors.
        centre: Zone centroid.
        k: Neighbour rank (>= 1).

    Returns:
        Correlation in [-1, 1] (negative when density falls outward); NaN for ``m <= k`` or no variation.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"knn_k must be an integer >= 1, got {k!r}")
    if points.shape[0] <= k:
        return math.nan
    d_k = cKDTree(points).query(points, k=k + 1)[0][:, -1]
    with np.errstate(divide="ignore"):
        lam = k / (math.pi * d_k * d_k)
    return _spearman(_radii(points, centre), lam)


def _spearman(x: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """Spearman's rho (average ranks for ties); NaN when either side is constant."""
    rx, ry = stats.rankdata(x), stats.rankdata(y)
    if np.ptp(rx) == 0.0 or np.ptp(ry) == 0.0:
        return math.nan
    return float(np.corrcoef(rx, ry)[0, 1])


@dataclass(frozen=True)
class ZoneFidelity:
    """Density-fidelity metrics of one zone (module docstring gives the definitions)."""

    n: int
    ks: float
    ks_pvalue: float
    w1: float
    density_ratio: float
    density_ratio_target: float
    monotonicity: float
    monotonicity_target: float
    centroid_bias: float
    containment: float
    landing_error_mean: float
    landing_error_p95: float

    def as_dict(self) -> dict[str, float]:
        """Field name to float value."""
        return {key: float(value) for key, value in asdict(self).items()}


def zone_fidelity(
    points: ArrayLike,
    centre: ArrayLike,
    radius: float,
    profile: CdfProfile,
    targets: ArrayLike | None = None,
    knn_k: int = 5,
) -> ZoneFidelity:
    """All fidelity metrics for the sensors assigned to one zone.

    Args:
        points: ``(m, 2)`` landing positions.
        centre: Zone centroid ``(2,)``.
        radius: Zone radius in metres.
        profile: Target profile (``cdf``; ``low_discrepancy(m)`` if available, for the ideal monotonicity).
        targets: ``(m, 2)`` intended landing points, or ``None``.
        knn_k: Neighbour rank for the k-NN density.

    Returns:
        The metrics (NaN where undefined, e.g. an empty zone).
    """
    p = check_points(points, "points")
    c = np.asarray(centre, dtype=np.float64).reshape(2)
    radius = float(radius)
    m = p.shape[0]
    r = _radii(p, c)
    ks, ks_p = radial_ks(r, profile)
    mono_target = math.nan
    if hasattr(profile, "low_discrepancy") and m > knn_k:
        mono_target = knn_monotonicity(np.asarray(profile.low_discrepancy(m)) + c, c, knn_k)
    err_mean = err_p95 = math.nan
    if targets is not None and m > 0:
        err = np.linalg.norm(p - check_points(targets, "targets_xy"), axis=1)
        err_mean, err_p95 = float(err.mean()), float(np.percentile(err, 95.0))
    return ZoneFidelity(
        n=m,
        ks=ks,
        ks_pvalue=ks_p,
        w1=radial_w1(r, profile, radius),
        density_ratio=density_ratio(r, radius) if m else math.nan,
        density_ratio_target=target_density_ratio(profile, radius),
        monotonicity=knn_monotonicity(p, c, knn_k),
        monotonicity_target=mono_target,
        centroid_bias=float(np.linalg.norm(p.mean(axis=0) - c) / radius) if m else math.nan,
        containment=float(np.mean(r <= radius)) if m else math.nan,
        landing_error_mean=err_mean,
        landing_error_p95=err_p95,
    )


def fidelity_per_zone(
    land_xy: ArrayLike,
    zone: ArrayLike,
    centres: ArrayLike,
    radii: ArrayLike,
    profiles: Sequence[CdfProfile],
    targets_xy: ArrayLike | None = None,
    knn_k: int = 5,
) -> list[ZoneFidelity]:
    """Fidelity metrics for every zone.

    Args:
        land_xy: ``(n, 2)`` landing positions.
        zone: ``(n,)`` zone of each sensor in ``[0, K)`` (see ``assign_zones``).
        centres: ``(K, 2)`` zone centroids.
        radii: ``(K,)`` zone radii.
        profiles: K target profiles.
        targets_xy: ``(n, 2)`` intended landing points, or ``None``.
        knn_k: Neighbour rank for the k-NN density.

    Returns:
        One ``ZoneFidelity`` per zone.
    """
    p = check_points(land_xy, "land_xy")
    c, r = check_discs(centres, radii)
    if len(profiles) != c.shape[0]:
        raise ValueError(f"profiles must hold one profile per zone (K = {c.shape[0]}), got {len(profiles)}")
    z = np.asarray(zone, dtype=np.int64).reshape(-1)
    if z.shape != (p.shape[0],):
        raise ValueError(f"zone must have shape (n,) = ({p.shape[0]},), got {z.shape}")
    tgt = None if targets_xy is None else check_points(targets_xy, "targets_xy")
    if tgt is not None and tgt.shape != p.shape:
        raise ValueError(f"targets_xy must have shape {p.shape}, got {tgt.shape}")
    out = []
    with warnings.catch_warnings():
        # kstest warns about exact-mode fallbacks on large samples; the asymptotic p-value is what we want.
        warnings.simplefilter("ignore", RuntimeWarning)
        for k in range(c.shape[0]):  # K zones, each vectorised over its sensors
            sel = z == k
            out.append(zone_fidelity(p[sel], c[k], r[k], profiles[k], None if tgt is None else tgt[sel], knn_k))
    return out
