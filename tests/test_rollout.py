"""``env.rollout(policy, steps, seed)``: the array path gives the step loop's results, policies act on rows."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.env.rollout import EVENT_KEYS, ArrayPolicy, RolloutResult, build_policy, count_events
from agentsim_env.policies.registry import make_policy

# small worlds, each run long enough for arrivals, collisions or traffic
WORLDS: dict[str, dict[str, Any]] = {
    "navigation": {"n_agents": 10, "max_steps": 60},
    "relay": {"n_groups": 2, "group_size": 3, "max_steps": 60},
    "rendezvous": {"n_agents": 6, "max_steps": 60},
}
CASES = [
    ("navigation", "go_to_goal"),
    ("navigation", "random"),
    ("relay", "flood"),
    ("relay", "silent"),
    ("rendezvous", "meet"),
    ("rendezvous", "random"),
]


def step_loop(env: Any, policy: Any, steps: int, seed: int) -> dict[str, Any]:
    """Reset and step through ``step()`` with the dict policy: what ``rollout`` must equal."""
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    returns = np.zeros(len(env.possible_agents))
    events = dict.fromkeys(EVENT_KEYS, 0)
    index = {a: i for i, a in enumerate(env.possible_agents)}
    taken = 0
    while env.agents and taken < steps:
        obs, rew, _, _, _ = env.step(policy.act({a: obs[a] for a in env.agents}))
        taken += 1
        for a, r in rew.items():
            returns[index[a]] += r
        for k, v in count_events(env.world.last_events).items():
            events[k] += v
    return {
        "steps": taken,
        "returns": returns,
        "pos": np.array(env.world.state.pos[: len(returns)]),
        "events": events,
        "agents": list(env.agents),
    }


@pytest.mark.parametrize("steps", [25, 10_000])
@pytest.mark.parametrize(("scenario", "name"), CASES)
def test_rollout_equals_the_step_loop(scenario: str, name: str, steps: int) -> None:
    config = WORLDS[scenario]
    env = agentsim_env.make(scenario, **config)
    want = step_loop(env, make_policy(scenario, env, name), steps, seed=3)
    env2 = agentsim_env.make(scenario, **config)
    got = env2.rollout(name, steps, seed=3)
    assert isinstance(got, RolloutResult)
    assert got.steps == want["steps"] == min(steps, want["steps"])
    np.testing.assert_array_equal(got.returns, want["returns"])
    np.testing.assert_array_equal(got.final_pos, want["pos"])
    assert got.events == want["events"]
    assert env2.agents == want["agents"]  # the env is left where step() leaves it
    assert got.returns.shape == (len(env.possible_agents),) and got.final_pos.shape == (
        len(env.possible_agents),
        3,
    )
    assert got.wall_s > 0 and got.steps_per_s > 0 and "env-steps/s" in got.summary()
    if scenario == "relay" and name == "flood":
        assert got.events["delivered"] > 0  # the comparison covers traffic


def test_a_dict_policy_object_is_wrapped() -> None:
    config = WORLDS["relay"]
    env = agentsim_env.make("relay", **config)
    want = step_loop(env, make_policy("relay", env, "flood"), 30, seed=1)

    class Dicts:  # a dict Policy without act_rows: the slow path
        def __init__(self, inner: Any) -> None:
            self.inner = inner

        def reset(self, seed: int | None = None) -> None:
            self.inner.reset(seed)

        def act(self, observations: dict[str, Any]) -> dict[str, Any]:
            return self.inner.act(observations)

    env2 = agentsim_env.make("relay", **config)
    got = env2.rollout(Dicts(make_policy("relay", env2, "flood")), 30, seed=1)
    np.testing.assert_array_equal(got.returns, want["returns"])
    assert got.events == want["events"]


def _observation_history(scenario: str, steps: int = 6) -> tuple[Any, list[dict[str, np.ndarray]]]:
    """An env and the observation arrays of every agent over a few steps of its default baseline."""
    env = agentsim_env.make(scenario, **WORLDS[scenario])
    obs, _ = env.reset(seed=2)
    policy = make_policy(scenario, env, None)
    policy.reset(2)
    history = []
    for _ in range(steps):
        names = list(env.possible_agents)
        history.append({k: np.stack([obs[a][k] for a in names]) for k in env._obs_keys})
        obs, *_ = env.step(policy.act({a: obs[a] for a in env.agents}))
        if len(env.agents) < len(names):
            break
    return env, history


def _rows_agree(env: Any, make: Any, history: list[dict[str, np.ndarray]]) -> None:
    """Acting on a random subset of slots gives those rows of acting on all, step after step; dict act agrees."""
    n = len(env.possible_agents)
    subset = np.sort(np.random.default_rng(0).choice(n, size=max(1, n // 2), replace=False))
    everyone, some, dicts = make(), make(), make()
    for p in (everyone, some, dicts):
        p.reset(7)
    for step, obs in enumerate(history):
        full = everyone.act_rows(obs, np.arange(n), step)
        part = some.act_rows({k: v[subset] for k, v in obs.items()}, subset, step)
        names = [env.possible_agents[i] for i in subset]
        via_dict = dicts.act({a: {k: obs[k][i] for k in obs} for a, i in zip(names, subset)})
        assert set(full) == set(env.scenario.act_parts())
        for k in full:
            np.testing.assert_array_equal(part[k], full[k][subset], err_msg=f"part {k} at step {step}")
            got = np.stack([np.asarray(via_dict[a][k]) for a in names])
            np.testing.assert_array_equal(got, part[k], err_msg=f"dict act, part {k} at step {step}")


@pytest.mark.parametrize(("scenario", "name"), CASES)
def test_subset_rows_equal_all_rows_and_dict_act(scenario: str, name: str) -> None:
    env, history = _observation_history(scenario)
    policy = make_policy(scenario, env, name)
    assert isinstance(policy, ArrayPolicy)
    _rows_agree(env, lambda: make_policy(scenario, env, name), history)


def test_random_draws_depend_on_the_seed() -> None:
    env, history = _observation_history("navigation", 1)
    p = make_policy("navigation", env, "random")
    slots = np.arange(len(env.possible_agents))
    p.reset(1)
    a = p.act_rows(history[0], slots, 0)["motion"]
    p.reset(2)
    b = p.act_rows(history[0], slots, 0)["motion"]
    assert not np.array_equal(a, b) and (np.abs(a) <= 1).all() and np.unique(a).size > a.size // 2


def test_build_policy_from_picklable_inputs() -> None:
    import pickle

    args = ("relay", WORLDS["relay"], "flood")
    policy = build_policy(*pickle.loads(pickle.dumps(args)))
    env, history = _observation_history("relay")
    _rows_agree(env, lambda: build_policy(*args), history)
    assert isinstance(policy, ArrayPolicy)


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An untrained PPO saved as ``agentsim train`` saves one (navigation, 3 agents)."""
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("trained") / "model"
    folder.mkdir()
    env = {"n_agents": 3, "max_steps": 30}
    vec = AgentSimVecEnv("navigation", 1, seed=0, **env)
    PPO("MlpPolicy", vec, n_steps=16, batch_size=16, seed=0, device="cpu").save(folder / "model.zip")
    vec.close()
    (folder / "config.json").write_text(json.dumps({"scenario": "navigation", "env": env}))
    return folder


