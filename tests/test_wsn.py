"""WSN deployment evaluator: every metric against an independent oracle.

Oracles: the domain reference's radio table, networkx (components, hop counts, Dijkstra, Laplacian spectrum),
Monte-Carlo points and the Poisson coverage formula, hand-computed lifetimes on a chain, a plain scipy
re-implementation of the lifetime simulation, and closed-form fidelity cases.
"""

from __future__ import annotations

import math

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats
from scipy.spatial import cKDTree

from agentsim_env.uav.wsn import (
    RadialProfile,
    RadioParams,
    WsnConfig,
    area_coverage,
    assign_zones,
    connectivity,
    coverage_lifetime,
    evaluate_deployment,
    k_coverage,
    radial_ks,
    radial_w1,
    routing_tree,
    rx_energy,
    simulate_lifetime,
    target_density_ratio,
    tx_energy,
    weighted_coverage,
    zone_fidelity,
    zone_grid,
)
from tests.reference.wsn import simulate_lifetime_reference

K_BITS = 4000
RADIO = RadioParams()


# ---------------------------------------------------------------------------------------------- radio
@pytest.mark.parametrize(("d", "micro_joules"), [(10.0, 204.0), (30.0, 236.0), (50.0, 300.0), (100.0, 720.0)])
def test_tx_energy_matches_domain_table(d: float, micro_joules: float) -> None:
    assert float(tx_energy(K_BITS, d)) * 1e6 == pytest.approx(micro_joules, rel=1e-9)


def test_rx_energy_crossover_and_vectorised_tx() -> None:
    assert float(rx_energy(K_BITS)) * 1e6 == pytest.approx(200.0, rel=1e-12)
    assert RADIO.d0 == pytest.approx(87.7, abs=0.05)
    assert float(tx_energy(K_BITS, 150.0)) * 1e3 == pytest.approx(2.83, abs=0.005)
    d = np.array([[0.0, 10.0], [RADIO.d0, 100.0]])
    out = tx_energy(K_BITS, d)
    assert out.shape == (2, 2)
    # The two regimes meet at d0 (eps_fs d0^2 == eps_mp d0^4), so the cost is continuous there.
    below = float(tx_energy(K_BITS, RADIO.d0 * (1 - 1e-12)))
    assert out[1, 0] == pytest.approx(below, rel=1e-9)


def test_radio_params_validation_names_field() -> None:
    with pytest.raises(ValueError, match="e_elec"):
        RadioParams(e_elec=0.0)
    with pytest.raises(ValueError, match="packet_bits"):
        RadioParams(packet_bits=0)
    with pytest.raises(ValueError, match="e0"):
        RadioParams(e0=-1.0)


# ---------------------------------------------------------------------------------------------- connectivity
def _nx_graph(points: np.ndarray, r_c: float, sinks: np.ndarray) -> nx.Graph:
    """Brute-force unit-disk graph with sinks as nodes ('s', j)."""
    g = nx.Graph()
    g.add_nodes_from(range(len(points)))
    d = np.linalg.norm(points[:, None] - points[None], axis=2)
    for i, j in zip(*np.nonzero(np.triu(d <= r_c, 1)), strict=True):
        g.add_edge(int(i), int(j))
    for j, s in enumerate(sinks):
        g.add_node(("s", j))
        for i in np.flatnonzero(np.linalg.norm(points - s, axis=1) <= r_c):
            g.add_edge(int(i), ("s", j))
    return g


@given(seed=st.integers(0, 10_000), n=st.integers(1, 70), r_c=st.floats(5.0, 40.0), m=st.integers(1, 3))
@settings(max_examples=40, deadline=None)
def test_connectivity_matches_networkx(seed: int, n: int, r_c: float, m: int) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0.0, 100.0, (n, 2))
    sinks = rng.uniform(0.0, 100.0, (m, 2))
    res = connectivity(pts, r_c, sinks)
    g = _nx_graph(pts, r_c, sinks)
    sensors_only = g.subgraph(range(n))
    comps = list(nx.connected_components(sensors_only))
    assert res.n_components == len(comps)
    assert res.lcc_fraction == pytest.approx(max(len(c) for c in comps) / n)
    g.add_node("super")
    for j in range(m):
        g.add_edge("super", ("s", j))
    lengths = nx.single_source_shortest_path_length(g, "super")
    hops = np.array([lengths.get(i, math.inf) - 1 for i in range(n)], dtype=float)
    np.testing.assert_array_equal(res.hops, hops)
    assert res.sink_reach == pytest.approx(np.isfinite(hops).mean())
    if np.isfinite(hops).any():
        assert res.hops_mean == pytest.approx(hops[np.isfinite(hops)].mean())
        assert res.hops_max == hops[np.isfinite(hops)].max()


