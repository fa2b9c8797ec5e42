"""UAV case-study domain models: rotary-wing energy, hot-zone files and the landed-sensor grid."""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from agentsim_env.uav.energy import (
    DEFAULT_ROTOR,
    GRAVITY,
    BatteryParams,
    RotorParams,
    energy_per_metre,
    energy_step,
    induced_power,
    max_range_speed,
    min_power_speed,
    power,
)
from agentsim_env.uav.landed_grid import local_counts
from agentsim_env.uav.wsn.profiles import RadialProfile
from agentsim_env.uav.zones import (
    Zone,
    ZoneSet,
    default_zones_path,
    load_zones,
    overlaps,
    save_zones,
    tiny_zones_path,
    validate_against_payload,
    zones_from_dict,
    zones_to_dict,
)

# ---------------------------------------------------------------------------------------------- energy


def test_derived_constants_match_the_table() -> None:
    p = RotorParams()
    assert p.P0 == pytest.approx(79.86, abs=0.01)
    assert p.Pi == pytest.approx(88.63, abs=0.01)
    assert p.U_tip == pytest.approx(120.0)
    assert p.v0 == pytest.approx(4.03, abs=0.005)


@pytest.mark.parametrize(("speed", "watts"), [(0.0, 168.5), (5.0, 143.6), (10.2, 126.0), (15.0, 138.5), (18.3, 161.6)])
def test_power_table(speed: float, watts: float) -> None:
    assert float(power(np.array([speed]))[0]) == pytest.approx(watts, rel=0.005)


def test_hover_is_p0_plus_pi_and_vectorised() -> None:
    v = np.array([0.0, 5.0, 10.0])
    out = power(v)
    assert out.shape == (3,)
    assert out[0] == pytest.approx(DEFAULT_ROTOR.P0 + DEFAULT_ROTOR.Pi, rel=1e-12)
    assert np.allclose(out, [float(power(x)) for x in v])
    assert np.allclose(power(-v), out)  # the sign of the speed does not matter


def test_optimal_speeds() -> None:
    v_end = min_power_speed()
    v_rng = max_range_speed()
    assert v_end == pytest.approx(10.2, abs=0.05)
    assert v_rng == pytest.approx(18.3, abs=0.05)
    assert float(energy_per_metre(v_rng)) == pytest.approx(8.83, rel=0.005)
    # The optimisers really found minima: nearby speeds do worse.
    for dv in (-0.5, 0.5):
        assert float(power(v_end + dv)) > float(power(v_end))
        assert float(energy_per_metre(v_rng + dv)) > float(energy_per_metre(v_rng))


@pytest.mark.parametrize(("extra_kg", "pi_watts"), [(0.0, 88.6), (0.5, 123.0), (1.0, 161.0), (2.0, 247.0)])
def test_payload_induced_power_table(extra_kg: float, pi_watts: float) -> None:
    w = DEFAULT_ROTOR.W + extra_kg * GRAVITY
    assert float(induced_power(w)) == pytest.approx(pi_watts, rel=0.01)
    # At hover the induced term is exactly Pi(W): the model recomputes it from the current weight.
    assert float(power(0.0, w)) == pytest.approx(DEFAULT_ROTOR.P0 + pi_watts, rel=0.01)


@given(
    v=st.floats(0.0, 30.0),
    w=st.floats(5.0, 60.0),
    dw=st.floats(0.1, 20.0),
)
def test_power_increases_with_payload(v: float, w: float, dw: float) -> None:
    assert float(power(v, w + dw)) > float(power(v, w))


def test_heavier_uav_flies_its_optima_faster() -> None:
    heavy = DEFAULT_ROTOR.W + 2.0 * GRAVITY
    assert min_power_speed(heavy) > min_power_speed()
    assert max_range_speed(heavy) > max_range_speed()


def test_induced_term_stable_at_high_speed() -> None:
    # The naive sqrt(1 + a^2) - a form returns 0 (or a negative) here; the stable one stays positive.
    v = np.array([60.0, 200.0, 1000.0])
    induced = power(v) - DEFAULT_ROTOR.P0 * (1 + 3 * v**2 / DEFAULT_ROTOR.U_tip**2)
    induced -= 0.5 * 0.6 * 1.225 * 0.05 * 0.503 * v**3
    assert np.all(induced > 0.0)
    assert np.all(np.isfinite(power(v)))


