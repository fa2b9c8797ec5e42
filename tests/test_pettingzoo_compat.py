"""PettingZoo conventions that RL libraries rely on beyond PettingZoo's own test suite."""

from __future__ import annotations

import pytest

import agentsim_env


@pytest.mark.parametrize("fmt", ["dict", "flat"])
def test_public_space_dicts_are_the_cached_spaces(fmt: str) -> None:
    # skrl's PettingZoo wrapper reads env.observation_spaces / env.action_spaces (ParallelEnv's declared fields)
    env = agentsim_env.make("navigation", n_agents=3, obs_format=fmt, action_format=fmt)
    assert list(env.observation_spaces) == env.possible_agents
    assert list(env.action_spaces) == env.possible_agents
    for a in env.possible_agents:
        assert env.observation_spaces[a] is env.observation_space(a)
        assert env.action_spaces[a] is env.action_space(a)
    assert env.observation_spaces[env.possible_agents[0]] is env.observation_spaces[env.possible_agents[-1]]
