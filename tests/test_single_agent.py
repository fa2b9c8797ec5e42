"""The single-agent Gymnasium view (``agentsim_env.env.single_agent``): both env checkers on every scenario, the
controlled agent and the others, terminated vs truncated, seeding, ``gymnasium.make``, and a short SB3 PPO run."""

from __future__ import annotations

import pickle
import warnings
from typing import Any

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from agentsim_env import list_scenarios
from agentsim_env.env.single_agent import SingleAgentEnv, register_gymnasium_envs

# a small open map with a wide goal: heading for the goal arrives (terminated) within a few dozen steps
OPEN = {"n_agents": 4, "max_steps": 200, "map_size": 20.0, "goal_radius": 3.0, "obstacle_density": 0.0}


def _greedy(obs: np.ndarray) -> np.ndarray:
    """Head for the goal: the task part (last four values) starts with the offset to it."""
    offset = obs[-4:-1]
    return (offset / (np.abs(offset).max() + 1e-9)).astype(np.float32)


def _greedy_all(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {a: _greedy(o) for a, o in obs.items()}


@pytest.mark.parametrize("scenario", list_scenarios())
def test_gymnasium_check_env(scenario: str) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(SingleAgentEnv(scenario), skip_render_check=True)
    # gymnasium's checker warns through gymnasium.logger ("WARN: ...")
    found = [str(w.message) for w in caught if "gymnasium" in w.filename or "WARN:" in str(w.message)]
    assert not found, found


@pytest.mark.parametrize("scenario", list_scenarios())
def test_sb3_check_env(scenario: str) -> None:
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_checker.check_env(SingleAgentEnv(scenario), warn=True)
    assert not [w for w in caught if "stable_baselines3" in w.filename], [str(w.message) for w in caught]


def test_spaces_are_the_flat_ones_of_the_parallel_env() -> None:
    env = SingleAgentEnv("navigation", n_agents=3)
    par = env.par_env
    assert env.agent == par.possible_agents[0]
    assert env.observation_space == par.observation_space(env.agent)
    assert env.action_space == par.action_space(env.agent)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    assert set(info) == set(par.scenario.info_keys())


def test_controls_the_chosen_agent_and_others_act_by_the_callable() -> None:
    calls: list[set[str]] = []

    def others(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        calls.append(set(obs))
        assert all(o.shape == (76,) for o in obs.values())
        return {a: np.array([1.0, 0.0, 0.0], dtype=np.float32) for a in obs}

    env = SingleAgentEnv("navigation", agent="agent_2", others=others, n_agents=3)
    first, _ = env.reset(seed=1)
    obs_all, _ = env.par_env.reset(seed=1)
    assert np.array_equal(first, obs_all["agent_2"])
    env.reset(seed=1)
    for _ in range(3):
        env.step(np.zeros(3, dtype=np.float32))
    assert calls == [{"agent_0", "agent_1"}] * 3


def test_others_default_to_zero_actions() -> None:
    a, b = (
        SingleAgentEnv("navigation", n_agents=3),
        SingleAgentEnv("navigation", n_agents=3, others=lambda obs: {k: np.zeros(3) for k in obs}),
    )
    oa, _ = a.reset(seed=3)
    ob, _ = b.reset(seed=3)
    for _ in range(5):
        act = np.array([0.5, -0.2, 0.0], dtype=np.float32)
        oa, ra, *_ = a.step(act)
        ob, rb, *_ = b.step(act)
        assert np.array_equal(oa, ob) and ra == rb


def test_others_missing_an_action_is_an_error_naming_it() -> None:
    env = SingleAgentEnv("navigation", n_agents=3, others=lambda obs: {})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="agent_1"):
        env.step(np.zeros(3, dtype=np.float32))


def test_truncated_at_the_time_limit_not_terminated() -> None:
    env = SingleAgentEnv("navigation", n_agents=1, max_steps=5)
    env.reset(seed=0)
    ends = [env.step(np.zeros(3, dtype=np.float32))[2:4] for _ in range(5)]
    assert ends == [(False, False)] * 4 + [(False, True)]
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(3, dtype=np.float32))


def test_terminated_when_the_agent_arrives_before_the_limit() -> None:
    env = SingleAgentEnv("navigation", others=_greedy_all, **OPEN)
    obs, _ = env.reset(seed=0)
    steps = 0
    for steps in range(1, OPEN["max_steps"] + 1):  # noqa: B007 - read after the loop
        obs, _, term, trunc, info = env.step(_greedy(obs))
        if term or trunc:
            break
    assert term and not trunc and steps < OPEN["max_steps"] and info["arrived"] == 1


def test_episode_goes_on_when_others_end() -> None:
    """Others leave the world as they arrive; the controlled agent (standing still) keeps stepping."""
    env = SingleAgentEnv("navigation", others=_greedy_all, **OPEN)
    env.reset(seed=0)
    for _ in range(OPEN["max_steps"] - 1):
        _, _, term, trunc, _ = env.step(np.zeros(3, dtype=np.float32))
        assert not (term or trunc)
        if env.par_env.agents == [env.agent]:
            break
    assert env.par_env.agents == [env.agent]
    env.step(np.zeros(3, dtype=np.float32))  # the others get no more calls: none is live


def test_same_seed_same_trajectory() -> None:
    def run(seed: int) -> list[Any]:
        env = SingleAgentEnv("rendezvous")
        out = [env.reset(seed=seed)[0]]
        for t in range(10):
            out.append(env.step(np.full(3, 0.1 * (t % 3), dtype=np.float32))[0])
        return out

    a, b, c = run(7), run(7), run(8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], c[0])


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="agent"):
        SingleAgentEnv("navigation", agent="nobody")
    with pytest.raises(ValueError, match="obs_format"):
        SingleAgentEnv("navigation", obs_format="dict")
    with pytest.raises(ValueError, match="others"):
        SingleAgentEnv("navigation", others=3)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="unknown scenario"):
        SingleAgentEnv("nowhere")


def test_gymnasium_make_after_registering() -> None:
    ids = register_gymnasium_envs()
    assert register_gymnasium_envs() == ids and "agentsim/navigation-v0" in ids
    env = gymnasium.make("agentsim/navigation-v0", n_agents=2, max_steps=3)
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert isinstance(env.unwrapped, SingleAgentEnv) and len(env.unwrapped.par_env.possible_agents) == 2


def test_pickles_mid_episode() -> None:
    env = SingleAgentEnv("navigation", n_agents=2)
    env.reset(seed=0)
    copy = pickle.loads(pickle.dumps(env))
    act = np.array([0.3, 0.1, 0.0], dtype=np.float32)
    assert np.array_equal(env.step(act)[0], copy.step(act)[0])


def test_rgb_render() -> None:
    env = SingleAgentEnv("navigation", n_agents=2, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame is not None and frame.ndim == 3 and frame.shape[2] == 3


def test_sb3_ppo_smoke() -> None:
    sb3 = pytest.importorskip("stable_baselines3")
    env = SingleAgentEnv("navigation", n_agents=2, max_steps=50)
    model = sb3.PPO("MlpPolicy", env, n_steps=256, batch_size=64, n_epochs=2, seed=0, device="cpu")
    model.learn(2048)
    params = np.concatenate([p.detach().numpy().ravel() for p in model.policy.parameters()])
    assert model.num_timesteps >= 2048 and np.isfinite(params).all()
    act, _ = model.predict(env.reset(seed=1)[0], deterministic=True)
    assert env.action_space.contains(act)
