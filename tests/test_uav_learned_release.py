"""Autopilot mode of ``uav_release`` (the learned-release setting) and trained models in ``agentsim evaluate``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import agentsim_env
from agentsim_env.uav.autopilot import SweepRoutes, lane_segments
from agentsim_env.uav.config import UavReleaseConfig
from agentsim_env.uav.evaluation import runner
from agentsim_env.uav.evaluation.strategies import is_model_token, model_env
from agentsim_env.uav.zones import load_zones, tiny_zones_path

TINY = {"zones": "tiny", "n_agents": 2, "payload": 12, "comms": None}
PILOT = {**TINY, "autopilot": True}
OLD_PARTS = ["self", "lidar", "zones", "landed", "inbox", "comms"]


def _fly(env, trigger, motion: float = 0.0, seed: int = 3, max_steps: int = 5000):
    """Fly ``env`` with a constant motion action and ``trigger(obs) -> release trigger``; per-step logs."""
    obs, _ = env.reset(seed=seed)
    log = []
    for _ in range(max_steps):
        if not env.agents:
            break
        acts = {a: {"motion": np.full(3, motion), "release": np.array([trigger(obs[a]), 0.0, 0.0])} for a in env.agents}
        obs, rew, *_ = env.step(acts)
        log.append((env.world.state.pos[: env.scenario.n_agents].copy(), dict(rew), env.world.task.wp.copy()))
    return log


def test_defaults_keep_the_old_mode() -> None:
    c = UavReleaseConfig()
    assert c.autopilot is False
    env = agentsim_env.make("uav_release", zones="tiny", n_agents=2, payload=12)
    assert list(env.scenario.obs_parts()) == OLD_PARTS
    assert env.scenario.pilot is None
    env.close()


@pytest.mark.parametrize(
    "bad",
    [
        {"autopilot": 1},
        {"autopilot_speed": 0.0},
        {"autopilot_altitude": 100.0},
        {"autopilot_lane": 0.1},
        {"release_cost": -1.0},
        {"autopilot_offset": 1},
    ],
)
def test_autopilot_fields_are_validated(bad: dict) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        agentsim_env.make("uav_release", **TINY, **bad)


def test_sweep_routes_cover_every_zone_in_equal_shares() -> None:
    zones = load_zones(tiny_zones_path())
    segs = lane_segments(zones, np.array([10.0, 10.0]), 10.0)
    assert len(segs) == 8  # 2 r / spacing lanes over the 40 m zone
    for a, b in segs:
        assert np.all(zones.zone_index(np.vstack([a, b]) * 0.999 + zones.centres()[0] * 0.001) == 0)
    routes = SweepRoutes(zones, np.array([10.0, 10.0]), 3, 10.0)
    lanes = [np.linalg.norm(np.diff(routes.points[j, : routes.n_wp[j]], axis=0), axis=1) for j in range(3)]
    in_zone = [seg.sum() for seg in lanes]
    assert max(in_zone) - min(in_zone) < 20.0  # equal lane length per UAV, up to the links between lanes


def test_autopilot_flies_itself_and_masks_releases_in_transit() -> None:
    env = agentsim_env.make("uav_release", **PILOT)
    assert list(env.scenario.obs_parts())[-1] == "autopilot"
    a = _fly(env, lambda o: -1.0, motion=0.0, max_steps=300)
    b = _fly(env, lambda o: -1.0, motion=1.0, max_steps=300)
    np.testing.assert_allclose(a[-1][0], b[-1][0])  # motion actions are ignored
    c = _fly(env, lambda o: 1.0, max_steps=5000)  # always trying to release
    transit = [i for i, (_, _, wp) in enumerate(c) if (wp[:2] == 0).all()]
    assert transit  # some steps in transit...
    assert env.world.payloads.objects.get("owner").size > 0
    t_first = env.world.payloads.objects.get("release_t").min()
    assert t_first >= (max(transit) + 1) * env.scenario.config.dt - 1e-9  # ...and no release before the sweep
    assert not env.agents  # payload empty: the mission ended
    env.close()


def _sides(routes, log) -> list[float]:
    """Per step and UAV on a leg after its first one: the signed distance of the UAV to the left of its leg."""
    out = []
    for pos, _, wp in log:
        for j in range(pos.shape[0]):
            if 2 <= wp[j] < routes.n_wp[j]:
                a, b = routes.points[j, wp[j] - 1], routes.points[j, wp[j]]
                u = (b - a) / max(np.linalg.norm(b - a), 1e-9)
                out.append(float(u[0] * (pos[j, 1] - a[1]) - u[1] * (pos[j, 0] - a[0])))
    return out


def test_lane_offset_action_moves_the_sweep_sideways() -> None:
    """``autopilot_offset``: motion[0] = +-1 flies half a lane to either side of the lane while sweeping, 0 on the
    lane; transit is not offset; without the flag motion is ignored (the test above)."""
    plain = agentsim_env.make("uav_release", **PILOT)
    ref = _fly(plain, lambda o: -1.0, motion=0.0, max_steps=400)
    plain.close()
    env = agentsim_env.make("uav_release", **PILOT, autopilot_offset=True)
    lane = env.scenario.config.autopilot_lane
    routes = env.scenario.pilot.routes
    runs = {m: _fly(env, lambda o: -1.0, motion=m, max_steps=400) for m in (0.0, 1.0, -1.0)}
    for m, log in runs.items():  # transit: the plain autopilot's flight
        for (p0, _, w0), (p1, _, w1) in zip(ref, log, strict=True):
            if (w0 == 0).all() and (w1 == 0).all():
                np.testing.assert_array_equal(p0, p1, err_msg=f"motion {m}")
    left, right, centre = (np.array(_sides(routes, runs[m])) for m in (1.0, -1.0, 0.0))
    assert min(len(left), len(right), len(centre)) > 50
    # most of the time each track sits on its side of the leg, about half a lane off (it turns at the corners)
    assert np.median(left) > 0.4 * lane and np.median(right) < -0.4 * lane
    assert np.median(np.abs(centre)) < 1.0
    assert np.abs(np.concatenate([left, right])).max() < 0.5 * lane + 4.0
    env.close()


def test_release_goes_to_the_predicted_landing_point() -> None:
    env = agentsim_env.make("uav_release", **PILOT)
    _fly(env, lambda o: 1.0 if o["autopilot"][0] > -0.5 else -1.0)
    ps = env.world.payloads.objects
    done = ps.get("landed")
    assert done.sum() >= 10
    miss = np.linalg.norm(ps.get("land_xy")[done] - ps.get("target_xy")[done], axis=1)
    assert np.median(miss) < 5.0  # scatter and gusts only
    env.close()


def test_shaped_return_is_coverage_minus_a_constant() -> None:
    """Only coverage weighted: the episode's return is w_coverage x coverage - cost x payload (any policy)."""
    zero = {k: 0.0 for k in ("w_fidelity", "w_energy", "w_miss", "w_out", "w_lcc", "w_lifetime")}
    env = agentsim_env.make("uav_release", **{**PILOT, "payload": 20}, **zero, w_coverage=100.0, release_cost=1.0)
    cfg, n = env.scenario.config, env.scenario.zones.n_sensors
    for rule in (lambda o: 1.0 if o["autopilot"][0] > 0.0 else -1.0, lambda o: -1.0):
        log = _fly(env, rule)
        total = sum(sum(r.values()) for _, r, _ in log)
        cov = env.world.task.tracker.weighted_coverage(0)
        constant = 100.0 * cfg.release_cost / n * cfg.payload * cfg.n_agents
        assert total == pytest.approx(100.0 * cov - constant, abs=0.05 * constant)
    env.close()


