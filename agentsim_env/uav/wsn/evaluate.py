"""One-call evaluation of a sensor deployment: a flat ``dict[str, float]`` of every WSN metric.

Keys (``{k}`` is the zone index; every call with the same number of zones yields the same keys in the same
order, so rows can go straight to a CSV):

======================================= ==============================================================
key                                     meaning
======================================= ==============================================================
n_sensors, n_zones, n_sinks             sizes
coverage, coverage_k, coverage_weighted binary-disc coverage of the zones' union, k-coverage
                                        (``k = config.k``), density-weighted coverage (mean over zones)
n_components, lcc_fraction              unit-disk graph of the sensors at ``r_c``
sink_reach, hops_mean, hops_max         fraction of sensors with a path to a sink; hop counts
fiedler                                 algebraic connectivity (NaN unless ``n <= fiedler_max_n``)
fnd, hnd, lnd, fnd_static               lifetime in rounds (``lifetime.py`` gives exact definitions)
coverage_lifetime                       rounds until connected coverage < threshold x initial
n_population                            sensors connected to a sink at round 0
ks_mean, w1_mean, centroid_bias_mean    fidelity metrics averaged over zones holding sensors
containment                             fraction of all sensors inside their assigned zone
landing_error_mean, landing_error_p95   over all sensors (NaN without ``targets_xy``)
zone{k}.coverage, .coverage_k,          per-zone coverage
zone{k}.coverage_weighted
zone{k}.sink_reach, .coverage_lifetime  per-zone reach and coverage lifetime
zone{k}.<ZoneFidelity field>            n, ks, ks_pvalue, w1, density_ratio, density_ratio_target,
                                        monotonicity, monotonicity_target, centroid_bias, containment,
                                        landing_error_mean, landing_error_p95
======================================= ==============================================================
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import field
from typing import Annotated, Any, ClassVar, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from agentsim_env.core.config_model import FieldError, Int, Real, Text, config
from agentsim_env.uav.wsn.connectivity import connectivity, unit_disk_edges
from agentsim_env.uav.wsn.coverage import (
    DensityProfile,
    check_discs,
    check_points,
    cover_pairs,
    coverage_from_counts,
    weighted_from_covered,
    zone_grid,
)
from agentsim_env.uav.wsn.fidelity import CdfProfile, assign_zones, fidelity_per_zone
from agentsim_env.uav.wsn.lifetime import coverage_lifetime, simulate_lifetime
from agentsim_env.uav.wsn.radio import RadioParams

__all__ = ["WsnConfig", "evaluate_deployment", "sink_positions"]


class ZoneProfile(DensityProfile, CdfProfile, Protocol):
    """A target profile with a vectorised ``density(r)`` and ``cdf(r)`` (e.g. ``RadialProfile``)."""


Positive = Annotated[Real, Field(gt=0.0)]
"""A finite number > 0."""


@config("wsn")
class WsnConfig:
    """Evaluation settings.

    Attributes:
        r_s: Sensing radius in metres.
        r_c: Communication range in metres.
        radio: Radio constants (packet length, initial energy ``e0``).
        sink: ``"centroid"`` (one mains-powered sink at every zone centroid) or ``(x, y)`` of one base
            station, or a tuple of such pairs for several.
        coverage_resolution: Lattice pitch of the coverage grid in metres.
        k: Degree for k-coverage (>= 1).
        coverage_lifetime_threshold: Fraction of the initial connected coverage, in (0, 1].
        knn_k: Neighbour rank of the k-NN density in the monotonicity metric (>= 1).
        fiedler_max_n: Compute the Fiedler value only up to this many sensors (dense O(n^3)); 0 disables.
        zone_weights: Zone weights for the overall weighted coverage, or ``None`` for equal weights.
    """

    nested: ClassVar[dict[str, type]] = {"radio": RadioParams}

    r_s: Positive = 10.0
    r_c: Positive = 25.0
    radio: RadioParams = field(default_factory=RadioParams)
    sink: Text | tuple[Any, ...] = "centroid"  # "centroid", (x, y) or a tuple of (x, y): see sink_positions
    coverage_resolution: Positive = 1.0
    k: Annotated[Int, Field(ge=1)] = 2
    coverage_lifetime_threshold: Annotated[Real, Field(gt=0.0, le=1.0)] = 0.9
    knn_k: Annotated[Int, Field(ge=1)] = 5
    fiedler_max_n: Annotated[Int, Field(ge=0)] = 300
    zone_weights: tuple[Real, ...] | None = None

    def __post_init__(self) -> None:
        """The sink: ``"centroid"`` or positions."""
        if isinstance(self.sink, str):
            if self.sink != "centroid":
                raise FieldError("sink", f"must be 'centroid', (x, y) or a tuple of (x, y), got {self.sink!r}")
        else:
            sink_positions(self.sink, np.zeros((1, 2)))  # raises on a malformed position


def sink_positions(sink: str | tuple | ArrayLike, centres: ArrayLike) -> NDArray[np.float64]:
    """Resolve a ``WsnConfig.sink`` value to an ``(m, 2)`` array of sink positions.

    Args:
        sink: ``"centroid"``, ``(x, y)`` or a sequence of ``(x, y)``.
        centres: ``(K, 2)`` zone centroids (used by ``"centroid"``).

    Returns:
        ``(m, 2)`` float64 positions.
    """
    if isinstance(sink, str):
        if sink != "centroid":
            raise ValueError(f"sink must be 'centroid', (x, y) or a tuple of (x, y), got {sink!r}")
        return check_points(centres, "centres")
    arr = np.asarray(sink, dtype=np.float64)
    if arr.shape == (2,):
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0 or not np.all(np.isfinite(arr)):
        raise ValueError(f"sink must be 'centroid', (x, y) or a tuple of (x, y), got {sink!r}")
    return arr


def _mean(values: list[float]) -> float:
    """Mean of the finite values, NaN if none."""
    arr = np.asarray(values, dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    return float(arr.mean()) if arr.size else math.nan


def evaluate_deployment(
    land_xy: ArrayLike,
    zone_of: ArrayLike | None,
    centres: ArrayLike,
    radii: ArrayLike,
    profiles: Sequence[ZoneProfile],
    config: WsnConfig = WsnConfig(),  # noqa: B008 - frozen, immutable default
    targets_xy: ArrayLike | None = None,
) -> dict[str, float]:
    """Evaluate coverage, connectivity, lifetime and density fidelity of one deployment.

    Args:
        land_xy: ``(n, 2)`` landing positions in metres.
        zone_of: ``(n,)`` intended zone of each sensor in ``[-1, K)``; -1 (or ``None`` for all) assigns the
            nearest zone.
        centres: ``(K, 2)`` zone centroids.
        radii: ``(K,)`` zone radii.
        profiles: K target profiles (``density``, ``cdf``; ``low_discrepancy`` optional).
        config: Evaluation settings.
        targets_xy: ``(n, 2)`` intended landing points, or ``None``.

    Returns:
        Flat mapping of metric name to float (see the module docstring for the keys).
    """
    land = check_points(land_xy, "land_xy")
    c, r = check_discs(centres, radii)
    n, n_zones = land.shape[0], c.shape[0]
    if len(profiles) != n_zones:
        raise ValueError(f"profiles must hold one profile per zone (K = {n_zones}), got {len(profiles)}")
    zone = assign_zones(land, c, r, zone_of)
    sinks = sink_positions(config.sink, c)

    grid = zone_grid(c, r, config.coverage_resolution)
    pairs = cover_pairs(grid, land, config.r_s)
    counts = np.bincount(pairs[0], minlength=grid.points.shape[0])
    cov = coverage_from_counts(grid, counts, 1)
    cov_k = coverage_from_counts(grid, counts, config.k)
    cov_w = weighted_from_covered(grid, counts >= 1, profiles, config.zone_weights)

    edges = unit_disk_edges(land, config.r_c)
    conn = connectivity(land, config.r_c, sinks, config.fiedler_max_n, edges)
    life = simulate_lifetime(land, sinks, config.r_c, config.radio, edges=edges)
    cov_life = coverage_lifetime(grid, land, config.r_s, life.death_round, config.coverage_lifetime_threshold, pairs)
    fid = fidelity_per_zone(land, zone, c, r, profiles, targets_xy, config.knn_k)

    reach = np.isfinite(conn.hops)
    inside = np.linalg.norm(land - c[zone], axis=1) <= r[zone] if n else np.zeros(0, dtype=bool)
    err_mean = err_p95 = math.nan
    if targets_xy is not None and n:
        err = np.linalg.norm(land - check_points(targets_xy, "targets_xy"), axis=1)
        err_mean, err_p95 = float(err.mean()), float(np.percentile(err, 95.0))

    out: dict[str, float] = {
        "n_sensors": float(n),
        "n_zones": float(n_zones),
        "n_sinks": float(sinks.shape[0]),
        "coverage": cov.overall,
        "coverage_k": cov_k.overall,
        "coverage_weighted": cov_w.overall,
        "n_components": float(conn.n_components),
        "lcc_fraction": conn.lcc_fraction,
        "sink_reach": conn.sink_reach,
        "hops_mean": conn.hops_mean,
        "hops_max": conn.hops_max,
        "fiedler": conn.fiedler,
        "fnd": life.fnd,
        "hnd": life.hnd,
        "lnd": life.lnd,
        "fnd_static": life.fnd_static,
        "coverage_lifetime": cov_life.overall,
        "n_population": float(life.n_population),
        "ks_mean": _mean([f.ks for f in fid]),
        "w1_mean": _mean([f.w1 for f in fid]),
        "centroid_bias_mean": _mean([f.centroid_bias for f in fid]),
        "containment": float(inside.mean()) if n else math.nan,
        "landing_error_mean": err_mean,
        "landing_error_p95": err_p95,
    }
    for k in range(n_zones):
        mine = zone == k
        out[f"zone{k}.coverage"] = float(cov.per_zone[k])
        out[f"zone{k}.coverage_k"] = float(cov_k.per_zone[k])
        out[f"zone{k}.coverage_weighted"] = float(cov_w.per_zone[k])
        out[f"zone{k}.sink_reach"] = float(reach[mine].mean()) if mine.any() else math.nan
        out[f"zone{k}.coverage_lifetime"] = float(cov_life.per_zone[k])
        for key, value in fid[k].as_dict().items():
            out[f"zone{k}.{key}"] = value
    return out
