"""Binary-disc area coverage of circular zones, evaluated on a lattice.

A point ``q`` is covered when some sensor lies within the sensing radius ``r_s`` (``||q - p_i|| <= r_s``).
The zones are discs; their union is sampled by the centres of a square lattice of pitch ``resolution``
anchored at the origin (cell centres at ``(i + 1/2) * resolution``), so zones that overlap share lattice
points and the union is counted once. Coverage is the fraction of lattice points covered, per zone and over
the union.

All sensor-to-point pairs within ``r_s`` come from one ``cKDTree.sparse_distance_matrix`` call; their number
is about ``n * pi r_s^2 / resolution^2`` whatever the zone area, and the count per point gives 1-, k- and
weighted coverage at once.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

__all__ = [
    "CoverageResult",
    "ZoneGrid",
    "area_coverage",
    "check_discs",
    "check_points",
    "cover_counts",
    "cover_pairs",
    "coverage_from_counts",
    "k_coverage",
    "weighted_coverage",
    "weighted_from_covered",
    "zone_grid",
]


class DensityProfile(Protocol):
    """Anything with a vectorised radial density ``density(r)`` (e.g. ``RadialProfile``)."""

    def density(self, r: ArrayLike, /) -> ArrayLike:
        """Density at distances ``r`` from the centre."""
        ...


# A lattice larger than this is almost certainly a unit mistake (e.g. km radii at 1 m pitch).
_MAX_GRID_POINTS = 20_000_000


def check_points(points: ArrayLike, name: str) -> NDArray[np.float64]:
    """Validate an ``(n, 2)`` array of finite planar coordinates.

    Args:
        points: Array-like of shape ``(n, 2)``.
        name: Field name used in error messages.

    Returns:
        The points as a C-contiguous float64 array.

    Raises:
        ValueError: If the shape is not ``(n, 2)`` or a value is not finite.
    """
    arr = np.ascontiguousarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must have shape (n, 2), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must contain finite coordinates")
    return arr


def check_discs(centres: ArrayLike, radii: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Validate zone discs.

    Args:
        centres: ``(K, 2)`` zone centroids in metres, K >= 1.
        radii: ``(K,)`` zone radii in metres, each finite and > 0.

    Returns:
        ``(centres, radii)`` as float64 arrays.

    Raises:
        ValueError: On bad shapes or values.
    """
    c = check_points(centres, "centres")
    r = np.ascontiguousarray(radii, dtype=np.float64).reshape(-1)
    if c.shape[0] == 0:
        raise ValueError("centres must hold at least one zone (K >= 1)")
    if r.shape[0] != c.shape[0]:
        raise ValueError(f"radii must have shape (K,) = ({c.shape[0]},), got {r.shape}")
    if not np.all(np.isfinite(r) & (r > 0.0)):
        raise ValueError("radii must be finite and > 0")
    return c, r


def _check_positive(value: float, name: str) -> float:
    """Return ``value`` as float if finite and > 0, else raise naming ``name``."""
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


@dataclass(frozen=True)
class ZoneGrid:
    """Lattice points sampling the union of zone discs.

    Attributes:
        centres: ``(K, 2)`` zone centroids.
        radii: ``(K,)`` zone radii.
        resolution: Lattice pitch in metres.
        points: ``(P, 2)`` lattice points in the union, each once.
        member: ``(P, K)`` bool, point ``p`` lies in zone ``k`` (``||p - c_k|| <= R_k``).
        tree: KD-tree over ``points`` (built once, reused by every coverage query on this grid).
    """

    centres: NDArray[np.float64]
    radii: NDArray[np.float64]
    resolution: float
    points: NDArray[np.float64]
    member: NDArray[np.bool_]
    tree: cKDTree = field(repr=False, compare=False)

    @property
    def cell_area(self) -> float:
        """Area represented by one lattice point, m^2."""
        return self.resolution * self.resolution


def zone_grid(centres: ArrayLike, radii: ArrayLike, resolution: float = 1.0) -> ZoneGrid:
    """Build the lattice over the union of zone discs.

    Args:
        centres: ``(K, 2)`` zone centroids in metres.
        radii: ``(K,)`` zone radii in metres.
        resolution: Lattice pitch in metres (> 0).

    Returns:
        The grid (read-only arrays; the last few grids are cached, since batch evaluations reuse one zone
        layout). A zone smaller than one cell may hold no lattice point; its coverage is then NaN.

    Raises:
        ValueError: On bad discs, a non-positive resolution, or a lattice above 2e7 points.
    """
    c, r = check_discs(centres, radii)
    h = _check_positive(resolution, "resolution")
    return _cached_grid(c.tobytes(), r.tobytes(), h)


