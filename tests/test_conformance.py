"""PettingZoo's own test suite, our multi-step determinism test, and state/space checks, on every case."""

from __future__ import annotations

import pickle
import types
from typing import Any

import numpy as np
import pytest
from pettingzoo.test import api_test, max_cycles_test, parallel_api_test, render_test, seed_test, state_test
from pettingzoo.utils.conversions import parallel_to_aec

import agentsim_env
from tests.cases import case_id, conformance_cases

CASES = conformance_cases()
IDS = [case_id(c) for c in CASES]


def _ctor(name: str, cfg: dict[str, Any]):  # type: ignore[no-untyped-def]
    def parallel(**kw: Any):  # type: ignore[no-untyped-def]
        return agentsim_env.make(name, **{**cfg, **kw})

    def aec(**kw: Any):  # type: ignore[no-untyped-def]
        return parallel_to_aec(parallel(**kw))

    return parallel, aec


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_parallel_api(case: tuple[str, dict]) -> None:
    parallel, _ = _ctor(*case)
    parallel_api_test(parallel(), num_cycles=300)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_aec_api_seed_render_state(case: tuple[str, dict]) -> None:
    parallel, aec = _ctor(*case)
    api_test(aec(), num_cycles=150)
    seed_test(aec, num_cycles=150)
    render_test(aec)
    state_test(aec(), parallel())


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_max_cycles(case: tuple[str, dict]) -> None:
    # PettingZoo's check drives unseeded random actions and expects every agent to reach max_cycles, so an agent
    # ended early by a random collision would fail it by chance: it checks truncation, so collisions are off
    name, cfg = case
    parallel, aec = _ctor(name, {**cfg, "collisions": False})
    max_cycles_test(types.SimpleNamespace(parallel_env=parallel, env=aec))


def _rollout(env: Any, seed: int, steps: int) -> list:
    out = [env.reset(seed=seed)]
    for k, a in enumerate(env.possible_agents):
        env.action_space(a).seed(seed + k)
    for _ in range(steps):
        if not env.agents:
            out.append(env.reset())
        acts = {a: env.action_space(a).sample() for a in env.agents}
        out.append(env.step(acts))
    return out


def _equal(x: Any, y: Any) -> bool:
    if isinstance(x, dict):
        return x.keys() == y.keys() and all(_equal(x[k], y[k]) for k in x)
    if isinstance(x, (list, tuple)):
        return len(x) == len(y) and all(_equal(a, b) for a, b in zip(x, y))
    if isinstance(x, np.ndarray):
        return np.array_equal(x, y)
    return bool(x == y)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_multistep_determinism(case: tuple[str, dict]) -> None:
    """Two envs, same seed, same seeded actions: every returned dict equal for 200 steps."""
    parallel, _ = _ctor(*case)
    a, b = _rollout(parallel(), 7, 200), _rollout(parallel(), 7, 200)
    assert _equal(a, b)
    c = _rollout(parallel(), 8, 5)
    assert not _equal(a[:6], c)


@pytest.mark.parametrize("case", CASES[:2], ids=IDS[:2])
def test_pickle_round_trip(case: tuple[str, dict]) -> None:
    parallel, _ = _ctor(*case)
    env = parallel()
    env.reset(seed=3)
    clone = pickle.loads(pickle.dumps(env))
    acts = {a: env.action_space(a).sample() for a in env.agents}
    assert _equal(env.step(acts), clone.step(acts))


def test_registry_lists_navigation() -> None:
    assert "navigation" in agentsim_env.list_scenarios()
    env = agentsim_env.make("navigation")
    assert env.metadata["name"] == "navigation_v0"
    spaces = [env.observation_space(a) for a in env.possible_agents]
    assert all(s == spaces[0] for s in spaces)


def _zero(x: Any) -> bool:
    return not any(np.any(v) for v in x.values()) if isinstance(x, dict) else not np.any(x)


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_ended_agents_stay(case: tuple[str, dict]) -> None:
    """``ended_agents="stay"`` in lockstep with the default over 300 steps (an agent is taken offline at step 3 of
    every episode, so every scenario has agents ending early): the live agents get exactly the default's results
    and the same state; the agents that ended stay in ``agents`` and in every dict with zero observations (inside
    the space), reward 0, zero infos and the flags they ended with, until the default's episode ends."""
    parallel, _ = _ctor(*case)
    leave, stay = parallel(), parallel(ended_agents="stay")
    every = stay.possible_agents
    space = stay.action_space(every[0])
    space.seed(5)
    ended: dict[str, tuple[bool, bool]] = {}
    steps = episodes = gone_steps = 0
    while steps < 300:
        assert _equal(leave.reset(seed=episodes), stay.reset(seed=episodes))
        episodes += 1
        ended.clear()
        t = 0
        while leave.agents:
            assert stay.agents == every
            t += 1
            if t == 3:
                slot = episodes % len(every)
                leave.world.set_offline(np.array([slot]))
                stay.world.set_offline(np.array([slot]))
            drawn = {a: space.sample() for a in every}
            live = list(leave.agents)
            res_l = leave.step({a: drawn[a] for a in live})
            res_s = stay.step(drawn)  # the ended agents' actions are ignored
            steps += 1
            assert np.array_equal(leave.state(), stay.state())
            obs, rew, term, trunc, info = res_s
            for d_l, d_s in zip(res_l, res_s):
                assert list(d_s) == every and set(d_l) == set(live)
                assert all(_equal(d_l[a], d_s[a]) for a in live)
            for a, flags in ended.items():
                assert _zero(obs[a]) and stay.observation_space(a).contains(obs[a])
                assert rew[a] == 0.0 and (term[a], trunc[a]) == flags and not any(info[a].values())
                gone_steps += 1
            ended.update({a: (term[a], trunc[a]) for a in live if term[a] or trunc[a]})
        assert stay.agents == [] and stay.step({}) == ({}, {}, {}, {}, {})
    assert gone_steps > 0