def test_a_trained_model_folder_rolls_out(model_dir: Path) -> None:
    from agentsim_env.policies.learned import load_policy

    config = {"n_agents": 3, "max_steps": 30}
    env = agentsim_env.make("navigation", **config)
    want = step_loop(env, load_policy(model_dir, env), 30, seed=4)
    got = agentsim_env.make("navigation", **config).rollout(str(model_dir), 30, seed=4)
    np.testing.assert_array_equal(got.returns, want["returns"])
    np.testing.assert_array_equal(got.final_pos, want["pos"])
    policy = build_policy("navigation", config, str(model_dir))
    env, history = _observation_history("navigation", 3)
    env = agentsim_env.make("navigation", **config)
    obs, _ = env.reset(seed=0)
    history = [{k: np.stack([obs[a][k] for a in env.possible_agents]) for k in env._obs_keys}]
    assert isinstance(policy, ArrayPolicy)
    _rows_agree(env, lambda: build_policy("navigation", config, str(model_dir)), history)


BAD = [
    ({"policy": "nope"}, ("policy", "go_to_goal", "random", "'nope'")),
    ({"policy": 42}, ("policy", "go_to_goal", "int")),
    ({"steps": 0}, ("steps", ">= 1")),
    ({"steps": 2.5}, ("steps", "integer")),
    ({"steps": True}, ("steps", "integer")),
    ({"seed": -1}, ("seed", ">= 0")),
    ({"seed": "x"}, ("seed", "integer")),
]


@pytest.mark.parametrize(("kwargs", "words"), BAD)
def test_bad_inputs_name_the_argument(kwargs: dict[str, Any], words: tuple[str, ...]) -> None:
    env = agentsim_env.make("navigation", n_agents=3, max_steps=5)
    args = {"policy": "go_to_goal", "steps": 5, "seed": 0, **kwargs}
    with pytest.raises(ValueError) as err:
        env.rollout(args["policy"], args["steps"], seed=args["seed"])
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_a_policy_returning_nan_is_named() -> None:
    env = agentsim_env.make("navigation", n_agents=3, max_steps=5)

    class Bad:
        def reset(self, seed: int | None = None) -> None:
            pass

        def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
            return {"motion": np.full((len(slots), 3), np.nan)}

    with pytest.raises(ValueError, match="'motion' holds NaN"):
        env.rollout(Bad(), 5, seed=0)


