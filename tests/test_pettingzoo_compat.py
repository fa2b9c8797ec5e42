"""PettingZoo conventions that RL libraries rely on beyond PettingZoo's own test suite."""

from __future__ import annotations

import os
import subprocess
import sys

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


CORE_INSTALL = """
import sys
sys.modules["websockets"] = None  # a core install: neither the viewer extra nor the render extra imports
sys.modules["pygame"] = None
import agentsim_env
from pettingzoo.test import render_test
from pettingzoo.utils.conversions import parallel_to_aec
from agentsim_env.env.single_agent import SingleAgentEnv

env = agentsim_env.make("navigation", n_agents=2)
print("modes", env.metadata["render_modes"], SingleAgentEnv("navigation", n_agents=1).metadata["render_modes"])
render_test(lambda **kw: parallel_to_aec(agentsim_env.make("navigation", n_agents=2, **kw)))
print("render_test passed")
for mode in ("web", "human"):  # built (render_test builds "human" to read the list), refused when started
    env = agentsim_env.make("navigation", n_agents=2, render_mode=mode)
    try:
        env.reset(seed=0)
    except ImportError as exc:
        print("refused", mode, exc)
"""


def test_render_modes_list_only_what_can_start_on_a_core_install() -> None:
    res = subprocess.run([sys.executable, "-c", CORE_INSTALL], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "SDL_VIDEODRIVER": "dummy"})  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    lines = res.stdout.splitlines()
    assert lines[0] == "modes ['rgb_array'] ['rgb_array']"
    assert "render_test passed" in lines
    web = next(line for line in lines if line.startswith("refused web"))
    human = next(line for line in lines if line.startswith("refused human"))
    assert 'agentsim-env[viewer]' in web and 'agentsim-env[render]' in human


def test_render_modes_with_the_extras_installed() -> None:
    pytest.importorskip("websockets")
    pytest.importorskip("pygame")
    assert agentsim_env.make("navigation", n_agents=2).metadata["render_modes"] == ["human", "rgb_array", "web"]
