"""PettingZoo conventions that RL libraries rely on beyond PettingZoo's own test suite."""

from __future__ import annotations

import os
import subprocess
import sys
import types

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
    res = subprocess.run(
        [sys.executable, "-c", CORE_INSTALL],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "SDL_VIDEODRIVER": "dummy"},
    )
    assert res.returncode == 0, res.stderr[-3000:]
    lines = res.stdout.splitlines()
    assert lines[0] == "modes ['rgb_array'] ['rgb_array']"
    assert "render_test passed" in lines
    web = next(line for line in lines if line.startswith("refused web"))
    human = next(line for line in lines if line.startswith("refused human"))
    assert "agentsim-env[viewer]" in web and "agentsim-env[render]" in human


def test_render_modes_with_the_extras_installed() -> None:
    pytest.importorskip("websockets")
    pytest.importorskip("pygame")
    assert agentsim_env.make("navigation", n_agents=2).metadata["render_modes"] == [
        "human",
        "rgb_array",
        "web",
    ]


def test_aec_constructor_beside_parallel_env() -> None:
    from pettingzoo import AECEnv
    from pettingzoo.test import api_test

    aec = agentsim_env.env("navigation", n_agents=3, max_cycles=20)
    assert isinstance(aec, AECEnv)
    assert aec.possible_agents == agentsim_env.parallel_env("navigation", n_agents=3).possible_agents
    api_test(aec, num_cycles=30)
    with pytest.raises(ValueError, match="ended_agents must be 'leave' for the AEC API"):
        agentsim_env.env("navigation", ended_agents="stay")
    with pytest.raises(ValueError, match="unknown config key"):
        agentsim_env.env("navigation", n_agnets=3)
    # the name is also the env subpackage's: its modules stay reachable as attributes
    import agentsim_env.env.vector as vector
    from agentsim_env.env import single_agent

    assert agentsim_env.env.vector is vector and agentsim_env.env.single_agent is single_agent


@pytest.mark.parametrize("name", agentsim_env.list_scenarios())
def test_per_scenario_modules_the_pettingzoo_way(name: str) -> None:
    # as pettingzoo.mpe.simple_v3: module <name>_v<version> with parallel_env, env (AEC) and raw_env
    import importlib

    from pettingzoo import AECEnv
    from pettingzoo.test import max_cycles_test

    from agentsim_env.scenarios.registry import scenario_class

    module_name = f"{name}_v{scenario_class(name).version}"
    mod = importlib.import_module(f"agentsim_env.zoo.{module_name}")
    par = mod.parallel_env()
    assert par.metadata["name"] == module_name
    assert isinstance(mod.env(), AECEnv) and isinstance(mod.raw_env(), AECEnv)
    assert mod.raw_env().unwrapped is not None
    # PettingZoo's check drives random actions and wants every agent to reach max_cycles: collisions off
    collisions_off = types.SimpleNamespace(
        parallel_env=lambda **kw: mod.parallel_env(collisions=False, **kw),
        env=lambda **kw: mod.env(collisions=False, **kw),
    )
    max_cycles_test(collisions_off)


GYMNASIUM_BY_ID = """
import gymnasium
import agentsim_env
assert not [i for i in gymnasium.registry if i.startswith("agentsim/")]  # importing the package registers nothing
env = gymnasium.make("agentsim_env.gymnasium_envs:agentsim/navigation-v0", n_agents=1)
print(type(env.unwrapped).__name__, env.observation_space.shape)
print(sorted(i for i in gymnasium.registry if i.startswith("agentsim/")))
"""


def test_gymnasium_ids_registered_by_importing_one_module() -> None:
    res = subprocess.run([sys.executable, "-c", GYMNASIUM_BY_ID], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-3000:]
    first, ids = res.stdout.splitlines()[:2]
    assert first.startswith("SingleAgentEnv (")
    assert ids == str(sorted(f"agentsim/{n}-v0" for n in agentsim_env.list_scenarios()))