def test_energy_step_climb_and_descent() -> None:
    m = DEFAULT_ROTOR.mass_kg
    vel = np.array([[3.0, 4.0, 0.0], [3.0, 4.0, 2.0], [3.0, 4.0, -2.0], [0.0, 0.0, 0.0]])
    mass = np.full(4, m)
    e = energy_step(vel, mass, 0.5)
    level = float(power(5.0)) * 0.5
    assert e.shape == (4,)
    assert e[0] == pytest.approx(level, rel=1e-12)
    assert e[1] == pytest.approx(level + m * GRAVITY * 2.0 * 0.5, rel=1e-12)  # m g vz dt
    assert e[2] == pytest.approx(level, rel=1e-12)  # no credit for descending
    assert e[3] == pytest.approx((DEFAULT_ROTOR.P0 + DEFAULT_ROTOR.Pi) * 0.5, rel=1e-12)
    # Releasing sensors (less mass) lowers the energy of the same manoeuvre.
    assert np.all(energy_step(vel, mass + 0.5, 0.5) > e)


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda: energy_step(np.zeros((2, 2)), np.ones(2), 0.1), "vel"),
        (lambda: energy_step(np.zeros((2, 3)), np.ones(3), 0.1), "mass"),
        (lambda: energy_step(np.zeros((2, 3)), np.ones(2), -0.1), "dt"),
        (lambda: power(np.ones(2), np.array([20.0, 0.0])), "weight_N"),
        (lambda: RotorParams(R=0.0), "RotorParams.R"),
        (lambda: BatteryParams(reserve_frac=1.0), "reserve_frac"),
        (lambda: BatteryParams(capacity_j=-1.0), "capacity_j"),
    ],
)
def test_energy_bad_input_names_the_field(call: Any, field: str) -> None:
    with pytest.raises(ValueError, match=re.escape(field)):
        call()


def test_battery_defaults() -> None:
    b = BatteryParams()
    assert b.capacity_j == pytest.approx(89.2 * 3600, rel=0.001)
    assert b.usable_j == pytest.approx(0.8 * b.capacity_j)
    # About 42 min at the endurance speed for the 2 kg model airframe (ideal: no wind, no climbs).
    assert b.capacity_j / float(power(min_power_speed())) / 60.0 == pytest.approx(42.0, abs=3.0)


# ---------------------------------------------------------------------------------------------- zones

GOOD: dict[str, Any] = {
    "version": 1,
    "map_size": [600, 400],
    "base": [20, 20],
    "zones": [
        {"name": "a", "centre": [150, 250], "radius": 80, "n_sensors": 50, "profile": "gauss", "sigma": 30},
        {"name": "b", "centre": [400, 150], "radius": 60, "n_sensors": 40, "profile": "power", "alpha": 1.5},
        {"centre": [500, 300], "radius": 50, "n_sensors": 30, "profile": "linear", "floor": 0.2, "weight": 2},
    ],
}


def _bad(zone: int, **changes: Any) -> dict[str, Any]:
    """GOOD with some fields of one zone replaced (a value of ``...`` deletes the field)."""
    d = copy.deepcopy(GOOD)
    for key, value in changes.items():
        if value is ...:
            del d["zones"][zone][key]
        else:
            d["zones"][zone][key] = value
    return d


