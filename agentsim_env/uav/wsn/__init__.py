"""Wireless-sensor-network evaluation of a sensor deployment over circular hot zones.

Coverage (binary disc, k-coverage, density-weighted), unit-disk connectivity to the sink(s), first-order
radio energy, minimum-energy routing lifetime and per-zone density fidelity. ``evaluate_deployment`` returns
all of it as one flat ``dict[str, float]``. Imports numpy, scipy and numba only.
"""

from agentsim_env.uav.wsn.connectivity import (
    ConnectivityResult,
    connectivity,
    sink_edges,
    unit_disk_edges,
    unit_disk_graph,
)
from agentsim_env.uav.wsn.coverage import (
    CoverageResult,
    ZoneGrid,
    area_coverage,
    cover_counts,
    cover_pairs,
    coverage_from_counts,
    k_coverage,
    weighted_coverage,
    weighted_from_covered,
    zone_grid,
)
from agentsim_env.uav.wsn.evaluate import WsnConfig, evaluate_deployment, sink_positions
from agentsim_env.uav.wsn.fidelity import (
    ZoneFidelity,
    assign_zones,
    density_ratio,
    fidelity_per_zone,
    knn_monotonicity,
    radial_ks,
    radial_w1,
    target_density_ratio,
    zone_fidelity,
)
from agentsim_env.uav.wsn.lifetime import (
    LifetimeResult,
    coverage_lifetime,
    routing_tree,
    simulate_lifetime,
)
from agentsim_env.uav.wsn.profiles import GOLDEN_ANGLE, PROFILE_KINDS, RadialProfile
from agentsim_env.uav.wsn.radio import RadioParams, aggregation_energy, rx_energy, tx_energy

__all__ = [
    "GOLDEN_ANGLE",
    "PROFILE_KINDS",
    "ConnectivityResult",
    "CoverageResult",
    "LifetimeResult",
    "RadialProfile",
    "RadioParams",
    "WsnConfig",
    "ZoneFidelity",
    "ZoneGrid",
    "aggregation_energy",
    "area_coverage",
    "assign_zones",
    "connectivity",
    "cover_counts",
    "cover_pairs",
    "coverage_from_counts",
    "coverage_lifetime",
    "density_ratio",
    "evaluate_deployment",
    "fidelity_per_zone",
    "k_coverage",
    "knn_monotonicity",
    "radial_ks",
    "radial_w1",
    "routing_tree",
    "rx_energy",
    "simulate_lifetime",
    "sink_edges",
    "sink_positions",
    "target_density_ratio",
    "tx_energy",
    "unit_disk_edges",
    "unit_disk_graph",
    "weighted_coverage",
    "weighted_from_covered",
    "zone_fidelity",
    "zone_grid",
]
