"""Release strategies B0-B8 flying ``uav_release``: containment, fidelity, density benefit, sectors, reclaim."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy.stats import kstest

import agentsim_env
from agentsim_env.comms.messages import FEATURES_PER_MESSAGE
from agentsim_env.policies.registry import baseline_names, make_policy
from agentsim_env.policies.release import ReleasePolicy, split_work, strategy_names
from agentsim_env.policies.release.coordination import (
    MSG_CLAIM,
    MSG_DONE,
    MSG_HELLO,
    MSG_RELEASED,
    MissionView,
    TargetBook,
    decode,
    encode,
)
from agentsim_env.policies.release.planning import in_sector
from agentsim_env.uav.wsn import evaluate_deployment

CALM = {"wind": {"mean_speed": 0.0}, "scatter": {"sigma_gnss": 0.5, "sigma_timing": 0.0, "sigma_bounce": 0.0}}
TINY = {"zones": "tiny", "n_uavs": 2, "payload": 12, **CALM}


def fly(env: Any, policy: ReleasePolicy, seed: int, *, max_steps: int = 8000, hook: Any = None) -> int:
    """Run until the policy's mission is complete and nothing is falling (or the env ends); returns steps."""
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    steps = 0
    while env.agents and steps < max_steps:
        obs, *_ = env.step(policy.act({a: obs[a] for a in env.agents}))
        steps += 1
        if hook is not None:
            hook(env, obs, steps)
        if policy.mission_complete and env.world.payloads.objects.n_falling == 0:
            break
    return steps


def sensors(env: Any) -> dict[str, np.ndarray]:
    """Released sensors of world 0: owner slot, zone, target and landing point."""
    ps = env.world.payloads.objects
    n = ps.count
    return {k: ps.get(k)[:n] for k in ("owner", "zone", "target_xy", "land_xy", "landed")}


def test_registry_builds_every_strategy_default_first() -> None:
    names = baseline_names("uav_release")
    assert names[0] == "B5_cvt" and set(names) == set(strategy_names())
    env = agentsim_env.make("uav_release", **TINY)
    pol = make_policy("uav_release", env, "B2_rings")
    assert isinstance(pol, ReleasePolicy) and pol.strategy == "B2_rings"


@pytest.mark.parametrize("strategy", strategy_names())
def test_every_strategy_lands_in_its_zone_without_wind(strategy: str) -> None:
    env = agentsim_env.make("uav_release", **TINY)
    pol = ReleasePolicy(env, strategy)
    fly(env, pol, seed=0)
    s = sensors(env)
    zones = env.scenario.zones
    assert s["landed"].all() and s["owner"].size == zones.n_sensors  # every sensor of the zone released
    inside = zones.zone_index(s["land_xy"]) == s["zone"]
    assert inside.mean() >= 0.95
    assert np.mean(np.hypot(*(s["land_xy"] - s["target_xy"]).T)) < 1.0  # GNSS error 0.5 m dominates


def test_inverse_cdf_matches_the_radial_profile_with_1000_sensors() -> None:
    zone = {
        "centre": [200, 200],
        "radius": 150,
        "n_sensors": 1000,
        "profile": "gauss",
        "sigma": 60,
        "floor": 0.05,
        "altitude": 12,
    }
    env = agentsim_env.make(
        "uav_release",
        zones={"map_size": [400, 400], "base": [20, 20], "zones": [zone]},
        n_uavs=10,
        payload=100,
        max_steps=20000,
        **CALM,
    )
    fly(env, ReleasePolicy(env, "B1_inverse_cdf", coordinate=False), seed=0, max_steps=20000)
    s = sensors(env)
    assert s["landed"].sum() == 1000
    r = np.hypot(*(s["land_xy"] - np.array([200.0, 200.0])).T)
    profile = env.scenario.zones.zones[0].radial_profile()
    assert kstest(r, profile.cdf).pvalue > 0.01
    # the test can fail: uniform radii (B0) are rejected by the same test
    assert kstest(150 * np.sqrt(np.random.default_rng(0).random(1000)), profile.cdf).pvalue < 0.01


def _evaluate(env: Any) -> dict[str, float]:
    s = sensors(env)
    zs = env.scenario.zones
    profiles = [z.radial_profile() for z in zs.zones]
    return evaluate_deployment(s["land_xy"], s["zone"], zs.centres(), zs.radii(), profiles, env.scenario.config.wsn)