# (file content, zone label expected in the message, field expected in the message)
BAD_ZONES = [
    (_bad(0, centre=...), "zones[0] 'a'", "centre"),
    (_bad(1, radius=...), "zones[1] 'b'", "radius"),
    (_bad(2, n_sensors=...), "zones[2]", "n_sensors"),
    (_bad(0, center=[1, 2]), "zones[0] 'a'", "center"),
    (_bad(1, colour="red"), "zones[1] 'b'", "colour"),
    (_bad(0, radius="80"), "zones[0] 'a'", "radius"),
    (_bad(0, radius=True), "zones[0] 'a'", "radius"),
    (_bad(0, radius=-5), "zones[0] 'a'", "radius"),
    (_bad(0, radius=0), "zones[0] 'a'", "radius"),
    (_bad(1, centre=[400]), "zones[1] 'b'", "centre"),
    (_bad(1, centre=[400, "x"]), "zones[1] 'b'", "centre"),
    (_bad(1, centre="400,150"), "zones[1] 'b'", "centre"),
    (_bad(2, n_sensors=0), "zones[2]", "n_sensors"),
    (_bad(2, n_sensors=10.0), "zones[2]", "n_sensors"),
    (_bad(2, n_sensors=-3), "zones[2]", "n_sensors"),
    (_bad(0, profile="exp"), "zones[0] 'a'", "profile"),
    (_bad(0, profile=3), "zones[0] 'a'", "profile"),
    (_bad(1, alpha=2.0), "zones[1] 'b'", "alpha"),
    (_bad(1, alpha=-0.1), "zones[1] 'b'", "alpha"),
    (_bad(0, sigma=0), "zones[0] 'a'", "sigma"),
    (_bad(0, sigma="wide"), "zones[0] 'a'", "sigma"),
    (_bad(2, floor=1.0), "zones[2]", "floor"),
    (_bad(2, floor=-0.2), "zones[2]", "floor"),
    (_bad(2, weight=0), "zones[2]", "weight"),
    (_bad(2, weight=-1.0), "zones[2]", "weight"),
    (_bad(0, altitude=0), "zones[0] 'a'", "altitude"),
    (_bad(0, altitude=500), "zones[0] 'a'", "altitude"),
    (_bad(0, name=7), "zones[0] 7", "name"),
    (_bad(0, centre=[50, 250]), "zones[0] 'a'", "centre"),  # 30 m beyond the left edge
    (_bad(1, centre=[570, 150]), "zones[1] 'b'", "centre"),  # beyond the right edge
    (_bad(2, centre=[500, 380]), "zones[2]", "centre"),  # beyond the top edge
]


@pytest.mark.parametrize(("content", "label", "field"), BAD_ZONES, ids=[f"bad{i}" for i in range(len(BAD_ZONES))])
def test_bad_zone_file_names_zone_and_field(tmp_path: Path, content: dict, label: str, field: str) -> None:
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(content))
    with pytest.raises(ValueError) as info:
        load_zones(path)
    msg = str(info.value)
    assert msg.startswith(str(path)), msg
    assert label + ":" in msg, msg
    assert repr(field) in msg, msg


def test_outside_map_says_by_how_much() -> None:
    with pytest.raises(ValueError, match=r"30 m beyond the left edge"):
        zones_from_dict(_bad(0, centre=[50, 250]))
    with pytest.raises(ValueError, match=r"10 m beyond the right edge.*10 m beyond the top edge"):
        zones_from_dict(_bad(2, centre=[560, 360]))


def test_profile_error_lists_the_allowed_kinds() -> None:
    with pytest.raises(ValueError, match=r"'uniform', 'power', 'gauss', 'linear'"):
        zones_from_dict(_bad(0, profile="rings"))


def test_unknown_field_suggests_spelling() -> None:
    with pytest.raises(ValueError, match=r"did you mean 'centre'"):
        zones_from_dict(_bad(0, center=[1, 2]))
    misspelt = _bad(0, center=[150, 280])
    del misspelt["zones"][0]["centre"]  # the required field only under its misspelling: named as such, not missing
    with pytest.raises(ValueError, match=r"unknown field 'center' \(did you mean 'centre'\?\)"):
        zones_from_dict(misspelt)
    missing = _bad(0)
    del missing["zones"][0]["centre"]
    with pytest.raises(ValueError, match=r"missing required field\(s\) \['centre'\]"):
        zones_from_dict(missing)


@pytest.mark.parametrize(
    ("content", "field"),
    [
        ({"zones": GOOD["zones"]}, "map_size"),
        ({"map_size": [600, 400]}, "zones"),
        ({**GOOD, "zones": []}, "zones"),
        ({**GOOD, "zones": [1]}, "zones[0]"),
        ({**GOOD, "map_size": [600, -1]}, "map_size"),
        ({**GOOD, "map_size": [600]}, "map_size"),
        ({**GOOD, "base": [700, 20]}, "base"),
        ({**GOOD, "base": "home"}, "base"),
        ({**GOOD, "version": 2}, "version"),
        ({**GOOD, "extra": 1}, "extra"),
    ],
)
def test_bad_top_level_names_the_field(content: dict, field: str) -> None:
    with pytest.raises(ValueError, match=re.escape(field)):
        zones_from_dict(content)


