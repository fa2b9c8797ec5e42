"""``ended_agents``: agents that end before their episode leave ``agents`` (default) or stay with zeros ("stay")."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env

CFG = {"n_agents": 4, "max_steps": 12}


def _flat(o: Any) -> np.ndarray:
    return np.concatenate([np.ravel(v) for v in o.values()]) if isinstance(o, dict) else np.ravel(o)


def _run(mode: str, fmt: str, offline_at: dict[int, list[int]], seed: int = 0) -> tuple[Any, list]:
    """One episode with seeded random actions for every agent in ``agents``; ``offline_at[t]``: slots taken
    offline before step ``t`` (they end in it). Returns the env and ``(agents_before, step result, state)``."""
    env = agentsim_env.make("navigation", **CFG, ended_agents=mode, obs_format=fmt, action_format=fmt)
    env.reset(seed=seed)
    space = env.action_space(env.possible_agents[0])
    space.seed(seed)
    out = []
    t = 0
    while env.agents:
        t += 1
        if t in offline_at:
            env.world.set_offline(np.array(offline_at[t]))
        before = list(env.agents)
        drawn = {a: space.sample() for a in env.possible_agents}  # the same draws whichever agents are listed
        acts = {a: drawn[a] for a in before}
        out.append((before, env.step(acts), env.state()))
    return env, out


@pytest.mark.parametrize("fmt", ["dict", "flat"])
def test_stay_zeros_until_truncation_at_max_steps(fmt: str) -> None:
    env, steps = _run("stay", fmt, {4: [1], 7: [3]})
    assert len(steps) == CFG["max_steps"]  # ends on time: not a step late, not early
    every = env.possible_agents
    for t, (before, (obs, rew, term, trunc, info), _) in enumerate(steps, start=1):
        assert before == every
        for d in (obs, rew, term, trunc, info):
            assert list(d) == every
        for a, ended in {"agent_1": 4, "agent_3": 7}.items():
            assert term[a] is (t >= ended) and trunc[a] is False  # terminated, and it stays so
            if t > ended:
                assert not _flat(obs[a]).any() and rew[a] == 0.0
                assert info[a].keys() == info["agent_0"].keys() and not any(info[a].values())
        last = t == CFG["max_steps"]
        assert trunc["agent_0"] is last and trunc["agent_2"] is last and term["agent_0"] is False
    assert env.agents == []
    assert env.step({}) == ({}, {}, {}, {}, {})


@pytest.mark.parametrize("fmt", ["dict", "flat"])
def test_stay_ends_the_episode_in_the_step_the_last_agent_ends(fmt: str) -> None:
    env, steps = _run("stay", fmt, {3: [0, 2], 5: [1, 3]})
    assert len(steps) == 5 and env.agents == []
    _, (_, _, term, trunc, _), _ = steps[-1]
    assert all(term.values()) and not any(trunc.values())


def test_stay_live_agents_and_state_match_leave() -> None:
    offline = {4: [1], 7: [3]}
    _, leave = _run("leave", "dict", offline)
    _, stay = _run("stay", "dict", offline)
    assert len(leave) == len(stay)
    for (live, res_l, state_l), (_, res_s, state_s) in zip(leave, stay):
        np.testing.assert_array_equal(state_l, state_s)
        for d_l, d_s in zip(res_l, res_s):
            assert list(d_l) == [a for a in live if a in d_l] and set(d_l) == set(live)
            for a in live:
                np.testing.assert_array_equal(
                    _flat(d_l[a]) if isinstance(d_l[a], dict) else d_l[a],
                    _flat(d_s[a]) if isinstance(d_s[a], dict) else d_s[a],
                )


def test_leave_is_the_default_and_removes_ended_agents() -> None:
    env = agentsim_env.make("navigation", **CFG)
    assert env.ended_agents == "leave"
    _, steps = _run("leave", "flat", {4: [1]})
    before, (obs, *_), _ = steps[4]
    assert "agent_1" not in before and "agent_1" not in obs


def test_stay_accepts_and_ignores_actions_of_ended_agents() -> None:
    env = agentsim_env.make("navigation", **CFG, ended_agents="stay", obs_format="flat", action_format="flat")
    env.reset(seed=1)
    env.world.set_offline(np.array([2]))
    env.step({a: np.zeros(3) for a in env.agents})
    pos = env.world.state.pos[2].copy()
    env.step({a: np.ones(3) for a in env.agents})  # agent_2 ended: its action moves nothing
    np.testing.assert_array_equal(env.world.state.pos[2], pos)
    with pytest.raises(ValueError, match="missing actions"):
        env.step({"agent_2": np.zeros(3)})


def test_bad_ended_agents_names_the_choices() -> None:
    with pytest.raises(ValueError, match=r"ended_agents must be one of \('leave', 'stay'\), got 'keep'"):
        agentsim_env.make("navigation", ended_agents="keep")


def test_supersuit_markov_vector_env_without_black_death() -> None:
    ss = pytest.importorskip("supersuit")
    env = agentsim_env.make("navigation", **CFG, ended_agents="stay", obs_format="flat", action_format="flat")
    vec = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(env), 2, num_cpus=0)
    vec.reset(seed=0)
    par = [v.par_env for v in vec.vec_envs]
    rng = np.random.default_rng(0)
    ended_early = episodes = 0
    for t in range(1, 2 * CFG["max_steps"] + 1):
        if t % CFG["max_steps"] == 5:  # agent_1 of the first copy ends mid-episode
            par[0].world.set_offline(np.array([1]))
        obs, rew, term, trunc, infos = vec.step(rng.uniform(-1, 1, (8, 3)).astype(np.float32))
        assert obs.shape[0] == 8
        if t % CFG["max_steps"] == 5:
            assert term[1] and not term[0]
        if t % CFG["max_steps"] > 5:  # ended: zeros and reward 0, still terminated, until the episode ends
            assert term[1] and rew[1] == 0.0 and not obs[1].any()
            ended_early += 1
        if t % CFG["max_steps"] == 0:  # both copies end on time, every entry truncated or terminated
            assert (term | trunc).all() and "terminal_observation" in infos[0]
            episodes += 1
        else:
            assert not trunc.any()
    assert ended_early > 0 and episodes == 2


def test_aec_refuses_stay() -> None:
    from agentsim_env.env.parallel_env import to_aec

    env = agentsim_env.make("navigation", **CFG, ended_agents="stay")
    with pytest.raises(ValueError, match=r"ended_agents must be 'leave' for the AEC API.*got 'stay'"):
        to_aec(env)
    assert to_aec(agentsim_env.make("navigation", **CFG)).possible_agents == env.possible_agents