def test_density_weighted_strategies_beat_uniform_on_the_default_zones() -> None:
    scores: dict[str, tuple[float, float]] = {}
    for strategy in ("B0_uniform", "B1_inverse_cdf", "B5_cvt"):
        cov, fnd = [], []
        for seed in (0, 1):
            env = agentsim_env.make("uav_release")
            fly(env, ReleasePolicy(env, strategy), seed=seed)
            ev = _evaluate(env)
            assert ev["n_sensors"] == 150
            cov.append(ev["coverage_weighted"])
            fnd.append(ev["fnd"])
        scores[strategy] = (float(np.mean(cov)), float(np.mean(fnd)))
    for strategy in ("B1_inverse_cdf", "B5_cvt"):
        assert scores[strategy][0] > scores["B0_uniform"][0], scores
        assert scores[strategy][1] > scores["B0_uniform"][1], scores


def _group_messages(obs: dict[str, Any], map_size: tuple[float, float], payload: int) -> dict[str, np.ndarray]:
    rows = np.concatenate([o["inbox"] for o in obs.values()])
    rows = rows[(rows[:, 0] > 0.5) & (rows[:, 2] > 0.5)]
    return decode(rows[:, FEATURES_PER_MESSAGE : FEATURES_PER_MESSAGE + 6], map_size, payload)


def test_two_uavs_release_in_disjoint_wedges_and_talk() -> None:
    env = agentsim_env.make("uav_release", **TINY)
    seen: set[int] = set()
    senders: set[int] = set()
    zs = env.scenario.zones

    def hook(env: Any, obs: dict[str, Any], step: int) -> None:
        msg = _group_messages(obs, zs.map_size, 12)
        seen.update(msg["kind"].tolist())
        senders.update(msg["uav"].tolist())

    fly(env, ReleasePolicy(env, "B5_cvt"), seed=0, hook=hook)
    assert {MSG_HELLO, MSG_CLAIM, MSG_RELEASED, MSG_DONE} <= seen and senders == {0, 1}
    s = sensors(env)
    pieces = split_work(zs, 2, 12)
    assert [p.uav for p in pieces] == [0, 1] and all(p.sector is not None for p in pieces)
    centre = np.asarray(zs.zones[0].centre)
    for p in pieces:
        mine = s["owner"] == p.uav
        assert mine.sum() >= 8
        assert in_sector(s["target_xy"][mine] - centre, p.sector).all()  # targets: exactly in its wedge
        far = mine & (np.hypot(*(s["land_xy"] - centre).T) > 5.0)
        assert in_sector(s["land_xy"][far] - centre, p.sector).mean() >= 0.9  # landings: up to the edge errors
    a, b = (in_sector(s["target_xy"] - centre, p.sector) for p in pieces)
    assert not np.any(a & b)  # the wedges are disjoint


@pytest.mark.parametrize("coordinate", [True, False])
def test_lost_uav_work_is_reclaimed_only_with_coordination(coordinate: bool) -> None:
    env = agentsim_env.make("uav_release", **{**TINY, "payload": 20})
    pol = ReleasePolicy(env, "B1LD_sunflower", coordinate=coordinate)
    state = {"lost_at": None}

    def hook(env: Any, obs: dict[str, Any], step: int) -> None:
        s = sensors(env)
        if state["lost_at"] is None and np.sum(s["owner"] == 1) >= 3:
            env.world.set_offline(np.array([1]))
            state["lost_at"] = step

    fly(env, pol, seed=0, hook=hook)
    assert state["lost_at"] is not None
    s = sensors(env)
    n1 = int(np.sum(s["owner"] == 1))
    assert n1 < 10  # UAV 1 did not finish its half
    targets = pol.book.xy
    done = np.array([np.min(np.hypot(*(s["target_xy"] - t).T)) < 1e-3 for t in targets])  # float32 actions
    if coordinate:
        assert done.all() and s["owner"].size == 20  # UAV 0 flew UAV 1's remaining targets
        assert np.sum(s["owner"] == 0) == 20 - n1
    else:
        assert s["owner"].size == 10 + n1 and not done.all()


# ---------------------------------------------------------------------------------------------- protocol units


def test_split_work_chunks_respect_payload_and_cover_every_sensor() -> None:
    zs = agentsim_env.make("uav_release").scenario.zones
    pieces = split_work(zs, 4, 40)
    per_uav = np.bincount([p.uav for p in pieces], weights=[p.count for p in pieces], minlength=4)
    assert per_uav.max() <= math.ceil(150 / 4) and per_uav.sum() == 150
    for k, z in enumerate(zs.zones):
        assert sum(p.count for p in pieces if p.zone == k) == z.n_sensors
        widths = [p.sector[1] - p.sector[0] for p in pieces if p.zone == k and p.sector is not None]
        assert sum(widths) == pytest.approx(2 * math.pi) or not widths
    with pytest.raises(ValueError, match="payload"):
        split_work(zs, 4, 30)