def test_malformed_json(tmp_path: Path) -> None:
    path = tmp_path / "broken.json"
    path.write_text('{"map_size": [1, 2],')
    with pytest.raises(ValueError, match="not valid JSON"):
        load_zones(path)
    path.write_text("[1, 2]")
    with pytest.raises(ValueError, match="JSON object"):
        load_zones(path)


def test_round_trip(tmp_path: Path) -> None:
    zs = zones_from_dict(GOOD)
    assert zones_from_dict(zones_to_dict(zs)) == zs
    path = tmp_path / "z.json"
    save_zones(zs, path)
    assert load_zones(path) == zs
    assert zs.zones[2].weight == 2.0 and isinstance(zs.zones[2].weight, float)
    assert zs.zones[2].name is None and "name" not in zones_to_dict(zs)["zones"][2]


def test_defaults_and_radial_profile() -> None:
    zs = zones_from_dict({"map_size": [200, 200], "zones": [{"centre": [100, 100], "radius": 40, "n_sensors": 5}]})
    z = zs.zones[0]
    assert (z.profile, z.alpha, z.sigma, z.floor, z.weight, z.altitude, z.name) == (
        "gauss",
        1.0,
        None,
        0.0,
        1.0,
        None,
        None,
    )
    assert zs.base is None
    assert z.radial_profile() == RadialProfile("gauss", 40.0, sigma=20.0)
    b = zones_from_dict(GOOD).zones[1].radial_profile()
    assert (b.kind, b.radius, b.alpha) == ("power", 60.0, 1.5)


def test_zone_constructed_in_code_is_validated() -> None:
    with pytest.raises(ValueError, match=r"zone 'x': field 'floor'"):
        Zone((0.0, 0.0), 1.0, 1, floor=1.5, name="x")
    with pytest.raises(ValueError, match=r"zones\[0\] 'x'.*not fully inside"):
        ZoneSet((Zone((5.0, 5.0), 10.0, 1, name="x"),), (100.0, 100.0))


def test_payload_check() -> None:
    zs = zones_from_dict(GOOD)  # 120 sensors
    validate_against_payload(zs, 3, 40)
    with pytest.raises(ValueError, match=r"need 120 sensors.*2 UAV\(s\) x 50 sensors carry only 100"):
        validate_against_payload(zs, 2, 50)
    with pytest.raises(ValueError, match="n_uavs"):
        validate_against_payload(zs, 0, 50)
    with pytest.raises(ValueError, match="payload_per_uav"):
        validate_against_payload(zs, 2, -1)


def test_packaged_files_load_and_validate() -> None:
    default = load_zones(default_zones_path())
    assert len(default.zones) == 3
    assert default.map_size == (600.0, 400.0) and default.base == (20.0, 20.0)
    assert {z.profile for z in default.zones} == {"gauss", "power", "linear"}
    assert all(60.0 <= z.radius <= 100.0 for z in default.zones)
    assert default.n_sensors == 150
    validate_against_payload(default, 4, 40)
    with pytest.raises(ValueError):
        validate_against_payload(default, 3, 40)
    assert overlaps(default) == []
    tiny = load_zones(tiny_zones_path())
    assert len(tiny.zones) == 1 and tiny.n_sensors == 20


def test_overlaps() -> None:
    zones = (
        Zone((100.0, 100.0), 50.0, 1),
        Zone((180.0, 100.0), 40.0, 1),  # overlaps 0 (80 < 90)
        Zone((270.0, 100.0), 50.0, 1),  # touches 1 exactly (90 = 40 + 50): not an overlap
        Zone((110.0, 110.0), 10.0, 1),  # inside 0
    )
    zs = ZoneSet(zones, (400.0, 300.0))
    assert overlaps(zs) == [(0, 1), (0, 3)]
    idx = zs.zone_index(np.array([[100.0, 100.0], [112.0, 110.0], [175.0, 100.0], [10.0, 290.0]]))
    assert idx.tolist() == [0, 3, 1, -1]


# ---------------------------------------------------------------------------------------------- landed grid


