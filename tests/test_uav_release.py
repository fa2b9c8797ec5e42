"""uav_release: config and zones validation, release mechanics, energy, rewards and mission end."""

from __future__ import annotations

import json

import numpy as np
import pytest

import agentsim_env
from agentsim_env.uav.zones import default_zones_path


def _idle(env, release=None):  # type: ignore[no-untyped-def]
    d = env.scenario.config.comms.action_dim
    out = {}
    for a in env.agents:
        rel = np.array([-1.0, 0.0, 0.0], np.float32)
        if release and a in release:
            rel = np.asarray(release[a], np.float32)
        out[a] = {"motion": np.zeros(3, np.float32), "release": rel, "comm": np.full(d, -1.0, np.float32)}
    return out


def _tiny(**kw):  # type: ignore[no-untyped-def]
    cfg = {
        "zones": "tiny",
        "n_uavs": 2,
        "payload": 12,
        "wind": {"mean_speed": 0.0},
        "scatter": {"sigma_gnss": 0.0, "sigma_timing": 0.0, "sigma_bounce": 0.0},
        **kw,
    }
    env = agentsim_env.make("uav_release", **cfg)
    env.reset(seed=0)
    return env


def test_release_falls_lands_and_is_recorded() -> None:
    env = _tiny()
    st = env.world.state
    st.pos[0] = [100.0, 100.0, 20.0]  # over the tiny zone's centre
    target_off = np.array([0.1, -0.05])
    env.step(_idle(env, {"uav_0": [1.0, *target_off]}))
    ps = env.world.payloads.objects
    assert ps.count == 1 and env.world.task.payload_left[0] == 11
    landed_info = 0
    for _ in range(40):
        _, _, _, _, info = env.step(_idle(env))
        landed_info += info["uav_0"]["landed"]
    assert ps.n_landed == 1 and landed_info == 1
    land = ps.get("land_xy")[0]
    # hovering release without wind or scatter lands right below
    np.testing.assert_allclose(land, [100.0, 100.0], atol=1e-6)
    np.testing.assert_allclose(ps.get("target_xy")[0], [100.0, 100.0] + target_off * 60.0)
    assert ps.get("zone")[0] == 0 and ps.get("owner")[0] == 0


def test_reward_terms_coverage_miss_and_out_of_zone() -> None:
    env = _tiny(w_energy=0.0, reward={"message_cost": 0.0, "collision_penalty": 0.0})
    st = env.world.state
    st.pos[0] = [100.0, 100.0, 10.0]  # inside the zone: coverage gain, exact target
    st.pos[1] = [10.0, 190.0, 10.0]  # far outside the zone: out-of-zone penalty
    env.step(_idle(env, {"uav_0": [1.0, 0.0, 0.0], "uav_1": [1.0, 0.0, 0.0]}))
    total = {"uav_0": 0.0, "uav_1": 0.0}
    for _ in range(30):
        _, r, *_ = env.step(_idle(env))
        for a in r:
            total[a] += r[a]
    assert total["uav_0"] > 0.5  # weighted coverage gain (x10) and a better W1 than the empty zone
    assert total["uav_1"] <= -0.99  # -1 for landing outside every zone, nothing gained


def test_energy_follows_power_model_and_payload() -> None:
    env = _tiny()
    st = env.world.state
    env.step(_idle(env))
    hover_full = st.energy.copy()
    assert np.all(hover_full > 0)
    env.world.task.payload_left[1] = 0  # a lighter UAV spends less to hover
    before = st.energy.copy()
    env.step(_idle(env))
    spent = st.energy - before
    assert spent[1] < spent[0]
    # 168.5 W hover at the reference weight: the airframe plus 12 x 50 g sensors needs more
    assert spent[0] / env.scenario.config.dt > 168.5


def test_empty_battery_ends_uav() -> None:
    env = _tiny(battery_j=500.0)
    ended = None
    for t in range(40):
        _, _, term, *_ = env.step(_idle(env))
        if term.get("uav_0"):
            ended = t
            break
    assert ended is not None and ended < 30


def test_mission_ends_when_all_landed_with_bonus() -> None:
    env = _tiny(payload=10, n_uavs=2)
    st = env.world.state
    st.pos[:, 2] = 10.0
    st.pos[0, :2], st.pos[1, :2] = [95.0, 100.0], [105.0, 100.0]
    ended, last_rewards = False, None
    for _ in range(200):
        acts = _idle(env, {a: [1.0, 0.0, 0.0] for a in env.agents})
        _, r, term, trunc, _ = env.step(acts)
        if env.agents == []:
            ended, last_rewards = all(term.values()), r
            break
    assert ended and last_rewards is not None
    assert all(v > 1.0 for v in last_rewards.values())  # connectivity / lifetime bonus on top


def test_zones_file_errors_name_zone_and_field(tmp_path) -> None:  # type: ignore[no-untyped-def]
    good = json.loads(open(default_zones_path()).read())
    cases = [
        (lambda d: d["zones"][1].pop("radius"), "zones\\[1\\].*radius"),
        (lambda d: d["zones"][2].__setitem__("radius", -5), "zones\\[2\\].*radius"),
        (lambda d: d["zones"][0].__setitem__("centre", [5, 5]), "zones\\[0\\]"),
        (lambda d: d["zones"][1].__setitem__("profile", "exp"), "zones\\[1\\].*profile"),
    ]
    for k, (mutate, match) in enumerate(cases):
        d = json.loads(json.dumps(good))
        mutate(d)
        p = tmp_path / f"bad{k}.json"
        p.write_text(json.dumps(d))
        with pytest.raises(ValueError, match=match):
            agentsim_env.make("uav_release", zones=str(p))
    with pytest.raises(ValueError, match="payload"):
        agentsim_env.make("uav_release", n_uavs=3, payload=40)  # 150 sensors > 120


@pytest.mark.parametrize(
    ("key", "value", "field"),
    [
        ("n_uavs", 0, "n_agents"),
        ("n_agents", 0, "n_agents"),
        ("sensor_mass", -0.1, "sensor_mass"),
        ("wind", {"mean_speed": -2}, "mean_speed"),
        ("scatter", {"sigma_gnss": -1}, "sigma_gnss"),
        ("comms", {"loss": 2.0}, "loss"),
        ("w_lcc", -1.0, "w_lcc"),
        ("zones", "/no/such/file.json", "file.json"),
        ("action_mode", "fly", "action_mode"),
    ],
)
def test_bad_config_names_field(key: str, value: object, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        agentsim_env.make("uav_release", **{key: value})


def test_render_shows_zones_and_sensors() -> None:
    env = agentsim_env.make("uav_release", zones="tiny", n_uavs=2, payload=12, render_mode="rgb_array")
    env.reset(seed=0)
    img = env.render()
    assert img.ndim == 3 and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) >= 3  # background, zone tint, UAVs


def test_mission_ends_when_zones_are_served_with_spares_on_board() -> None:
    env = _tiny(payload=12, n_uavs=2)  # 24 on board for the tiny zone's 20 sensors
    st = env.world.state
    st.pos[:, 2] = 10.0
    st.pos[0, :2], st.pos[1, :2] = [95.0, 100.0], [105.0, 100.0]
    for k in range(200):
        trigger = 1.0 if k < 10 else -1.0  # 10 releases each, then wait
        _, _, term, _, _ = env.step(_idle(env, {a: [trigger, 0.0, 0.0] for a in env.agents}))
        if not env.agents:
            break
    assert not env.agents and all(term.values())
    assert env.world.task.payload_left.tolist() == [2, 2]
