"""Tests for the release planning layer (policies/release/planning.py and targets.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from scipy.stats import kstest

from agentsim_env.policies.release.planning import (
    in_sector,
    path_length,
    plan_tour,
    sector_quota,
    split_sectors,
)
from agentsim_env.policies.release.registry import make_plan, strategy_names
from agentsim_env.uav.wsn.profiles import RadialProfile

R = 100.0
CENTRE = np.array([250.0, -40.0])
GAUSS = RadialProfile("gauss", R, sigma=35.0)


def _plan(name, n=200, profile=GAUSS, seed=3, **kw):
    return make_plan(name, CENTRE, profile, n, 30.0, 8.0, np.random.default_rng(seed), **kw)


def _radii(plan):
    return np.hypot(*(plan.release_xy - CENTRE).T)


@pytest.fixture(scope="module")
def ballistic():
    return pytest.importorskip("agentsim_env.payloads.ballistic")


# ------------------------------------------------------------------------------------- counts / zone
@pytest.mark.parametrize("name", sorted(strategy_names()))
def test_each_strategy_yields_n_targets_inside_the_zone(name):
    plan = _plan(name)
    assert plan.n_releases == 200
    assert plan.release_points.shape == (200, 3) and plan.release_vel.shape == (200, 3)
    inside = _radii(plan) <= R + 1e-9
    if name in ("B0_uniform", "B1_inverse_cdf"):
        assert inside.all()
    assert inside.mean() >= 0.99
    if plan.mode == "teleport":
        assert plan.path_length == 0.0 and plan.waypoints.shape == (0, 3)
        np.testing.assert_array_equal(plan.release_points[:, :2], plan.release_xy)
    else:
        # every release maps to a waypoint; fly-through plans visit each target exactly once
        assert plan.release_wp.min() >= 0 and plan.release_wp.max() < plan.waypoints.shape[0]
        assert np.all(np.diff(plan.release_wp) >= (1 if plan.mode == "waypoints" else 0))
        assert plan.path_length == pytest.approx(path_length(plan.waypoints, plan.start_xy))
        np.testing.assert_allclose(plan.waypoints[:, 2], 30.0)


@pytest.mark.parametrize("name", ["B0_uniform", "B1_inverse_cdf", "B6_drop_clusters", "B7_ergodic"])
def test_random_strategies_are_reproducible_and_seeded(name):
    a, b, c = _plan(name, seed=7), _plan(name, seed=7), _plan(name, seed=8)
    np.testing.assert_array_equal(a.release_xy, b.release_xy)
    np.testing.assert_array_equal(a.waypoints, b.waypoints)
    if name != "B7_ergodic":  # the SMC trajectory is deterministic by design
        assert not np.array_equal(a.release_xy, c.release_xy)


def test_b1_radii_follow_the_profile_and_b0_does_not():
    for prof in (GAUSS, RadialProfile("power", R, alpha=1.0), RadialProfile("linear", R, floor=0.1)):
        assert kstest(_radii(_plan("B1_inverse_cdf", n=1000, profile=prof)), prof.cdf).pvalue > 0.01
    assert kstest(_radii(_plan("B0_uniform", n=1000)), GAUSS.cdf).pvalue < 1e-6


@pytest.mark.parametrize("name", ["B1LD_sunflower", "B3_spiral", "B4_boustrophedon", "B7_ergodic"])
def test_deterministic_patterns_track_the_profile(name):
    radii = _radii(_plan(name, n=600))
    assert kstest(radii, GAUSS.cdf).pvalue > 0.01


# ------------------------------------------------------------------------------------- B2 / B5 / B6
@pytest.mark.parametrize("ring_radii", ["cdf", "isotropic"])
def test_b2_inner_rings_are_denser(ring_radii):
    plan = _plan("B2_rings", n=400, options={"ring_radii": ring_radii})
    radii = np.round(_radii(plan), 6)
    ring_r, counts = np.unique(radii, return_counts=True)
    assert ring_r.size == plan.info["n_rings"] >= 3
    along = 2 * math.pi * ring_r / counts  # release spacing on each ring
    assert np.all(np.diff(along) > 0)
    if ring_radii == "cdf":  # CDF midpoints: equal mass, equal counts
        np.testing.assert_allclose(GAUSS.cdf(ring_r), (np.arange(ring_r.size) + 0.5) / ring_r.size)
        assert counts.max() - counts.min() <= 1


def test_b5_cvt_density_falls_with_radius_and_beats_random_spacing():
    cvt = _plan("B5_cvt", n=300)
    r = _radii(cvt)
    edges = np.array([0.0, 30.0, 60.0, 90.0])
    dens = np.histogram(r, edges)[0] / np.diff(math.pi * edges**2)
    assert np.all(np.diff(dens) < 0)

    def min_nn(xy):
        return cKDTree(xy).query(xy, k=2)[0][:, 1].min()

    assert min_nn(cvt.release_xy) > 3.0 * min_nn(_plan("B1_inverse_cdf", n=300).release_xy)


def test_b6_hovers_at_few_drop_points():
    plan = _plan("B6_drop_clusters", n=300, options={"n_drops": 12})
    assert plan.mode == "hover" and plan.release_speed == 0.0
    assert plan.waypoints.shape[0] <= 12
    assert plan.info["drop_counts"].sum() == 300
    np.testing.assert_array_equal(np.bincount(plan.release_wp), plan.info["drop_counts"])
    np.testing.assert_allclose(plan.release_points[:, :2], plan.waypoints[plan.release_wp, :2])


# ------------------------------------------------------------------------------------- tours
@settings(max_examples=30, deadline=None)
@given(n=st.integers(1, 60), seed=st.integers(0, 2**31 - 1))
def test_tour_visits_every_target_once_and_two_opt_never_lengthens(n, seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-50, 50, (n, 2))
    start = rng.uniform(-80, 80, 2)
    nn = plan_tour(pts, start, two_opt=False)
    opt = plan_tour(pts, start)
    for order in (nn, opt):
        np.testing.assert_array_equal(np.sort(order), np.arange(n))
    assert path_length(pts[opt], start) <= path_length(pts[nn], start) + 1e-9


def test_two_opt_improves_a_random_tour():
    pts = np.random.default_rng(0).uniform(0, 100, (300, 2))
    nn = path_length(pts[plan_tour(pts, np.zeros(2), two_opt=False)], np.zeros(2))
    opt = path_length(pts[plan_tour(pts, np.zeros(2))], np.zeros(2))
    assert opt < 0.97 * nn


# ------------------------------------------------------------------------------------- sectors
@settings(max_examples=30, deadline=None)
@given(caps=st.lists(st.floats(0.2, 5.0), min_size=1, max_size=6), off=st.floats(-7.0, 7.0))
def test_split_sectors_partition_the_circle(caps, off):
    sectors = split_sectors(len(caps), caps, theta0=off)
    assert sectors[0][0] == off and sectors[-1][1] == off + 2 * math.pi
    for (_, a1), (b0, _) in zip(sectors[:-1], sectors[1:], strict=True):
        assert a1 == b0
    widths = np.array([b - a for a, b in sectors])
    np.testing.assert_allclose(widths / widths.sum(), np.array(caps) / sum(caps), rtol=1e-9)
    pts = np.random.default_rng(1).normal(size=(500, 2))
    member = np.stack([in_sector(pts, s) for s in sectors])
    np.testing.assert_array_equal(member.sum(axis=0), 1)  # each point in exactly one wedge
    assert sum(sector_quota(997, s) for s in sectors) == 997


SECTOR_NAMES = ["B1_inverse_cdf", "B1LD_sunflower", "B2_rings", "B3_spiral", "B5_cvt", "B7_ergodic"]
COMPENSATED = ["B1_inverse_cdf", "B2_rings", "B3_spiral", "B6_drop_clusters", "B7_ergodic"]


@pytest.mark.parametrize("name", SECTOR_NAMES)
def test_sector_plans_stay_in_their_wedge_and_share_the_zone(name):
    sectors = split_sectors(3, [1.0, 2.0, 1.0], theta0=0.4)
    plans = [_plan(name, n=240, sector=s) for s in sectors]
    for s, p in zip(sectors, plans, strict=True):
        assert in_sector(p.release_xy - CENTRE, s).all()
    counts = [p.n_releases for p in plans]
    assert sum(counts) == 240
    assert abs(counts[1] - 120) <= 12 and abs(counts[0] - 60) <= 12  # mass share of each wedge
    if name == "B1LD_sunflower":  # wedges of a deterministic pattern partition the full pattern
        full = np.sort(_plan(name, n=240).release_xy, axis=0)
        np.testing.assert_allclose(np.sort(np.vstack([p.release_xy for p in plans]), axis=0), full)


# ------------------------------------------------------------------------------------- compensation
@pytest.mark.parametrize("name", COMPENSATED)
def test_compensated_release_points_land_on_targets(name, ballistic):
    fall, wind = ballistic.FallParams(), np.array([3.0, -1.5])
    plan = _plan(name, n=150, fall=fall, wind_mean=wind)
    xy, _ = ballistic.predict_landing(plan.release_points, plan.release_vel, fall, wind, 0.01)
    assert np.max(np.hypot(*(xy - plan.release_xy).T)) < 0.5
    assert plan.residual < 0.5
    throw = np.hypot(*(plan.release_xy - plan.release_points[:, :2]).T)
    assert throw.min() > 1.0  # wind drift (and the forward throw) are really compensated
    if plan.mode == "waypoints":
        np.testing.assert_allclose(np.hypot(*plan.release_vel[:, :2].T), 8.0)
        # the UAV arrives at each release point heading along its incoming leg
        prev = np.vstack([plan.start_xy, plan.waypoints[:, :2]])[plan.release_wp]
        leg = plan.release_points[:, :2] - prev
        cosang = np.sum(leg * plan.release_vel[:, :2], axis=1) / (np.hypot(*leg.T) * 8.0)
        assert cosang.min() > math.cos(1e-3)
        assert np.hypot(*leg.T).min() >= 2.0 - 1e-6  # min_leg
    else:
        np.testing.assert_array_equal(plan.release_vel, 0.0)


def test_without_a_fall_model_release_points_are_the_targets():
    plan = _plan("B3_spiral", n=100)
    np.testing.assert_allclose(plan.release_points[:, :2], plan.release_xy)
    assert plan.n_lead_in == 0 and plan.residual == 0.0


def test_hover_option_stops_over_each_target(ballistic):
    fall = ballistic.FallParams()
    plan = _plan("B1LD_sunflower", n=50, fall=fall, options={"mode": "hover"})
    assert plan.mode == "hover" and plan.release_speed == 0.0
    np.testing.assert_allclose(plan.release_points[:, :2], plan.release_xy, atol=1e-9)  # still air
    np.testing.assert_array_equal(plan.release_wp, np.arange(50))


# ------------------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"strategy": "B9"}, "strategy"),
        ({"options": {"n_rings": 3}}, "options"),
        ({"sector": (1.0, 0.5)}, "sector"),
        ({"n_sensors": -1}, "n_sensors"),
        ({"altitude": 0.0}, "altitude"),
    ],
)
def test_bad_input_raises_value_error_naming_the_field(kwargs, field):
    args = {"strategy": "B1_inverse_cdf", "n_sensors": 10, "altitude": 30.0, "sector": None, "options": None}
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        make_plan(
            args["strategy"],
            CENTRE,
            GAUSS,
            args["n_sensors"],
            args["altitude"],
            8.0,
            np.random.default_rng(0),
            sector=args["sector"],
            options=args["options"],
        )
    with pytest.raises(ValueError, match="capacities"):
        split_sectors(2, [1.0, -1.0])
