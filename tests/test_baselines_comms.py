"""Every scripted baseline acts on every action part its scenario's config creates.

A config decides the action parts: ``comm`` exists when ``comms`` is set, and ``motion`` is (3,) in velocity
mode and (8,) in primitive mode. A baseline written for the default config must still hand the env a
complete, well-shaped action when comms are switched on or off (a silent ``comm`` part: channel "none")
and, for the velocity baselines, in primitive mode (the "velocity" primitive with the same velocity).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.cli import main
from agentsim_env.policies.registry import baseline_names, make_policy
from agentsim_env.uav.zones import tiny_zones_path

SCENARIOS = agentsim_env.list_scenarios()
CASES = [(s, b) for s in SCENARIOS for b in baseline_names(s)]
SMALL: dict[str, dict[str, Any]] = {"uav_release": {"zones": str(tiny_zones_path())}}


def _make(scenario: str, **config: Any) -> Any:
    """The scenario's env, or None when its config refuses ``config`` (``relay`` always has comms)."""
    try:
        return agentsim_env.make(scenario, **SMALL.get(scenario, {}), **config)
    except ValueError as exc:
        if config.get("comms", "") is None and "comms" in str(exc):
            return None
        raise


def _roll(env: Any, policy: Any, steps: int = 2) -> None:
    """A few steps of ``policy``, checking that each action has exactly the env's parts in their shapes."""
    parts = {k: s.shape for k, s in env.action_space(env.possible_agents[0]).items()}
    obs, _ = env.reset(seed=0)
    policy.reset(0)
    for _ in range(steps):
        if not env.agents:
            break
        acts = policy.act({a: obs[a] for a in env.agents})
        assert set(acts) == set(env.agents)
        for a, act in acts.items():
            assert {k: np.shape(v) for k, v in act.items()} == parts, (a, act)
        obs, *_ = env.step(acts)


def test_every_scenario_has_baselines() -> None:
    assert SCENARIOS and all(baseline_names(s) for s in SCENARIOS)


@pytest.mark.parametrize("comms", ["off", "on"])
@pytest.mark.parametrize(("scenario", "baseline"), CASES, ids=[f"{s}-{b}" for s, b in CASES])
def test_baseline_acts_on_every_part_with_comms_on_and_off(scenario: str, baseline: str, comms: str) -> None:
    env = _make(scenario, comms=None if comms == "off" else {})
    if env is None:
        assert scenario == "relay"  # the one scenario that cannot run without comms
        return
    assert ("comm" in env.scenario.act_parts()) == (comms == "on")
    _roll(env, make_policy(scenario, env, baseline))


@pytest.mark.parametrize(("scenario", "baseline"), CASES, ids=[f"{s}-{b}" for s, b in CASES])
def test_baseline_in_primitive_mode_acts_or_refuses_at_once(scenario: str, baseline: str) -> None:
    env = _make(scenario, action_mode="primitive")
    assert env.scenario.act_parts()["motion"].shape == (8,)
    try:
        policy = make_policy(scenario, env, baseline)
    except ValueError as exc:  # a baseline that needs velocity mode says so when it is built
        assert "action_mode" in str(exc)
        return
    _roll(env, policy)


@pytest.mark.parametrize("scenario", ["navigation", "rendezvous"])
def test_velocity_baseline_flies_the_same_in_primitive_mode(scenario: str) -> None:
    """The "velocity" primitive with the baseline's velocity: the same flight as in velocity mode."""
    paths = []
    for mode in ("velocity", "primitive"):
        env = agentsim_env.make(scenario, n_agents=3, action_mode=mode)
        policy = make_policy(scenario, env)
        obs, _ = env.reset(seed=2)
        for _ in range(5):
            obs, *_ = env.step(policy.act(obs))
        paths.append(env.world.state.pos.copy())
    np.testing.assert_allclose(paths[0], paths[1], atol=1e-9)


def test_cli_run_with_comms_uses_the_default_baseline(tmp_path: Path) -> None:
    argv = ["run", "navigation", "--episodes", "1", "--set", "n_agents=2", "max_steps=5", "comms={}"]
    assert main([*argv, "--out", "", "--quiet"]) == 0