# ------------------------------------------------------------------------------- trained models in evaluate
def _save_model(folder: Path, scenario: str = "uav_release", env_cfg: dict | None = None) -> Path:
    """An untrained PPO on the autopilot env, saved as ``agentsim train`` does (model.zip + config.json)."""
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv

    torch.set_num_threads(1)
    env_cfg = dict(PILOT if env_cfg is None else env_cfg)
    vec = AgentSimVecEnv("uav_release", 1, seed=0, **env_cfg)
    PPO("MlpPolicy", vec, n_steps=16, batch_size=16, seed=0, device="cpu").save(folder / "model.zip")
    vec.close()
    (folder / "config.json").write_text(json.dumps({"scenario": scenario, "env": env_cfg}))
    return folder


def test_model_folder_token_is_checked(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    assert is_model_token(str(empty)) and not is_model_token("B0_uniform")
    with pytest.raises(ValueError, match="lacks model.zip and config.json"):
        runner.resolve_strategies([str(empty)])
    with pytest.raises(ValueError, match="does not exist"):
        runner.resolve_strategies([str(tmp_path / "nope") + "/"])
    other = tmp_path / "other"
    other.mkdir()
    (other / "model.zip").write_bytes(b"")
    (other / "config.json").write_text(json.dumps({"scenario": "navigation", "env": {}}))
    with pytest.raises(ValueError, match="trained on scenario 'navigation'"):
        runner.resolve_strategies([str(other)])


def test_trained_model_flies_in_evaluate_with_its_env(tmp_path: Path) -> None:
    folder = tmp_path / "pilot_model"
    folder.mkdir()
    _save_model(folder)
    token = str(folder)
    assert runner.resolve_strategies([token, "B0_uniform"]) == [token, "B0_uniform"]
    assert runner.strategy_labels([token, "B0_uniform"]) == ["pilot_model", "B0_uniform"]
    assert model_env(token, "uav_release")["autopilot"] is True
    grid = runner.run_grid(["tiny"], [token], [0], {"n_agents": 2, "payload": 12}, progress=False)
    assert grid.strategies == ["pilot_model"]
    (run,) = [r for r in grid.runs if r.strategy == "pilot_model"]
    assert run.metrics["steps"] > 0 and np.isfinite(run.metrics["coverage_weighted"])
    # the model's env (autopilot) was used: the fleet flew its sweep, far from the base
    assert run.metrics["path_length_m"] > 100.0


def test_scripted_release_without_comms_and_refused_with_autopilot() -> None:
    import agentsim_env
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.policies.rollout import run_episode

    env = agentsim_env.make("uav_release", zones="tiny", n_uavs=1, payload=20, comms=None)
    policy = make_policy("uav_release", env, "B0_uniform")  # no comms: the UAVs do not coordinate
    assert policy.coordinate is False
    ep = run_episode(env, policy, 0)
    assert ep.info_sums["landed"] == 20
    with pytest.raises(ValueError, match="coordinate=True needs comms"):
        from agentsim_env.policies.release.policy import ReleasePolicy

        ReleasePolicy(env, "B0_uniform", coordinate=True)
    with pytest.raises(ValueError, match="needs autopilot=False"):
        make_policy("uav_release", agentsim_env.make("uav_release", zones="tiny", autopilot=True), "B5_cvt")