def test_fiedler_matches_laplacian_spectrum() -> None:
    rng = np.random.default_rng(3)
    pts = rng.uniform(0.0, 60.0, (40, 2))
    res = connectivity(pts, 25.0, fiedler_max_n=100)
    g = _nx_graph(pts, 25.0, np.zeros((0, 2)))
    expected = np.sort(nx.laplacian_spectrum(g))[1]
    assert res.fiedler == pytest.approx(max(expected, 0.0), abs=1e-9)
    assert connectivity(pts, 25.0).fiedler != connectivity(pts, 25.0).fiedler  # NaN when not asked for
    split = np.vstack([pts, pts + 1000.0])
    assert connectivity(split, 25.0, fiedler_max_n=100).fiedler == 0.0


# ---------------------------------------------------------------------------------------------- routing
def _edge_cost(d: float, into_sink: bool) -> float:
    return float(tx_energy(K_BITS, d)) + (0.0 if into_sink else float(rx_energy(K_BITS)))


@given(seed=st.integers(0, 10_000), n=st.integers(2, 60), m=st.integers(1, 2))
@settings(max_examples=30, deadline=None)
def test_min_energy_routes_match_networkx_dijkstra(seed: int, n: int, m: int) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0.0, 100.0, (n, 2))
    sinks = rng.uniform(20.0, 80.0, (m, 2))
    r_c = 30.0
    cost, parent, _ = routing_tree(pts, sinks, r_c)
    dg = nx.DiGraph()
    everything = np.vstack([pts, sinks])
    for u in range(n):
        for v in range(n + m):
            d = float(np.linalg.norm(everything[u] - everything[v]))
            if u != v and d <= r_c:
                dg.add_edge(u, v, weight=_edge_cost(d, v >= n))
    dg.add_nodes_from(range(n + m))
    dist = nx.multi_source_dijkstra_path_length(dg.reverse(), set(range(n, n + m)))
    expected = np.array([dist.get(i, math.inf) for i in range(n)])
    np.testing.assert_allclose(cost, expected, rtol=1e-12)
    for u in np.flatnonzero(np.isfinite(cost)):  # each parent edge lies on a shortest path
        p = parent[u]
        step = _edge_cost(float(np.linalg.norm(everything[u] - everything[p])), p >= n)
        assert cost[u] == pytest.approx(step + (0.0 if p >= n else cost[p]), rel=1e-12)


# ---------------------------------------------------------------------------------------------- lifetime
def _chain(length: int, spacing: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    xs = spacing * np.arange(1, length + 1, dtype=float)
    return np.stack([xs, np.zeros(length)], axis=1), np.zeros((1, 2))


def test_chain_lifetime_matches_closed_form() -> None:
    """Sensors every 10 m on a line to the sink, r_c = 15 m: each node relays everything behind it."""
    length = 6
    pts, sink = _chain(length)
    e_tx, e_rx = float(tx_energy(K_BITS, 10.0)), float(rx_energy(K_BITS))
    load_first = length * e_tx + (length - 1) * e_rx
    res = simulate_lifetime(pts, sink, 15.0)
    assert res.fnd == math.floor(0.5 / load_first)
    assert res.fnd_static == pytest.approx(0.5 / load_first)
    # The sink's only neighbour dies first and cuts everyone else off in the same round.
    assert res.hnd == res.lnd == res.fnd
    assert list(res.cause) == [1] + [2] * (length - 1)

    # Give the first node 10 J: the second dies first, then the first runs alone until it is empty.
    e0 = np.full(length, 0.5)
    e0[0] = 10.0
    res = simulate_lifetime(pts, sink, 15.0, e0=e0)
    load_second = (length - 1) * e_tx + (length - 2) * e_rx
    fnd = math.floor(0.5 / load_second)
    assert fnd < 10.0 / load_first
    assert res.fnd == fnd
    assert res.death_round[0] == fnd + math.floor((10.0 - fnd * load_first) / e_tx)
    assert res.lnd == res.death_round[0]
    assert res.hnd == fnd


def test_doubling_e0_doubles_fnd() -> None:
    rng = np.random.default_rng(11)
    pts = rng.uniform(0.0, 120.0, (150, 2))
    sink = np.array([[60.0, 60.0]])
    one = simulate_lifetime(pts, sink, 25.0, RadioParams(e0=0.5))
    two = simulate_lifetime(pts, sink, 25.0, RadioParams(e0=1.0))
    assert one.fnd > 0
    assert two.fnd_static == pytest.approx(2.0 * one.fnd_static, rel=1e-12)
    assert two.fnd in (2 * one.fnd, 2 * one.fnd + 1)  # floor(2x) is 2 floor(x) or one more
    assert two.lnd >= one.lnd


@given(seed=st.integers(0, 10_000), n=st.integers(1, 60), m=st.integers(1, 2), r_c=st.floats(12.0, 35.0))
@settings(max_examples=30, deadline=None)
def test_lifetime_kernel_matches_reference_and_is_ordered(seed: int, n: int, m: int, r_c: float) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0.0, 80.0, (n, 2))
    sinks = rng.uniform(20.0, 60.0, (m, 2))
    e0 = rng.uniform(0.2, 1.0, n)
    fast = simulate_lifetime(pts, sinks, r_c, e0=e0)
    ref = simulate_lifetime_reference(pts, sinks, r_c, e0=e0)
    np.testing.assert_array_equal(fast.death_round, ref.death_round)
    np.testing.assert_array_equal(fast.cause, ref.cause)
    assert (fast.fnd, fast.hnd, fast.lnd) == (ref.fnd, ref.hnd, ref.lnd)
    assert fast.fnd_static == pytest.approx(ref.fnd_static, rel=1e-12)
    assert fast.fnd <= fast.hnd <= fast.lnd
    if fast.n_population:
        assert fast.fnd == math.floor(fast.fnd_static * (1 + 1e-12))  # nothing changes before the first death