def _brute_counts(
    uav_xy: np.ndarray,
    uav_world: np.ndarray,
    sensor_xy: np.ndarray,
    sensor_world: np.ndarray,
    cells: int,
    extent: float,
    scale: float,
) -> np.ndarray:
    out = np.zeros((len(uav_xy), cells, cells), dtype=np.float64)
    for u in range(len(uav_xy)):
        for s in range(len(sensor_xy)):
            if sensor_world[s] != uav_world[u]:
                continue
            fx = (sensor_xy[s, 0] - (uav_xy[u, 0] - 0.5 * extent)) * (cells / extent)
            fy = (sensor_xy[s, 1] - (uav_xy[u, 1] - 0.5 * extent)) * (cells / extent)
            if 0.0 <= fx < cells and 0.0 <= fy < cells:
                out[u, math.floor(fy), math.floor(fx)] += 1.0
    return np.clip(out / scale, 0.0, 1.0)


@pytest.mark.parametrize("seed", range(6))
def test_local_counts_matches_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_worlds = int(rng.integers(1, 4))
    U, n = int(rng.integers(1, 7)), int(rng.integers(0, 300))
    cells = int(rng.integers(1, 10))
    extent = float(rng.uniform(20.0, 120.0))
    scale = float(rng.choice([1.0, 3.0, 50.0]))
    uav_xy = rng.uniform(0.0, 150.0, (U, 2))
    sensor_xy = rng.uniform(0.0, 150.0, (n, 2))
    # Some sensors on the grid lines of the first UAV's window, to test the half-open cell convention.
    k = min(n, 20)
    step = extent / cells
    sensor_xy[:k] = uav_xy[0] - 0.5 * extent + step * rng.integers(0, cells + 1, (k, 2))
    uav_world = rng.integers(0, n_worlds, U)
    sensor_world = rng.integers(0, n_worlds, n)
    got = local_counts(uav_xy, uav_world, sensor_xy, sensor_world, cells, extent, scale)
    want = _brute_counts(uav_xy, uav_world, sensor_xy, sensor_world, cells, extent, scale)
    assert got.dtype == np.float32 and got.shape == (U, cells, cells)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=0.0)
    assert got.min() >= 0.0 and got.max() <= 1.0


def test_local_counts_layout_mask_and_out() -> None:
    uav = np.array([[100.0, 100.0], [100.0, 100.0]])
    sensors = np.array([[101.0, 131.0], [95.0, 61.0], [101.0, 131.0], [100.0, 100.0], [141.0, 100.0]])
    worlds = np.array([0, 0, 0, 1, 0])
    got = local_counts(uav, np.array([0, 1]), sensors, worlds, cells=8, extent=80.0, scale=2.0)
    # (101, 131): dx = 1 -> ix 4; dy = 31 -> iy 7 (north row). Two sensors there -> 2 / 2 = 1.
    assert got[0, 7, 4] == 1.0
    assert got[0, 0, 3] == 0.5  # (95, 61): dx = -5 -> ix 3, dy = -39 -> iy 0
    assert got[0].sum() == 1.5  # (141, 100) lies outside the half-open window
    assert got[1, 4, 4] == 0.5 and got[1].sum() == 0.5  # only the world-1 sensor
    buf = np.full((2, 8, 8), 9.0, dtype=np.float32)
    landed = np.array([True, True, False, True, True])
    res = local_counts(uav, np.array([0, 1]), sensors, worlds, 8, 80.0, 2.0, landed=landed, out=buf)
    assert res is buf
    assert buf[0, 7, 4] == 0.5 and buf[0].sum() == 1.0


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"cells": 0}, "cells"),
        ({"extent": 0.0}, "extent"),
        ({"scale": -1.0}, "scale"),
        ({"uav_world": np.zeros(3)}, "uav_world"),
        ({"sensor_xy": np.zeros((4, 3))}, "sensor_xy"),
        ({"landed": np.ones(2, dtype=bool)}, "landed"),
        ({"out": np.zeros((2, 8, 8))}, "out"),
    ],
)
def test_local_counts_bad_input(kwargs: dict, field: str) -> None:
    args: dict[str, Any] = {
        "uav_xy": np.zeros((2, 2)),
        "uav_world": np.zeros(2, dtype=int),
        "sensor_xy": np.zeros((4, 2)),
        "sensor_world": np.zeros(4, dtype=int),
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        local_counts(**args)


def test_docs_examples_are_valid_zone_files() -> None:
    doc = Path(__file__).resolve().parents[1] / "docs" / "zones.md"
    blocks = re.findall(r"```json\n(.*?)```", doc.read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 2
    assert zones_from_dict(json.loads(blocks[0])) == load_zones(default_zones_path())
    assert zones_from_dict(json.loads(blocks[1])).n_sensors == 20