def test_run_prints_steps_per_second(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    assert (
        main(
            [
                "run",
                "navigation",
                "--episodes",
                "2",
                "--quiet",
                "--out",
                "",
                "--set",
                "n_agents=4",
                "max_steps=10",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "| env-steps/s |" in out and "| agent-steps/s |" in out, out


def _old_fly_mission(env: Any, policy: Any, seed: int) -> dict[str, float]:
    """``fly_mission`` as it stepped through ``step()`` with dicts: what the rollout path must equal."""
    from agentsim_env.uav.evaluation import mission

    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    log = mission.MissionLog(env)
    ps = env.world.payloads.objects
    steps, work_done = 0, False
    while env.agents and not work_done:
        obs, *_ = env.step(policy.act({a: obs[a] for a in env.agents}))
        log.update(env)
        steps += 1
        work_done = ps.n_falling == 0 and mission._work_done(policy)
    return mission.mission_metrics(env, log, steps, work_done)


def test_evaluate_flies_missions_through_rollout(monkeypatch: pytest.MonkeyPatch) -> None:
    from agentsim_env.env.parallel_env import AgentSimParallelEnv
    from agentsim_env.uav.evaluation.mission import fly_mission

    config = {"zones": "tiny", "n_uavs": 2, "payload": 10, "max_steps": 1500}
    env = agentsim_env.make("uav_release", **config)
    want = _old_fly_mission(env, make_policy("uav_release", env, "B2_rings"), 3)
    calls = []
    real = AgentSimParallelEnv.rollout

    def spy(self: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(args)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(AgentSimParallelEnv, "rollout", spy)
    env = agentsim_env.make("uav_release", **config)
    got = fly_mission(env, make_policy("uav_release", env, "B2_rings"), 3)
    assert calls, "fly_mission did not run through env.rollout"
    assert got == want


def test_a_recorded_env_rolls_out_through_its_step(tmp_path: Path) -> None:
    from agentsim_env.recorder import record
    from agentsim_env.recorder.read import Store

    config = {"n_agents": 4, "max_steps": 12}
    want = agentsim_env.make("navigation", **config).rollout("go_to_goal", 12, seed=2)
    env = record(agentsim_env.make("navigation", **config), tmp_path / "r.db")
    got = env.rollout("go_to_goal", 12, seed=2)
    env.close()
    np.testing.assert_array_equal(got.returns, want.returns)
    np.testing.assert_array_equal(got.final_pos, want.final_pos)
    assert got.events == want.events and got.steps == want.steps
    with Store(tmp_path / "r.db") as store:
        steps = store.steps().index.get_level_values("step")
        assert steps.nunique() == want.steps + 1  # every step written, the reset's included


@pytest.mark.parametrize("env_keys", [{"obs_format": "flat", "action_format": "flat"}, {"ended_agents": "stay"}])
def test_rollout_is_the_same_in_every_env_format(env_keys: dict[str, Any]) -> None:
    config = WORLDS["navigation"]
    want = agentsim_env.make("navigation", **config).rollout("go_to_goal", 10_000, seed=6)
    env = agentsim_env.make("navigation", **config, **env_keys)
    got = env.rollout("go_to_goal", 10_000, seed=6)
    np.testing.assert_array_equal(got.returns, want.returns)
    np.testing.assert_array_equal(got.final_pos, want.final_pos)
    assert got.events == want.events and got.steps == want.steps and env.agents == []


def test_a_stay_env_after_a_partial_rollout_lists_what_step_lists() -> None:
    config = {**WORLDS["navigation"], "ended_agents": "stay"}
    stepped = agentsim_env.make("navigation", **config)
    want = step_loop(stepped, make_policy("navigation", stepped, "go_to_goal"), 45, seed=6)
    env = agentsim_env.make("navigation", **config)
    env.rollout("go_to_goal", 45, seed=6)
    assert env.agents == want["agents"] == list(env.possible_agents)
    assert (env._terminated == stepped._terminated).all() and env._terminated.any()
    np.testing.assert_array_equal(env._live_idx, stepped._live_idx)


@pytest.mark.parametrize("scenario", ["navigation", "rendezvous"])
def test_trajectories_recorded_on_arrays_equal_the_dict_loop(scenario: str) -> None:
    from agentsim_env.policies.rollout import run_episode
    from agentsim_env.render.trajectories import TrajectoryRecorder

    config = {**WORLDS[scenario], "max_steps": 80}
    env = agentsim_env.make(scenario, **config)
    by_dicts = TrajectoryRecorder()
    run_episode(env, make_policy(scenario, env, None), 4, on_step=by_dicts)
    want = by_dicts.result(env)
    env = agentsim_env.make(scenario, **config)
    on_arrays = TrajectoryRecorder()
    env.rollout(make_policy(scenario, env, None), config["max_steps"], seed=4, on_step=on_arrays.on_rollout)
    got = on_arrays.result(env)
    np.testing.assert_array_equal(got.xy, want.xy)
    np.testing.assert_array_equal(got.last, want.last)
    assert got.outcome == want.outcome and got.steps == want.steps
    assert len(set(want.outcome)) > 1  # the comparison covers more than one outcome