@functools.lru_cache(maxsize=4)
def _cached_grid(centres_key: bytes, radii_key: bytes, h: float) -> ZoneGrid:
    """Build the lattice for validated discs given as raw float64 bytes."""
    c = np.frombuffer(centres_key, dtype=np.float64).reshape(-1, 2)
    r = np.frombuffer(radii_key, dtype=np.float64)
    lo = np.floor((c - r[:, None]) / h).astype(np.int64)
    hi = np.ceil((c + r[:, None]) / h).astype(np.int64)
    total = int(np.prod(hi - lo, axis=1).sum())
    if total > _MAX_GRID_POINTS:
        raise ValueError(f"resolution {h} gives about {total} lattice points (max {_MAX_GRID_POINTS}); raise it")
    chunks = []
    for k in range(c.shape[0]):  # K zones, each vectorised over its bounding box
        xs = (np.arange(lo[k, 0], hi[k, 0]) + 0.5) * h
        ys = (np.arange(lo[k, 1], hi[k, 1]) + 0.5) * h
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        inside = _in_disc(pts, c[k], r[k])
        # Dedupe the union: a lattice point belongs to the first zone containing it. Anchoring the
        # lattice at the origin makes overlapping zones generate bit-identical points.
        for j in range(k):
            inside &= ~_in_disc(pts, c[j], r[j])
        chunks.append(pts[inside])
    points = np.ascontiguousarray(np.concatenate(chunks, axis=0))
    member = np.stack([_in_disc(points, c[k], r[k]) for k in range(c.shape[0])], axis=1)
    for arr in (points, member):
        arr.flags.writeable = False  # shared through the cache
    return ZoneGrid(c, r, h, points, member, cKDTree(points))


def _in_disc(points: NDArray[np.float64], centre: NDArray[np.float64], radius: float) -> NDArray[np.bool_]:
    """Closed-disc test with one fixed expression so that every caller agrees bit for bit."""
    d = points - centre
    return d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] <= radius * radius