def test_coverage_lifetime_matches_brute_force() -> None:
    rng = np.random.default_rng(5)
    centres, radii = np.array([[50.0, 50.0]]), np.array([40.0])
    pts = centres + RadialProfile("gauss", 40.0).sample(120, rng)
    life = simulate_lifetime(pts, centres, 20.0)
    grid = zone_grid(centres, radii, 1.0)
    got = coverage_lifetime(grid, pts, 8.0, life.death_round, 0.9)
    c0 = area_coverage(pts[life.death_round > 0], grid, 8.0).overall
    expected = math.nan
    for t in np.unique(life.death_round):
        if area_coverage(pts[life.death_round > t], grid, 8.0).overall < 0.9 * c0:
            expected = float(t)
            break
    assert got.overall == expected
    assert life.fnd <= got.overall <= life.lnd


# ---------------------------------------------------------------------------------------------- coverage
def test_area_and_k_coverage_match_monte_carlo() -> None:
    rng = np.random.default_rng(1)
    centres, radii = np.array([[0.0, 0.0], [30.0, 10.0]]), np.array([25.0, 20.0])
    pts = rng.uniform(-30.0, 55.0, (70, 2))
    r_s, res = 6.0, 0.25
    mc = rng.uniform([-25.0, -25.0], [55.0, 35.0], (300_000, 2))
    inside = np.stack([np.linalg.norm(mc - c, axis=1) <= r for c, r in zip(centres, radii, strict=True)], 1)
    union = inside.any(axis=1)
    counts = np.array([len(x) for x in cKDTree(pts).query_ball_point(mc, r_s)])
    for k, got in (
        (1, area_coverage(pts, (centres, radii), r_s, res)),
        (2, k_coverage(pts, (centres, radii), r_s, 2, res)),
    ):
        for mask, value in [
            (union, got.overall),
            (inside[:, 0], got.per_zone[0]),
            (inside[:, 1], got.per_zone[1]),
        ]:
            p_hat = (counts[mask] >= k).mean()
            se = math.sqrt(p_hat * (1 - p_hat) / mask.sum())
            assert abs(value - p_hat) < 4 * se + 0.002  # MC error + lattice error at 0.25 m pitch


def test_coverage_matches_poisson_formula() -> None:
    """A Poisson deployment of intensity lambda covers 1 - exp(-lambda pi r_s^2) of the area."""
    big_r, r_s, mu = 150.0, 3.0, 1.0
    lam = mu / (math.pi * r_s * r_s)
    values = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        # Deploy beyond the zone edge by r_s so that border points see the same intensity.
        n = rng.poisson(lam * math.pi * (big_r + r_s) ** 2)
        pts = RadialProfile("uniform", big_r + r_s).sample(n, rng)
        values.append(area_coverage(pts, (np.zeros((1, 2)), np.array([big_r])), r_s, 0.5).overall)
    se = np.std(values, ddof=1) / math.sqrt(len(values))
    assert abs(np.mean(values) - (1 - math.exp(-mu))) < 4 * se + 0.002