def test_message_round_trip() -> None:
    msg = np.stack(
        [
            encode(MSG_RELEASED, 3, (123.25, 45.5), (600.0, 400.0), zone=2, piece=7),
            encode(MSG_DONE, 1, (10.0, 20.0), (600.0, 400.0), payload_frac=5 / 40),
        ]
    )
    assert msg.dtype == np.float32 and np.all(np.abs(msg) <= 1.0)
    d = decode(msg, (600.0, 400.0), 40)
    assert d["kind"].tolist() == [MSG_RELEASED, MSG_DONE] and d["uav"].tolist() == [3, 1]
    assert d["zone"][0] == 2 and d["piece"][0] == 7 and d["left"][1] == 5
    assert np.allclose(d["xy"][0], (123.25, 45.5), atol=1e-3)
    with pytest.raises(ValueError, match="kind"):
        encode(9, 0, (0, 0), (1.0, 1.0))


def test_view_reclaim_goes_to_the_lowest_idle_uav() -> None:
    zs = agentsim_env.make("uav_release").scenario.zones
    pieces = split_work(zs, 3, 50)
    xy = np.arange(12, dtype=float).reshape(6, 2)
    book = TargetBook(xy, np.zeros(6, np.int64), np.zeros(6, np.int64), np.array([2, 2, 2, 2, 0, 1]), pieces)
    views = [MissionView(j, book, 3, 50) for j in range(3)]
    released = decode(encode(MSG_RELEASED, 2, xy[0], zs.map_size, piece=0)[None], zs.map_size, 50)
    for j in (0, 1):
        views[j].hear(5, released, 0, lost_after=10)
    # before the timeout nobody is lost
    assert views[0].reclaim(10, 10, 50).size == 0
    # both 0 and 1 idle with payload: the lower id takes UAV 2's 3 unreleased targets, in order
    done = decode(encode(MSG_DONE, 0, (0, 0), zs.map_size, payload_frac=0.5)[None], zs.map_size, 50)
    hello = decode(encode(MSG_HELLO, 1, (0, 0), zs.map_size, payload_frac=0.5)[None], zs.map_size, 50)
    views[1].hear(25, done, 0, lost_after=10)
    views[0].hear(25, hello, 0, lost_after=10)
    assert views[1].reclaim(30, 10, 50).size == 0
    assert views[0].reclaim(30, 10, 2).tolist() == [1, 2]  # only what its payload allows
    assert views[0].owner[1] == 0 and views[0].orphans(30, 10).tolist() == [3]


def test_a_target_claim_moves_ownership_and_bad_input_names_the_field() -> None:
    env = agentsim_env.make("uav_release", **TINY)
    zs = env.scenario.zones
    pieces = split_work(zs, 2, 12)
    book = TargetBook(
        np.array([[90.0, 100.0]]), np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1, np.int64), pieces
    )
    view = MissionView(0, book, 2, 12)
    claim = decode(encode(MSG_CLAIM, 1, (90.0, 100.0), zs.map_size, piece=0)[None], zs.map_size, 12)
    view.hear(3, claim, 0, lost_after=10)
    assert view.owner[0] == 1 and not view.reclaiming[1]  # UAV 0 was alive: a plain hand-over, not a reclaim
    with pytest.raises(ValueError, match="strategy"):
        ReleasePolicy(env, "B9_magic")
    with pytest.raises(ValueError, match="release_speed"):
        ReleasePolicy(env, "B2_rings", release_speed=99.0)
    with pytest.raises(ValueError, match="action_mode"):
        ReleasePolicy(agentsim_env.make("uav_release", **TINY, action_mode="primitive"), "B2_rings")
    with pytest.raises(ValueError, match="comms.payload_dim"):
        ReleasePolicy(agentsim_env.make("uav_release", **TINY, comms={"payload_dim": 4}), "B2_rings")
    flat = agentsim_env.make("uav_release", **TINY, obs_format="flat")
    obs, _ = flat.reset(seed=0)
    with pytest.raises(ValueError, match="Dict observations"):
        ReleasePolicy(flat, "B2_rings").act(obs)
