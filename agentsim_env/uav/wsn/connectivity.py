"""Unit-disk connectivity of a deployment and its reachability to the sink(s).

Sensors ``i`` and ``j`` share a link when ``||p_i - p_j|| <= r_c``. Sinks (zone centroids or a base station)
are extra, mains-powered nodes linked to every sensor within ``r_c``; with several sinks a sensor needs a path
to any one of them. Components and the largest connected component are counted over sensors only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from agentsim_env.uav.wsn.coverage import check_points

__all__ = ["ConnectivityResult", "connectivity", "sink_edges", "unit_disk_edges", "unit_disk_graph"]


def _check_range(r_c: float) -> float:
    """Validate the communication range."""
    r = float(r_c)
    if not (math.isfinite(r) and r > 0.0):
        raise ValueError(f"r_c must be a finite number > 0, got {r_c!r}")
    return r


def unit_disk_edges(points: ArrayLike, r_c: float) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Undirected links of the unit-disk graph.

    Args:
        points: ``(n, 2)`` node positions in metres.
        r_c: Communication range in metres (> 0).

    Returns:
        ``(pairs (E, 2) with i < j, lengths (E,))``.
    """
    p = check_points(points, "points")
    r = _check_range(r_c)
    if p.shape[0] < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    pairs = cKDTree(p).query_pairs(r, output_type="ndarray").astype(np.int64)
    lengths = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]], axis=1)
    return pairs, lengths


def sink_edges(
    points: ArrayLike, sinks: ArrayLike, r_c: float
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Links between sensors and sinks within ``r_c``.

    Args:
        points: ``(n, 2)`` sensor positions.
        sinks: ``(m, 2)`` sink positions.
        r_c: Communication range in metres.

    Returns:
        ``(sensor_index, sink_index, lengths)``, each of shape ``(L,)``.
    """
    p = check_points(points, "points")
    s = check_points(sinks, "sinks")
    r = _check_range(r_c)
    if p.shape[0] == 0 or s.shape[0] == 0:
        z = np.zeros(0, dtype=np.int64)
        return z, z, np.zeros(0)
    sdm = cKDTree(p).sparse_distance_matrix(cKDTree(s), r, output_type="ndarray")
    i, j = sdm["i"].astype(np.int64), sdm["j"].astype(np.int64)
    # Recompute lengths rather than trust sdm's values: a coincident sensor/sink pair must stay a link
    # even though its length is 0.
    return i, j, np.linalg.norm(p[i] - s[j], axis=1)


def unit_disk_graph(points: ArrayLike, r_c: float) -> sparse.csr_matrix:
    """Symmetric 0/1 adjacency matrix of the unit-disk graph (ones, so coincident nodes stay linked).

    Args:
        points: ``(n, 2)`` node positions.
        r_c: Communication range in metres.

    Returns:
        ``(n, n)`` CSR matrix.
    """
    p = check_points(points, "points")
    pairs, _ = unit_disk_edges(p, r_c)
    return _adjacency(p.shape[0], pairs)


def _adjacency(n: int, pairs: NDArray[np.int64]) -> sparse.csr_matrix:
    """Symmetric 0/1 CSR adjacency from undirected pairs."""
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    return sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))


@dataclass(frozen=True)
class ConnectivityResult:
    """Connectivity metrics of a deployment.

    Attributes:
        n_components: Number of connected components of the sensor graph (isolated sensors count).
        lcc_fraction: Size of the largest component over the number of sensors.
        sink_reach: Fraction of sensors with a path to a sink.
        hops_mean: Mean hop count to the nearest sink over the sensors that reach one (NaN if none).
        hops_max: Maximum such hop count (NaN if none).
        fiedler: Algebraic connectivity (second-smallest Laplacian eigenvalue) of the sensor graph; NaN
            when not computed. It is 0 exactly when the graph is disconnected.
        labels: ``(n,)`` component label of each sensor.
        hops: ``(n,)`` hop count to the nearest sink, ``inf`` when unreachable.
    """

    n_components: int
    lcc_fraction: float
    sink_reach: float
    hops_mean: float
    hops_max: float
    fiedler: float
    labels: NDArray[np.int64]
    hops: NDArray[np.float64]


def connectivity(
    sensors: ArrayLike,
    r_c: float,
    sinks: ArrayLike | None = None,
    fiedler_max_n: int = 0,
    edges: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
) -> ConnectivityResult:
    """Components, sink reachability and hop counts of the unit-disk graph.

    Args:
        sensors: ``(n, 2)`` sensor positions in metres.
        r_c: Communication range in metres.
        sinks: ``(m, 2)`` sink positions; ``None`` means no sink (reach 0, hops NaN).
        fiedler_max_n: Compute the Fiedler value with a dense eigensolver when ``2 <= n <= fiedler_max_n``
            (O(n^3): keep it to a few hundred); otherwise it is NaN.
        edges: Precomputed ``unit_disk_edges(sensors, r_c)`` to share with other metrics.

    Returns:
        The metrics.
    """
    p = check_points(sensors, "sensors")
    r = _check_range(r_c)
    s = np.zeros((0, 2)) if sinks is None else check_points(sinks, "sinks")
    n, m = p.shape[0], s.shape[0]
    if n == 0:
        empty = np.zeros(0)
        return ConnectivityResult(0, math.nan, math.nan, math.nan, math.nan, math.nan, empty.astype(np.int64), empty)
    pairs = unit_disk_edges(p, r)[0] if edges is None else edges[0]
    adj = _adjacency(n, pairs)
    n_comp, labels = csgraph.connected_components(adj, directed=False)
    lcc = float(np.bincount(labels).max() / n)

    hops = np.full(n, np.inf)
    if m > 0:
        si, sj, _ = sink_edges(p, s, r)
        both = np.concatenate([pairs, np.stack([si, n + sj], axis=1)], axis=0)
        dist = csgraph.dijkstra(
            _adjacency(n + m, both),
            directed=False,
            indices=np.arange(n, n + m),
            unweighted=True,
            min_only=True,
        )
        hops = np.asarray(dist[:n], dtype=np.float64)
    reach = np.isfinite(hops)
    hops_mean = float(hops[reach].mean()) if reach.any() else math.nan
    hops_max = float(hops[reach].max()) if reach.any() else math.nan

    fiedler = math.nan
    if 2 <= n <= int(fiedler_max_n):
        lap = csgraph.laplacian(adj).toarray()
        # Exactly 0 when disconnected; otherwise clip eigensolver round-off.
        fiedler = 0.0 if n_comp > 1 else float(max(np.linalg.eigvalsh(lap)[1], 0.0))
    return ConnectivityResult(
        int(n_comp), lcc, float(reach.mean()), hops_mean, hops_max, fiedler, labels.astype(np.int64), hops
    )