def test_weighted_coverage_matches_importance_sampling() -> None:
    rng = np.random.default_rng(2)
    centres, radii = np.array([[0.0, 0.0], [200.0, 0.0]]), np.array([40.0, 30.0])
    profiles = [RadialProfile("gauss", 40.0, sigma=12.0), RadialProfile("uniform", 30.0)]
    pts = np.vstack([rng.uniform(-40, 40, (50, 2)), centres[1] + rng.uniform(-30, 30, (40, 2))])
    got = weighted_coverage(pts, centres, radii, profiles, 7.0, resolution=0.25)
    tree = cKDTree(pts)
    per_zone = []
    for k, prof in enumerate(profiles):
        q = centres[k] + prof.sample(200_000, rng)  # points drawn with density phi
        p_hat = float((tree.query(q, distance_upper_bound=7.0)[0] <= 7.0).mean())
        assert abs(got.per_zone[k] - p_hat) < 4 * math.sqrt(p_hat * (1 - p_hat) / q.shape[0]) + 0.003
        per_zone.append(got.per_zone[k])
    assert got.overall == pytest.approx(np.mean(per_zone))
    # With a uniform profile the weighting is flat: weighted coverage equals area coverage.
    assert got.per_zone[1] == pytest.approx(area_coverage(pts, (centres, radii), 7.0, 0.25).per_zone[1], abs=1e-9)


def test_zone_grid_counts_overlap_once() -> None:
    one = zone_grid(np.array([[0.0, 0.0]]), np.array([10.0]), 0.5)
    twice = zone_grid(np.array([[0.0, 0.0], [0.0, 0.0]]), np.array([10.0, 10.0]), 0.5)
    assert twice.points.shape == one.points.shape
    assert one.points.shape[0] * 0.25 == pytest.approx(math.pi * 100.0, rel=0.01)
    with pytest.raises(ValueError, match="resolution"):
        zone_grid(np.array([[0.0, 0.0]]), np.array([10.0]), 0.0)


# ---------------------------------------------------------------------------------------------- fidelity
def test_fidelity_small_for_profile_samples_large_for_wrong_profile() -> None:
    rng = np.random.default_rng(7)
    gauss = RadialProfile("gauss", 50.0, sigma=15.0)
    good = zone_fidelity(gauss.sample(2000, rng), (0.0, 0.0), 50.0, gauss)
    bad = zone_fidelity(RadialProfile("uniform", 50.0).sample(2000, rng), (0.0, 0.0), 50.0, gauss)
    assert good.ks < 0.04 and good.ks_pvalue > 1e-3 and good.w1 < 0.02
    assert bad.ks > 0.2 and bad.ks_pvalue < 1e-10 and bad.w1 > 0.05
    assert good.monotonicity < -0.3 and good.monotonicity_target < -0.3
    assert good.density_ratio == pytest.approx(good.density_ratio_target, rel=0.25)
    assert bad.density_ratio == pytest.approx(1.0, rel=0.25)


def test_radial_ks_and_w1_closed_forms() -> None:
    rng = np.random.default_rng(8)
    uni = RadialProfile("uniform", 10.0)
    r = 10.0 * np.sqrt(rng.random(300))
    stat, pvalue = radial_ks(r, uni)
    ref = stats.kstest(r, uni.cdf)
    assert stat == pytest.approx(ref.statistic, abs=1e-12)
    assert pvalue == pytest.approx(ref.pvalue, rel=1e-9)
    # Every sensor at R/2 against the uniform law: int_0^1/2 x^2 dx + int_1/2^1 (1 - x^2) dx = 1/4.
    assert radial_w1(np.full(50, 5.0), uni, 10.0) == pytest.approx(0.25, abs=1e-6)
    # 1/r density: inner and outer rings hold a third of the mass each, areas 1/9 and 5/9.
    assert target_density_ratio(RadialProfile("power", 10.0, alpha=1.0), 10.0) == pytest.approx(5.0)
    assert target_density_ratio(uni, 10.0) == pytest.approx(1.0)