def cover_pairs(grid: ZoneGrid, sensors: ArrayLike, r_s: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All (lattice point, sensor) pairs with ``||q - p|| <= r_s``.

    Args:
        grid: Zone lattice.
        sensors: ``(n, 2)`` sensor positions.
        r_s: Sensing radius in metres (> 0).

    Returns:
        ``(point_index, sensor_index)`` int64 arrays of equal length.
    """
    s = check_points(sensors, "sensors")
    r = _check_positive(r_s, "r_s")
    if s.shape[0] == 0 or grid.points.shape[0] == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty
    pairs = cKDTree(s).sparse_distance_matrix(grid.tree, r, output_type="ndarray")
    return pairs["j"].astype(np.int64), pairs["i"].astype(np.int64)


def cover_counts(grid: ZoneGrid, sensors: ArrayLike, r_s: float) -> NDArray[np.int64]:
    """Number of sensors within ``r_s`` of every lattice point.

    Args:
        grid: Zone lattice.
        sensors: ``(n, 2)`` sensor positions.
        r_s: Sensing radius in metres.

    Returns:
        ``(P,)`` int64 counts.
    """
    point_idx, _ = cover_pairs(grid, sensors, r_s)
    return np.bincount(point_idx, minlength=grid.points.shape[0]).astype(np.int64)


@dataclass(frozen=True)
class CoverageResult:
    """Coverage fractions.

    Attributes:
        overall: Fraction of the union of zones (each lattice point once).
        per_zone: ``(K,)`` fraction of each zone (NaN for a zone without lattice points).
    """

    overall: float
    per_zone: NDArray[np.float64]


def _fractions(grid: ZoneGrid, flag: NDArray[np.bool_]) -> CoverageResult:
    """Mean of a per-point flag over the union and over each zone."""
    inside = grid.member.sum(axis=0)
    hits = (grid.member & flag[:, None]).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_zone = np.where(inside > 0, hits / np.maximum(inside, 1), np.nan)
    overall = float(flag.mean()) if flag.size else math.nan
    return CoverageResult(overall, per_zone.astype(np.float64))


def coverage_from_counts(grid: ZoneGrid, counts: NDArray[np.int64], k: int = 1) -> CoverageResult:
    """Fraction of area covered by at least ``k`` sensors, from per-point counts.

    Args:
        grid: Zone lattice.
        counts: ``(P,)`` sensor counts per lattice point (``cover_counts``).
        k: Coverage degree (>= 1).

    Returns:
        Coverage per zone and overall.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k must be an integer >= 1, got {k!r}")
    return _fractions(grid, np.asarray(counts) >= k)


def _region_grid(region: tuple[ArrayLike, ArrayLike] | ZoneGrid, resolution: float) -> ZoneGrid:
    """Accept a prebuilt grid or a ``(centres, radii)`` pair."""
    if isinstance(region, ZoneGrid):
        return region
    if not (isinstance(region, (tuple, list)) and len(region) == 2):
        raise ValueError("region must be a (centres (K, 2), radii (K,)) pair or a ZoneGrid")
    return zone_grid(region[0], region[1], resolution)


def area_coverage(
    sensors: ArrayLike,
    region: tuple[ArrayLike, ArrayLike] | ZoneGrid,
    r_s: float,
    resolution: float = 1.0,
) -> CoverageResult:
    """Binary-disc area coverage of a union of zone discs.

    Args:
        sensors: ``(n, 2)`` sensor positions in metres.
        region: ``(centres (K, 2), radii (K,))`` or a prebuilt ``ZoneGrid`` (then ``resolution`` is ignored).
        r_s: Sensing radius in metres.
        resolution: Lattice pitch in metres.

    Returns:
        Covered fraction per zone and over the union.
    """
    return k_coverage(sensors, region, r_s, 1, resolution)


def k_coverage(
    sensors: ArrayLike,
    region: tuple[ArrayLike, ArrayLike] | ZoneGrid,
    r_s: float,
    k: int,
    resolution: float = 1.0,
) -> CoverageResult:
    """Fraction of area covered by at least ``k`` sensors (Huang and Tseng's k-coverage).

    Args:
        sensors: ``(n, 2)`` sensor positions in metres.
        region: ``(centres (K, 2), radii (K,))`` or a prebuilt ``ZoneGrid``.
        r_s: Sensing radius in metres.
        k: Coverage degree (>= 1).
        resolution: Lattice pitch in metres.

    Returns:
        k-covered fraction per zone and over the union.
    """
    grid = _region_grid(region, resolution)
    return coverage_from_counts(grid, cover_counts(grid, sensors, r_s), k)


def weighted_from_covered(
    grid: ZoneGrid,
    covered: NDArray[np.bool_],
    profiles: Sequence[DensityProfile],
    weights: ArrayLike | None = None,
) -> CoverageResult:
    """Importance-weighted coverage ``int phi 1[covered] / int phi`` per zone, from a per-point flag.

    Each zone uses its own profile density ``phi_k(||q - c_k||)`` over its own lattice points (a point in
    two zones counts in both). The overall value is the ``weights``-weighted mean of the zone values, so
    it does not depend on how each profile is normalised.

    Args:
        grid: Zone lattice.
        covered: ``(P,)`` bool coverage flag per lattice point.
        profiles: K objects with a vectorised ``density(r)`` (e.g. ``RadialProfile``).
        weights: ``(K,)`` zone weights (>= 0, not all 0); default equal.

    Returns:
        Weighted coverage per zone and overall.
    """
    n_zones = grid.centres.shape[0]
    if len(profiles) != n_zones:
        raise ValueError(f"profiles must hold one profile per zone (K = {n_zones}), got {len(profiles)}")
    w = np.ones(n_zones) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape != (n_zones,) or not np.all(np.isfinite(w) & (w >= 0.0)) or w.sum() <= 0.0:
        raise ValueError(f"weights must be {n_zones} finite values >= 0, not all 0")
    per_zone = np.full(n_zones, np.nan)
    for k in range(n_zones):  # K zones; each is vectorised over its lattice points
        idx = np.flatnonzero(grid.member[:, k])
        if idx.size == 0:
            continue
        r = np.hypot(*(grid.points[idx] - grid.centres[k]).T)
        # Cell-centre quadrature; clamping r to half a cell keeps the integrable r^-alpha singularity of
        # a power profile finite when a lattice point falls on the centroid.
        phi = np.asarray(profiles[k].density(np.maximum(r, 0.5 * grid.resolution)), dtype=np.float64)
        total = phi.sum()
        if total > 0.0:
            per_zone[k] = float(phi[covered[idx]].sum() / total)
    ok = np.isfinite(per_zone)
    overall = float(np.sum(w[ok] * per_zone[ok]) / w[ok].sum()) if np.any(ok) and w[ok].sum() > 0 else math.nan
    return CoverageResult(overall, per_zone)


def weighted_coverage(
    sensors: ArrayLike,
    centres: ArrayLike,
    radii: ArrayLike,
    profiles: Sequence[DensityProfile],
    r_s: float,
    resolution: float = 1.0,
    weights: ArrayLike | None = None,
) -> CoverageResult:
    """Coverage weighted by each zone's target density ``phi``: ``int phi 1[covered] / int phi``.

    Args:
        sensors: ``(n, 2)`` sensor positions in metres.
        centres: ``(K, 2)`` zone centroids.
        radii: ``(K,)`` zone radii.
        profiles: K objects with a vectorised ``density(r)``.
        r_s: Sensing radius in metres.
        resolution: Lattice pitch in metres.
        weights: ``(K,)`` zone weights for the overall mean; default equal.

    Returns:
        Weighted coverage per zone and overall.
    """
    grid = zone_grid(centres, radii, resolution)
    covered = cover_counts(grid, sensors, r_s) >= 1
    return weighted_from_covered(grid, covered, profiles, weights)
