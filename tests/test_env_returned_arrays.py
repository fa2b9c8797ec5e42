"""Arrays handed out by ``reset()``, ``step()`` and ``state()`` of both env front ends are the caller's: no later
stage, step or automatic reset writes into them."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.scenarios.registry import list_scenarios, scenario_class


def short_config(name: str) -> dict[str, Any]:
    """The scenario's first test config with episodes short enough to reset often."""
    return {**scenario_class(name).test_configs[0], "max_steps": 4}


def _arrays(value: Any) -> list[np.ndarray]:
    """Every numpy array inside ``value`` (nested dicts, lists and tuples)."""
    if isinstance(value, np.ndarray):
        return [value]
    if isinstance(value, dict):
        value = list(value.values())
    if isinstance(value, (list, tuple)):
        return [a for v in value for a in _arrays(v)]
    return []


def test_infos_of_an_automatic_reset_step_belong_to_the_ended_episode() -> None:
    batch = BatchedEnv("navigation", n_worlds=1, n_agents=2, max_steps=3)
    single = agentsim_env.make("navigation", n_agents=2, max_steps=3, action_format="flat")
    batch.reset(seed=[0])
    single.reset(seed=0)
    for _ in range(3):
        out = batch.step(np.zeros((1, 2, batch.act_dim)))
        _, _, _, _, info = single.step({a: np.zeros(batch.act_dim, np.float32) for a in single.agents})
    assert out.reset_worlds[0]
    assert out.info["distance"][0].tolist() == [info[a]["distance"] for a in single.possible_agents]


@pytest.mark.parametrize("name", list_scenarios())
def test_batched_results_are_never_written_later(name: str) -> None:
    batch = BatchedEnv(name, 3, **short_config(name))
    rng = np.random.default_rng(0)
    held = [batch.reset(seed=1)]
    resets = 0
    for _ in range(12):
        out = batch.step(rng.uniform(-1, 1, (3, batch.n_agents, batch.act_dim)))
        resets += int(out.reset_worlds.sum())
        held += [
            out.obs,
            out.rewards,
            out.terminated,
            out.truncated,
            out.alive,
            out.final_obs,
            out.reset_worlds,
        ]
        held += list(out.info.values())
    assert resets >= 3, "the test should cross automatic resets"
    copies = [a.copy() for a in held]
    batch.reset(seed=2)  # right after a step: that step's results are still the caller's
    for _ in range(6):  # later steps and automatic resets
        batch.step(rng.uniform(-1, 1, (3, batch.n_agents, batch.act_dim)))
    for i, (a, c) in enumerate(zip(held, copies)):
        np.testing.assert_array_equal(a, c, err_msg=f"{name}: returned array {i} was written later")


@pytest.mark.parametrize("name", list_scenarios())
def test_parallel_env_results_are_never_written_later(name: str) -> None:
    env = agentsim_env.make(name, **short_config(name))
    obs, infos = env.reset(seed=1)
    held: list[Any] = [obs, infos, env.state()]
    for episode in range(3):
        while env.agents:
            out = env.step({a: env.action_space(a).sample() for a in env.agents})
            held += [*out, env.state()]
        held += [*env.reset(seed=2 + episode), env.state()]
    arrays = _arrays(held)
    assert len(arrays) > 20
    copies = [a.copy() for a in arrays]
    for _ in range(3):
        env.step({a: env.action_space(a).sample() for a in env.agents})
    env.reset(seed=9)
    for i, (a, c) in enumerate(zip(arrays, copies)):
        np.testing.assert_array_equal(a, c, err_msg=f"{name}: returned array {i} was written later")