def test_containment_centroid_bias_and_landing_error() -> None:
    prof = RadialProfile("uniform", 10.0)
    ring = 4.0 * np.stack([np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)], axis=1)
    centred = zone_fidelity(ring, (0.0, 0.0), 10.0, prof)
    assert centred.centroid_bias == pytest.approx(0.0, abs=1e-12)
    assert centred.containment == 1.0
    shifted = zone_fidelity(ring + [5.0, 0.0], (0.0, 0.0), 10.0, prof, targets=ring + [2.0, -4.0])
    assert shifted.centroid_bias == pytest.approx(0.5)
    assert shifted.containment == 1.0
    assert shifted.landing_error_mean == pytest.approx(5.0)
    assert shifted.landing_error_p95 == pytest.approx(5.0)
    half_out = np.vstack([ring, ring * 3.0])  # radius 12 > 10
    assert zone_fidelity(half_out, (0.0, 0.0), 10.0, prof).containment == 0.5


def test_assign_zones_uses_nearest_disc_for_missing() -> None:
    centres, radii = np.array([[0.0, 0.0], [100.0, 0.0]]), np.array([10.0, 40.0])
    pts = np.array([[0.0, 0.0], [40.0, 0.0], [70.0, 0.0], [1.0, 0.0]])
    # (40, 0) is 30 m from disc 0's edge but 20 m from disc 1's: nearest disc, not nearest centre.
    np.testing.assert_array_equal(assign_zones(pts, centres, radii, [-1, -1, -1, 1]), [0, 1, 1, 1])
    with pytest.raises(ValueError, match="zone_of"):
        assign_zones(pts, centres, radii, [0, 0, 0, 2])


# ---------------------------------------------------------------------------------------------- evaluate
def _deployment(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]:
    rng = np.random.default_rng(seed)
    centres, radii = np.array([[0.0, 0.0], [160.0, 20.0]]), np.array([60.0, 45.0])
    profiles = [RadialProfile("gauss", 60.0, floor=0.1), RadialProfile("power", 45.0, alpha=1.0)]
    zone = np.arange(n) % 2
    targets = np.vstack([centres[k] + profiles[k].sample(1, rng) for k in zone]) if n else np.zeros((0, 2))
    return targets + rng.normal(0.0, 1.5, targets.shape), zone, centres, radii, profiles


def test_evaluate_deployment_flat_dict() -> None:
    land, zone, centres, radii, profiles = _deployment(400, 0)
    out = evaluate_deployment(land, zone, centres, radii, profiles, WsnConfig(), targets_xy=land)
    again = evaluate_deployment(land, zone, centres, radii, profiles, WsnConfig(), targets_xy=land)
    assert out == again  # deterministic
    assert all(isinstance(v, float) for v in out.values())
    for key in ("coverage", "coverage_k", "coverage_weighted", "lcc_fraction", "sink_reach", "containment"):
        assert 0.0 <= out[key] <= 1.0, key
    assert out["coverage_k"] <= out["coverage"]
    assert out["fnd"] <= out["hnd"] <= out["lnd"]
    assert out["fnd"] <= out["coverage_lifetime"] <= out["lnd"]
    assert out["landing_error_mean"] == 0.0
    assert out["zone0.n"] + out["zone1.n"] == 400
    assert out["fiedler"] != out["fiedler"]  # n > fiedler_max_n: NaN
    cov = area_coverage(land, (centres, radii), 10.0)
    assert out["zone1.coverage"] == pytest.approx(cov.per_zone[1])
    # Same keys, same order, for any deployment over the same zones, including an empty one.
    empty = evaluate_deployment(np.zeros((0, 2)), np.zeros(0, int), centres, radii, profiles)
    assert list(empty) == list(out)
    assert empty["coverage"] == 0.0 and empty["fnd"] == 0.0


def test_config_validation_names_field() -> None:
    with pytest.raises(ValueError, match="r_s"):
        WsnConfig(r_s=-1.0)
    with pytest.raises(ValueError, match="sink"):
        WsnConfig(sink="nowhere")
    with pytest.raises(ValueError, match="coverage_lifetime_threshold"):
        WsnConfig(coverage_lifetime_threshold=0.0)
    with pytest.raises(ValueError, match="k"):
        WsnConfig(k=0)
    land, zone, centres, radii, profiles = _deployment(20, 1)
    with pytest.raises(ValueError, match="profiles"):
        evaluate_deployment(land, zone, centres, radii, profiles[:1])
    with pytest.raises(ValueError, match="land_xy"):
        evaluate_deployment(land[:, :1], zone, centres, radii, profiles)
    out = evaluate_deployment(land, zone, centres, radii, profiles, WsnConfig(sink=(500.0, 500.0)))
    assert out["sink_reach"] == 0.0 and out["n_population"] == 0.0 and out["n_sinks"] == 1.0
