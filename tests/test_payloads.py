"""Payload physics: ballistic fall, wind, and the vectorised PayloadSet."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.payloads import (
    FallParams,
    PayloadSet,
    ScatterConfig,
    WindConfig,
    WindModel,
    compensated_release_xy,
    fall_time_vertical_drag,
    predict_landing,
    vacuum_landing,
)
from tests.reference.payloads import reference_fall

CUBE = FallParams()  # 100 g, 6 cm cube, C_d 1.05
BOX = FallParams(mass=0.25, area=0.08**2)
SPHERE = FallParams(mass=0.05, cd=0.47, area=math.pi * 0.025**2)
VACUUM = FallParams(cd=0.0)


def _drop_all(ps: PayloadSet, wind: WindModel | None, rng: np.random.Generator, dt: float = 0.1) -> int:
    """Step until nothing falls; return the number of steps."""
    steps = 0
    while ps.n_falling:
        ps.step(dt, wind, rng)
        steps += 1
        assert steps < 10_000
    return steps


def _still_wind(speed: float, direction: float = 0.0, profile: str = "uniform", sigma: float = 0.0) -> WindModel:
    cfg = WindConfig(mean_speed=speed, direction=direction, profile=profile, gust_sigma_frac=sigma)
    return WindModel(cfg, np.random.default_rng(0))


# ---------------------------------------------------------------- parameters and closed forms
def test_fall_params() -> None:
    assert CUBE.terminal_speed == pytest.approx(20.6, abs=0.05)
    assert BOX.terminal_speed == pytest.approx(24.4, abs=0.05)
    assert SPHERE.terminal_speed == pytest.approx(29.5, abs=0.05)
    assert VACUUM.terminal_speed == math.inf and VACUUM.drag_k == 0.0
    for kwargs, name in [
        ({"mass": 0.0}, "mass"),
        ({"cd": -1.0}, "cd"),
        ({"area": math.nan}, "area"),
        ({"rho_air": -1.0}, "rho_air"),
        ({"g": 0.0}, "g"),
    ]:
        with pytest.raises(ValueError, match=name):
            FallParams(**kwargs)


def test_vacuum_landing_closed_form() -> None:
    xy, t = vacuum_landing([1.0, 2.0, 30.0], [10.0, -3.0, 0.0], 9.81)
    t_exp = math.sqrt(2 * 30.0 / 9.81)
    assert t[0] == pytest.approx(t_exp, rel=1e-14)
    np.testing.assert_allclose(xy[0], [1.0 + 10.0 * t_exp, 2.0 - 3.0 * t_exp], rtol=1e-14)
    # Thrown upward: rises first, then falls.
    _, t_up = vacuum_landing([0.0, 0.0, 10.0], [0.0, 0.0, 5.0], 9.81)
    assert t_up[0] == pytest.approx((5.0 + math.sqrt(25.0 + 2 * 9.81 * 10.0)) / 9.81, rel=1e-14)
    with pytest.raises(ValueError, match="z"):
        vacuum_landing([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="p0"):
        vacuum_landing([0.0, 0.0], [0.0, 0.0, 0.0])


def test_vertical_drag_fall_time() -> None:
    h = np.array([1.0, 10.0, 30.0, 100.0])
    t = fall_time_vertical_drag(h, CUBE)
    _, t_ref = reference_fall(np.c_[np.zeros((4, 2)), h], np.zeros((4, 3)), CUBE, dt=1e-3)
    np.testing.assert_allclose(t, t_ref, rtol=1e-7)
    np.testing.assert_allclose(fall_time_vertical_drag(h, VACUUM), np.sqrt(2 * h / 9.81))
    # Far beyond terminal speed: t -> h / v_t + (v_t / g) ln 2, and no overflow.
    vt = CUBE.terminal_speed
    assert fall_time_vertical_drag(1e5, CUBE) == pytest.approx(1e5 / vt + vt / 9.81 * math.log(2.0), rel=1e-12)
    # The vertical-only time is slightly below the coupled fall with forward speed.
    _, t_coupled = predict_landing([0.0, 0.0, 30.0], [10.0, 0.0, 0.0], CUBE)
    assert fall_time_vertical_drag(30.0, CUBE) < t_coupled[0] < 1.05 * fall_time_vertical_drag(30.0, CUBE)


# Domain table 3.1 (release at 10 m/s): node, h, t_f, forward throw, extra drift with +5 m/s tailwind.
TABLE = [
    (CUBE, 10.0, 1.52, 12.7, 1.4),
    (CUBE, 30.0, 2.83, 19.8, 4.7),
    (CUBE, 50.0, 3.91, 23.4, 8.5),
    (BOX, 30.0, 2.73, 21.1, 3.5),
    (SPHERE, 30.0, 2.65, 22.1, 2.5),
]


@pytest.mark.parametrize(("params", "h", "t_f", "throw", "tail"), TABLE)
def test_domain_table(params: FallParams, h: float, t_f: float, throw: float, tail: float) -> None:
    p0 = np.array([[0.0, 0.0, h], [0.0, 0.0, h]])
    v0 = np.array([[10.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    xy, t = predict_landing(p0[:1], v0[:1], params)
    xy_w, _ = predict_landing(p0[:1], v0[:1], params, wind_mean=[5.0, 0.0])
    assert t[0] == pytest.approx(t_f, rel=0.01)
    assert xy[0, 0] == pytest.approx(throw, rel=0.01) and xy[0, 1] == 0.0
    assert xy_w[0, 0] - xy[0, 0] == pytest.approx(tail, abs=0.06)
    _, t_vac = vacuum_landing(p0[:1], v0[:1])
    assert t[0] > t_vac[0]  # drag slows the fall ...
    assert xy[0, 0] < 10.0 * t_vac[0]  # ... and shortens the throw


def test_predict_matches_fine_reference_with_wind() -> None:
    wind = _still_wind(6.0, direction=0.7, profile="log")
    p0 = np.array([[0.0, 0.0, 10.0], [5.0, 5.0, 30.0]])
    v0 = np.array([[10.0, 0.0, 0.0], [0.0, -10.0, 1.0]])
    ref, t_ref = reference_fall(p0, v0, CUBE, wind.mean_velocity_at, dt=1e-3)
    xy, t = predict_landing(p0, v0, CUBE, wind.mean_velocity_at)
    throw = np.linalg.norm(ref - p0[:, :2], axis=1)
    assert np.all(np.linalg.norm(xy - ref, axis=1) < 1e-3 * throw)
    np.testing.assert_allclose(t, t_ref, rtol=1e-5)


# ---------------------------------------------------------------- wind
def test_wind_profiles() -> None:
    log = WindConfig(mean_speed=5.0, profile="log", z0=0.03, z_ref=10.0)
    z = np.array([-1.0, 0.0, 0.03, 1.0, 10.0, 40.0])
    f = log.profile_factor(z)
    assert f[0] == f[1] == f[2] == 0.0  # clipped at and below z0
    assert f[4] == pytest.approx(1.0)
    assert f[3] == pytest.approx(math.log(1 / 0.03) / math.log(10 / 0.03))
    assert f[5] > 1.0
    pw = WindConfig(profile="power", z_ref=10.0).profile_factor(np.array([0.0, 10.0, 20.0]))
    np.testing.assert_allclose(pw, [0.0, 1.0, 2 ** (1 / 7)])
    np.testing.assert_allclose(WindConfig(profile="uniform").profile_factor(z), 1.0)
    wm = WindModel(WindConfig(mean_speed=4.0, direction=math.pi / 2, profile="log"), np.random.default_rng(0))
    v = wm.velocity_at(np.array([10.0, 10.0]), gusts=np.array([[1.0, 0.0], [0.0, 0.0]]))
    np.testing.assert_allclose(v, [[1.0, 4.0, 0.0], [0.0, 4.0, 0.0]], atol=1e-12)


def test_wind_draws_per_episode() -> None:
    cfg = WindConfig(randomise_speed=(2.0, 8.0), direction=None)
    wm = WindModel(cfg, np.random.default_rng(3), n_worlds=64)
    assert np.all((wm.speed >= 2.0) & (wm.speed <= 8.0)) and np.ptp(wm.speed) > 1.0
    assert np.ptp(wm.direction) > 1.0
    np.testing.assert_allclose(np.linalg.norm(wm.mean, axis=1), wm.speed)
    before = wm.mean
    wm.reset(np.random.default_rng(4), world=[5])
    after = wm.mean
    assert not np.allclose(before[5], after[5]) and np.array_equal(np.delete(before, 5, 0), np.delete(after, 5, 0))
    assert np.array_equal(WindModel(cfg, np.random.default_rng(3), 64).mean, before)
    with pytest.raises(ValueError, match="world"):
        wm.velocity_at(np.array([1.0]))
    with pytest.raises(ValueError, match="world"):
        wm.velocity_at(np.array([1.0]), world=64)


def test_ou_gusts_statistics() -> None:
    wm = WindModel(WindConfig(mean_speed=5.0, gust_sigma_frac=0.2, gust_tau=2.0), np.random.default_rng(0))
    rng = np.random.default_rng(1)
    g0 = wm.init_gusts(20_000, rng)
    g1 = wm.advance_gusts(g0, 0.5, rng)
    assert np.std(g0) == pytest.approx(1.0, rel=0.03)  # sigma = 0.2 * 5 m/s
    assert np.std(g1) == pytest.approx(1.0, rel=0.03)  # stationary
    corr = np.corrcoef(g0[:, 0], g1[:, 0])[0, 1]
    assert corr == pytest.approx(math.exp(-0.5 / 2.0), abs=0.02)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"mean_speed": -1.0}, "mean_speed"),
        ({"direction": math.inf}, "direction"),
        ({"randomise_speed": (3.0, 1.0)}, "randomise_speed"),
        ({"profile": "cubic"}, "profile"),
        ({"z0": 0.0}, "z0"),
        ({"z_ref": 0.01}, "z_ref"),
        ({"gust_sigma_frac": -0.1}, "gust_sigma_frac"),
        ({"gust_tau": 0.0}, "gust_tau"),
    ],
)
def test_wind_config_validation(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        WindConfig(**kwargs)


# ---------------------------------------------------------------- PayloadSet physics
@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), dt=st.sampled_from([0.1, 0.05, 0.37, 1.0]))
def test_drag_free_matches_closed_form(seed: int, dt: float) -> None:
    rng = np.random.default_rng(seed)
    n = 64
    p0 = np.c_[rng.uniform(-100, 100, (n, 2)), rng.uniform(0.5, 80.0, n)]
    v0 = rng.uniform(-15.0, 15.0, (n, 3))
    ps = PayloadSet(params=VACUUM, capacity=8)
    ps.release(0, 0, p0, v0, t=2.0)
    _drop_all(ps, None, rng, dt)
    xy, t = vacuum_landing(p0, v0, VACUUM.g)
    np.testing.assert_allclose(ps.landed_xy(), xy, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ps.get("land_t"), 2.0 + t, rtol=1e-9)


def test_drag_matches_fine_reference() -> None:
    p0 = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 30.0], [3.0, -4.0, 30.0]])
    v0 = np.array([[10.0, 0.0, 0.0], [10.0, 0.0, 0.0], [-7.0, 7.0, -1.0]])
    ref, t_ref = reference_fall(p0, v0, CUBE, dt=1e-4)
    ps = PayloadSet(params=CUBE)
    ps.release(0, 0, p0, v0, 0.0)
    _drop_all(ps, None, np.random.default_rng(0))
    throw = np.linalg.norm(ref - p0[:, :2], axis=1)
    assert np.all(np.linalg.norm(ps.landed_xy() - ref, axis=1) < 0.01 * throw)
    np.testing.assert_allclose(ps.landed_xy(), ref, atol=1e-3)  # in fact sub-millimetre
    np.testing.assert_allclose(ps.get("land_t"), t_ref, rtol=1e-4)
    assert ps.landed_xy()[1, 0] == pytest.approx(19.8, rel=0.01)


@pytest.mark.parametrize("profile", ["log", "power", "uniform"])
def test_kernel_matches_numpy_integrator(profile: str) -> None:
    # Differential test: the numba kernel against the numpy RK4 + Hermite functions, same sub-step.
    cfg = WindConfig(randomise_speed=(3.0, 8.0), profile=profile, gust_sigma_frac=0.0)
    wm = WindModel(cfg, np.random.default_rng(2), n_worlds=3)
    rng = np.random.default_rng(9)
    n = 300
    p0 = np.c_[rng.uniform(-50, 50, (n, 2)), rng.uniform(2.0, 60.0, n)]
    v0 = rng.uniform(-12.0, 12.0, (n, 3))
    world = rng.integers(0, 3, n)
    ps = PayloadSet(params=SPHERE, max_substep=0.01)
    ps.release(np.arange(n), world, p0, v0, 0.0)
    _drop_all(ps, wm, rng)
    for w in range(3):
        sel = world == w
        xy, t = predict_landing(p0[sel], v0[sel], SPHERE, lambda z, w=w: wm.mean_velocity_at(z, world=w), dt=0.01)
        np.testing.assert_allclose(ps.landed_xy(world=w), xy, atol=1e-9)
        np.testing.assert_allclose(ps.get("land_t")[sel], t, atol=1e-9)


def test_tailwind_increases_drift() -> None:
    p0 = np.array([0.0, 0.0, 30.0])
    v0 = np.array([10.0, 0.0, 0.0])
    land = {}
    for name, direction in (("tail", 0.0), ("head", math.pi), ("cross", math.pi / 2)):
        ps = PayloadSet(params=CUBE)
        ps.release(0, 0, p0, v0, 0.0)
        _drop_all(ps, _still_wind(5.0, direction, profile="log"), np.random.default_rng(0))
        land[name] = ps.landed_xy()[0]
    still = PayloadSet(params=CUBE)
    still.release(0, 0, p0, v0, 0.0)
    _drop_all(still, None, np.random.default_rng(0))
    x0 = still.landed_xy()[0, 0]
    assert land["tail"][0] > x0 + 2.0
    assert land["head"][0] < x0 - 2.0
    assert land["cross"][1] > 2.0 and abs(land["tail"][1]) < 1e-12


def test_compensated_release_hits_target() -> None:
    wm = _still_wind(6.0, direction=1.0, profile="log")
    targets = np.array([[10.0, 20.0], [-30.0, 5.0], [0.0, 0.0]])
    v0 = np.array([8.0, -3.0, 0.0])
    rel = compensated_release_xy(targets, 25.0, v0, CUBE, wm.mean_velocity_at)
    ps = PayloadSet(params=CUBE)
    ps.release(0, 0, np.c_[rel, np.full(3, 25.0)], np.tile(v0, (3, 1)), 0.0)
    _drop_all(ps, wm, np.random.default_rng(0))
    np.testing.assert_allclose(ps.landed_xy(), targets, atol=1e-3)


def test_five_thousand_objects_vectorised() -> None:
    rng = np.random.default_rng(11)
    n = 5000
    p0 = np.c_[rng.uniform(-200, 200, (n, 2)), rng.uniform(5.0, 60.0, n)]
    v0 = np.c_[rng.uniform(-12.0, 12.0, (n, 2)), np.zeros(n)]
    wm = _still_wind(4.0, direction=2.0, profile="log")
    ps = PayloadSet(params=CUBE, capacity=16)
    ids = ps.release(rng.integers(0, 8, n), 0, p0, v0, 0.0, zone=3)
    assert ps.capacity >= n and ps.count == n and np.array_equal(ids, np.arange(n))
    landed = []
    while ps.n_falling:
        landed.append(ps.step(0.1, wm, rng))
    all_landed = np.concatenate(landed)
    assert np.array_equal(np.sort(all_landed), ids) and ps.n_landed == n
    assert all(np.all(np.diff(x) > 0) for x in landed)
    xy, t = predict_landing(p0, v0, CUBE, wm.mean_velocity_at, dt=0.01)
    np.testing.assert_allclose(ps.landed_xy(zone=3), xy, atol=2e-3)
    np.testing.assert_allclose(ps.get("land_t"), t, atol=1e-4)
    assert np.all(ps.get("pos")[:, 2] == 0.0) and not np.any(ps.get("falling"))


# ---------------------------------------------------------------- scatter and bookkeeping
SCATTER = ScatterConfig(sigma_gnss=1.5, sigma_timing=0.05, sigma_bounce=0.5, gust_drift=True)


def _scattered(seed: int, n: int = 200) -> np.ndarray:
    wm = WindModel(WindConfig(mean_speed=5.0, direction=0.0, gust_sigma_frac=0.3), np.random.default_rng(0))
    ps = PayloadSet(params=CUBE, scatter=SCATTER)
    rng = np.random.default_rng(seed)
    ps.release(0, 0, np.tile([0.0, 0.0, 30.0], (n, 1)), np.tile([10.0, 0.0, 0.0], (n, 1)), 0.0, rng=rng)
    _drop_all(ps, wm, rng)
    return ps.landed_xy()


def test_same_seed_same_scatter() -> None:
    a, b, c = _scattered(42), _scattered(42), _scattered(43)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)


def test_scatter_magnitudes() -> None:
    # Hovering release, still air: GNSS and bounce add in quadrature (sigma^2 = 1.5^2 + 0.5^2).
    n = 4000
    rng = np.random.default_rng(0)
    ps = PayloadSet(params=CUBE, scatter=ScatterConfig(sigma_gnss=1.5, sigma_bounce=0.5))
    ps.release(0, 0, np.tile([0.0, 0.0, 20.0], (n, 1)), np.zeros((n, 3)), 0.0, rng=rng)
    _drop_all(ps, None, rng)
    assert np.std(ps.landed_xy(), axis=0) == pytest.approx([math.hypot(1.5, 0.5)] * 2, rel=0.05)
    np.testing.assert_allclose(ps.get("release_pos")[:, 2], 20.0)
    # Timing jitter spreads along the track only: v * sigma_t = 10 * 0.1 = 1 m.
    ps = PayloadSet(params=CUBE, scatter=ScatterConfig(sigma_timing=0.1))
    ps.release(0, 0, np.tile([0.0, 0.0, 20.0], (n, 1)), np.tile([10.0, 0.0, 0.0], (n, 1)), 0.0, rng=rng)
    _drop_all(ps, None, rng)
    xy = ps.landed_xy()
    assert np.std(xy[:, 0]) == pytest.approx(1.0, rel=0.05) and np.std(xy[:, 1]) == 0.0
    np.testing.assert_allclose(ps.get("nominal_pos")[:, 0], 0.0)
    # Gusts alone: drift scatter is a fraction kappa of sigma_w * t_f, smaller for a faster-falling node
    # (here kappa ~ 0.3: the cube's horizontal response time v_t / g ~ 2 s is close to its fall time).
    wm = WindModel(WindConfig(mean_speed=6.0, direction=0.0, gust_sigma_frac=0.3), np.random.default_rng(0))
    spread = {}
    for name, params, drift in (("cube", CUBE, True), ("sphere", SPHERE, True), ("off", CUBE, False)):
        ps = PayloadSet(params=params, scatter=ScatterConfig(gust_drift=drift))
        ps.release(0, 0, np.tile([0.0, 0.0, 30.0], (n, 1)), np.zeros((n, 3)), 0.0)
        _drop_all(ps, wm, rng)
        spread[name] = np.std(ps.landed_xy(), axis=0)
        scale = 0.3 * 6.0 * ps.get("fall_time").mean()
        if drift:
            assert np.all((spread[name] > 0.1 * scale) & (spread[name] < 1.0 * scale))
    assert np.all(spread["sphere"] < spread["cube"])
    assert np.all(spread["off"] < 1e-9)
    with pytest.raises(ValueError, match="rng"):
        PayloadSet(scatter=ScatterConfig(sigma_gnss=1.0)).release(0, 0, [0.0, 0.0, 5.0], [0.0, 0.0, 0.0], 0.0)


def test_release_bookkeeping_and_pickle() -> None:
    rng = np.random.default_rng(0)
    wm = WindModel(WindConfig(mean_speed=5.0, gust_sigma_frac=0.2), np.random.default_rng(1), n_worlds=2)
    ps = PayloadSet(params=CUBE, scatter=SCATTER, capacity=2)
    ids_a = ps.release(
        [0, 1], [0, 1], [[0.0, 0.0, 20.0], [5.0, 5.0, 40.0]], [[5.0, 0.0, 0.0]] * 2, 1.0, 2, [1.0, 2.0], rng
    )
    ps.step(0.1, wm, rng)
    ids_b = ps.release(3, 1, [1.0, 1.0, 0.0], [0.0, 0.0, 0.0], 1.1, rng=rng)  # on the ground already
    assert list(ids_a) == [0, 1] and list(ids_b) == [2]
    np.testing.assert_array_equal(ps.get("target_xy")[0], [1.0, 2.0])
    assert np.isnan(ps.get("target_xy")[2]).all() and ps.get("zone").tolist() == [2, 2, -1]
    # A pickled copy continues identically.
    clone, rng_clone = pickle.loads(pickle.dumps((ps, rng)))
    first = ps.step(0.1, wm, rng)
    assert 2 in first
    assert np.array_equal(clone.step(0.1, wm, rng_clone), first)
    _drop_all(ps, wm, rng)
    _drop_all(clone, wm, rng_clone)
    assert np.array_equal(ps.landed_xy(), clone.landed_xy())
    assert ps.get("land_t")[2] == pytest.approx(1.1) and ps.get("fall_time")[2] == 0.0
    np.testing.assert_allclose(ps.get("land_t"), ps.get("release_t") + ps.get("fall_time"))
    assert ps.landed_ids(world=1).tolist() == [1, 2] and ps.landed_ids(owner=0).tolist() == [0]
    np.testing.assert_array_equal(ps.index_of([2, 0]), [2, 0])
    ps.clear_world(0)
    assert ps.count == 2 and ps.get("id").tolist() == [1, 2]
    np.testing.assert_array_equal(ps.index_of([2]), [1])
    with pytest.raises(ValueError, match="ids"):
        ps.index_of([0])
    ps.reset()
    assert ps.count == 0 and ps.landed_xy().shape == (0, 2) and ps.step(0.1, wm, rng).size == 0
    assert ps.release(0, 0, [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 0.0, rng=rng).tolist() == [0]


def test_payload_validation() -> None:
    bad = [
        ({"sigma_gnss": -1.0}, "sigma_gnss"),
        ({"sigma_timing": math.nan}, "sigma_timing"),
        ({"sigma_bounce": -0.1}, "sigma_bounce"),
        ({"gust_drift": 1}, "gust_drift"),
    ]
    for kwargs, name in bad:
        with pytest.raises(ValueError, match=name):
            ScatterConfig(**kwargs)
    with pytest.raises(ValueError, match="capacity"):
        PayloadSet(capacity=0)
    with pytest.raises(ValueError, match="max_substep"):
        PayloadSet(max_substep=0.0)
    ps = PayloadSet()
    with pytest.raises(ValueError, match="pos"):
        ps.release(0, 0, [[0.0, 0.0]], [[0.0, 0.0, 0.0]], 0.0)
    with pytest.raises(ValueError, match="vel"):
        ps.release(0, 0, [[0.0, 0.0, 1.0]], [[0.0, 0.0, 0.0]] * 2, 0.0)
    with pytest.raises(ValueError, match="owner"):
        ps.release([0, 1, 2], 0, [[0.0, 0.0, 1.0]] * 2, [[0.0, 0.0, 0.0]] * 2, 0.0)
    with pytest.raises(ValueError, match="target_xy"):
        ps.release(0, 0, [[0.0, 0.0, 1.0]] * 2, [[0.0, 0.0, 0.0]] * 2, 0.0, target_xy=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="dt"):
        ps.step(0.0, None, np.random.default_rng(0))
    with pytest.raises(ValueError, match="name"):
        ps.get("nope")
