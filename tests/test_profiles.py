"""Radial density profiles: normalisation, CDF, inversion, sampling and validation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, stats

from agentsim_env.uav.wsn.profiles import GOLDEN_ANGLE, PROFILE_KINDS, RadialProfile

R = 25.0
PROFILES = [
    RadialProfile("uniform", R),
    RadialProfile("power", R, alpha=0.0),
    RadialProfile("power", R, alpha=1.0),
    RadialProfile("power", R, alpha=1.7),
    RadialProfile("gauss", R),
    RadialProfile("gauss", R, sigma=4.0),
    RadialProfile("gauss", R, sigma=200.0),
    RadialProfile("linear", R),
    RadialProfile("linear", R, floor=0.3),
    RadialProfile("power", R, alpha=1.5, floor=0.2),
    RadialProfile("gauss", R, sigma=3.0, floor=0.1),
    RadialProfile("uniform", R, floor=0.5),
]
IDS = [f"{p.kind}-a{p.alpha}-s{p.sigma}-f{p.floor}" for p in PROFILES]


def _mass(p: RadialProfile, r0: float, r1: float) -> float:
    """Numeric integral of 2 pi r density(r) over [r0, r1]."""
    return integrate.quad(lambda r: 2.0 * math.pi * r * p.density(r), r0, r1, limit=200, epsabs=1e-13)[0]


@pytest.mark.parametrize("p", PROFILES, ids=IDS)
def test_density_integrates_to_one(p: RadialProfile) -> None:
    assert _mass(p, 0.0, R) == pytest.approx(1.0, abs=1e-8)


@pytest.mark.parametrize("p", PROFILES, ids=IDS)
def test_cdf_matches_integral_of_density(p: RadialProfile) -> None:
    for r in (0.0, 0.1, 2.5, 7.0, 12.5, 20.0, R):
        assert p.cdf(r) == pytest.approx(_mass(p, 0.0, r), abs=1e-8)
    assert p.cdf(-1.0) == 0.0 and p.cdf(R + 1.0) == 1.0
    assert p.mass_between(5.0, 15.0) == pytest.approx(_mass(p, 5.0, 15.0), abs=1e-8)


@pytest.mark.parametrize("p", PROFILES, ids=IDS)
def test_inverse_cdf_inverts_cdf(p: RadialProfile) -> None:
    r = np.linspace(0.0, R, 2001)
    # Where the pure Gaussian's CDF has saturated to 1 in float64 the radius is not recoverable.
    ok = (p.cdf(r) < 1.0 - 1e-12) | (r == R)
    assert np.max(np.abs(p.inverse_cdf(p.cdf(r[ok])) - r[ok])) < 1e-9 * R
    u = np.linspace(0.0, 1.0, 2001)
    r_u = p.inverse_cdf(u)
    assert np.all(np.diff(r_u) >= 0.0) and r_u[0] == 0.0 and r_u[-1] == pytest.approx(R)
    np.testing.assert_allclose(p.cdf(r_u), u, atol=1e-12)


def test_closed_form_inverses() -> None:
    u = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(RadialProfile("uniform", R).inverse_cdf(u), R * np.sqrt(u), rtol=1e-14)
    np.testing.assert_allclose(RadialProfile("power", R, alpha=1.0).inverse_cdf(u), R * u, rtol=1e-14)
    np.testing.assert_allclose(RadialProfile("power", R, alpha=0.5).inverse_cdf(u), R * u ** (1 / 1.5), rtol=1e-14)
    s = 6.0
    expected = s * np.sqrt(-2.0 * np.log(1.0 - u * (1.0 - np.exp(-(R**2) / (2 * s * s)))))
    np.testing.assert_allclose(RadialProfile("gauss", R, sigma=s).inverse_cdf(u), expected, rtol=1e-12, atol=1e-12)
    x = RadialProfile("linear", R).inverse_cdf(u) / R
    np.testing.assert_allclose(3 * x**2 - 2 * x**3, u, atol=1e-14)


def test_shapes_relative_to_centre() -> None:
    lin = RadialProfile("linear", 10.0)
    assert lin.density(0.0) == pytest.approx(3.0 / (math.pi * 100.0))
    assert lin.density(10.0) == 0.0 and lin.density(10.5) == 0.0 and lin.density(-0.1) == 0.0
    g = RadialProfile("gauss", 10.0)
    assert g.sigma == 5.0  # default resolved to radius / 2
    assert g.density(0.0) / g.density(5.0) == pytest.approx(math.exp(0.5))
    pw = RadialProfile("power", 10.0, alpha=1.0)
    assert pw.density(2.0) / pw.density(4.0) == pytest.approx(2.0)
    assert np.isinf(pw.density(0.0))
    assert RadialProfile("uniform", 10.0).density(np.array([0.0, 3.0, 9.9])).shape == (3,)


def test_floor_is_a_mass_mixture() -> None:
    eta = 0.25
    pure = RadialProfile("gauss", R, sigma=3.0)
    mixed = RadialProfile("gauss", R, sigma=3.0, floor=eta)
    uni = RadialProfile("uniform", R)
    r = np.linspace(0.0, R, 51)
    np.testing.assert_allclose(mixed.density(r), (1 - eta) * pure.density(r) + eta * uni.density(r), rtol=1e-14)
    np.testing.assert_allclose(mixed.cdf(r), (1 - eta) * pure.cdf(r) + eta * uni.cdf(r), rtol=1e-14)
    # The floor populates the rim that the narrow Gaussian leaves almost empty.
    assert mixed.mass_between(0.8 * R, R) > 0.2 * eta
    assert pure.mass_between(0.8 * R, R) < 1e-6
    # Sampling the mixture CDF agrees with sampling component by component.
    rng = np.random.default_rng(5)
    n = 4000
    via_cdf = np.hypot(*mixed.sample(n, rng).T)
    use_uni = rng.random(n) < eta
    by_component = np.where(use_uni, np.hypot(*uni.sample(n, rng).T), np.hypot(*pure.sample(n, rng).T))
    assert stats.ks_2samp(via_cdf, by_component).pvalue > 1e-3


@pytest.mark.parametrize("p", PROFILES, ids=IDS)
def test_samples_pass_ks(p: RadialProfile) -> None:
    rng = np.random.default_rng(1234)
    xy = p.sample(2000, rng)
    assert xy.shape == (2000, 2)
    radii = np.hypot(xy[:, 0], xy[:, 1])
    assert radii.max() <= R
    assert stats.kstest(radii, p.cdf).pvalue > 1e-3
    # Angles are uniform too.
    theta = np.arctan2(xy[:, 1], xy[:, 0])
    assert stats.kstest(theta, stats.uniform(loc=-math.pi, scale=2 * math.pi).cdf).pvalue > 1e-3


def test_ks_rejects_the_wrong_profile() -> None:
    # Negative control: the KS check above has power to tell profiles apart.
    rng = np.random.default_rng(1234)
    radii = np.hypot(*RadialProfile("uniform", R).sample(2000, rng).T)
    assert stats.kstest(radii, RadialProfile("gauss", R).cdf).pvalue < 1e-6


def test_sample_is_seeded() -> None:
    p = RadialProfile("power", R, alpha=1.2, floor=0.1)
    a = p.sample(50, np.random.default_rng(7))
    b = p.sample(50, np.random.default_rng(7))
    c = p.sample(50, np.random.default_rng(8))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@pytest.mark.parametrize("p", PROFILES, ids=IDS)
def test_low_discrepancy_sunflower(p: RadialProfile) -> None:
    n = 500
    xy = p.low_discrepancy(n)
    assert xy.shape == (n, 2)
    radii = np.hypot(xy[:, 0], xy[:, 1])
    # Quantile radii: the empirical CDF is within 1 / (2n) of the profile's everywhere.
    assert stats.kstest(radii, p.cdf).statistic <= 0.5 / n + 1e-9
    np.testing.assert_allclose(radii, p.inverse_cdf((np.arange(1, n + 1) - 0.5) / n))
    i = np.arange(1, n + 1)
    ang = np.arctan2(xy[:, 1], xy[:, 0])
    big = radii > 1e-9 * R
    d = np.angle(np.exp(1j * (ang[big] - i[big] * GOLDEN_ANGLE)))
    assert np.max(np.abs(d)) < 1e-9
    assert p.low_discrepancy(0).shape == (0, 2)


@settings(max_examples=50, deadline=None)
@given(
    kind=st.sampled_from(PROFILE_KINDS),
    radius=st.floats(0.5, 500.0),
    alpha=st.floats(0.0, 1.95),
    sigma_frac=st.floats(0.05, 5.0),
    floor=st.one_of(st.just(0.0), st.floats(0.0, 0.95)),
    u=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
)
def test_inverse_cdf_property(
    kind: str, radius: float, alpha: float, sigma_frac: float, floor: float, u: list[float]
) -> None:
    p = RadialProfile(kind, radius, alpha=alpha, sigma=sigma_frac * radius, floor=floor)
    uu = np.sort(np.asarray(u))
    r = p.inverse_cdf(uu)
    assert np.all((r >= 0.0) & (r <= radius * (1 + 1e-12)))
    assert np.all(np.diff(r) >= 0.0)
    np.testing.assert_allclose(p.cdf(r), uu, atol=1e-9)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"kind": "cone", "radius": 1.0}, "kind"),
        ({"kind": "uniform", "radius": 0.0}, "radius"),
        ({"kind": "uniform", "radius": float("inf")}, "radius"),
        ({"kind": "power", "radius": 1.0, "alpha": 2.0}, "alpha"),
        ({"kind": "power", "radius": 1.0, "alpha": -0.1}, "alpha"),
        ({"kind": "gauss", "radius": 1.0, "sigma": 0.0}, "sigma"),
        ({"kind": "gauss", "radius": 1.0, "sigma": -1.0}, "sigma"),
        ({"kind": "linear", "radius": 1.0, "floor": 1.0}, "floor"),
        ({"kind": "linear", "radius": 1.0, "floor": -0.1}, "floor"),
    ],
)
def test_bad_fields_raise(kwargs: dict, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        RadialProfile(**kwargs)


def test_bad_arguments_raise() -> None:
    p = RadialProfile("linear", 5.0)
    with pytest.raises(ValueError, match="u must"):
        p.inverse_cdf([0.5, 1.5])
    with pytest.raises(ValueError, match="u must"):
        p.inverse_cdf(np.nan)
    with pytest.raises(ValueError, match="n must"):
        p.sample(-1, np.random.default_rng(0))
    with pytest.raises(ValueError, match="n must"):
        p.low_discrepancy(2.5)  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", PROFILE_KINDS)
def test_low_discrepancy_indices_pick_the_same_points(kind: str) -> None:
    prof = RadialProfile(kind, 30.0, alpha=0.7, floor=0.2)
    idx = np.array([0, 3, 4, 97, 199])
    np.testing.assert_array_equal(prof.low_discrepancy(200, idx), prof.low_discrepancy(200)[idx])
