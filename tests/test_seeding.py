"""One random stream per world: world w of a batch reset with seed s behaves exactly like a ParallelEnv reset
with seed s, given the same actions, for every registered scenario, with every source of randomness on (a
lossy, delayed channel, heartbeats, wind with gusts, release scatter); automatic resets continue the seed's
episodes as ``reset()`` without a seed does."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.scenarios.registry import list_scenarios, scenario_class

NOISY_COMMS = {"loss": 0.3, "latency": 2, "heartbeat_period": 5, "heartbeat_timeout": 12}
EXTRA: dict[str, dict[str, Any]] = {
    "uav_release": {
        "wind": {"mean_speed": 3.0, "randomise_speed": (1.0, 5.0), "gust_sigma_frac": 0.3},
        "scatter": {"sigma_gnss": 1.0, "sigma_timing": 0.05, "sigma_bounce": 0.5},
        "payload": 12,
    },
    "navigation": {"gnss": {"sigma_h": 1.0, "sigma_v": 0.3}},
}


def noisy_config(name: str) -> dict[str, Any]:
    """The scenario's first test config with every random element switched on and short episodes."""
    base = dict(scenario_class(name).test_configs[0])
    return {**base, "comms": NOISY_COMMS, "max_steps": 45, **EXTRA.get(name, {})}


@pytest.mark.parametrize("name", list_scenarios())
def test_world_of_a_batch_equals_a_single_env(name: str) -> None:
    cfg = noisy_config(name)
    seeds = [21, 7, 1234]
    w = 1
    batch = BatchedEnv(name, len(seeds), **cfg)
    single = agentsim_env.make(name, obs_format="flat", action_format="flat", **cfg)
    obs_b = batch.reset(seed=seeds)
    obs_s, _ = single.reset(seed=seeds[w])
    agents = single.possible_agents
    rng = np.random.default_rng(3)
    episodes = 0
    for step in range(200):
        for i, a in enumerate(agents):
            if a in obs_s:
                np.testing.assert_array_equal(obs_b[w, i], obs_s[a], err_msg=f"{name}: obs of {a} at step {step}")
        acts = rng.uniform(-1, 1, (len(seeds), batch.n_agents, batch.act_dim)).astype(np.float32)
        out = batch.step(acts)
        live = list(single.agents)
        obs_s, rew, term, trunc, _ = single.step({a: acts[w, agents.index(a)] for a in live})
        for a in live:
            i = agents.index(a)
            assert np.float32(rew[a]) == out.rewards[w, i], f"{name}: reward of {a} at step {step}"
            assert term[a] == out.terminated[w, i] and trunc[a] == out.truncated[w, i], f"{name}: {a} at {step}"
        if out.reset_worlds[w]:
            for a in live:
                np.testing.assert_array_equal(out.final_obs[w, agents.index(a)], obs_s[a])
            assert not single.agents
            obs_s, _ = single.reset()  # the next episode of the same seed
            episodes += 1
        obs_b = out.obs
    assert episodes >= 2, f"{name}: the test should cross automatic resets"


def test_seed_argument_forms() -> None:
    b = BatchedEnv("navigation", 2, n_agents=3)
    one = b.reset(seed=5)
    np.testing.assert_array_equal(one, b.reset(seed=[5, 6]))  # an int s gives world w the seed s + w
    with pytest.raises(ValueError, match="sequence of 2 ints"):
        b.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match=">= 0"):
        b.reset(seed=[1, -2])


def test_a_world_does_not_depend_on_its_neighbours() -> None:
    """The same seed in world 0 gives the same episode whatever the other worlds are seeded with."""
    cfg = noisy_config("uav_release")
    runs = []
    for other in (1, 99):
        b = BatchedEnv("uav_release", 2, **cfg)
        obs = [b.reset(seed=[3, other])[0]]
        rng = np.random.default_rng(0)
        for _ in range(60):
            obs.append(b.step(rng.uniform(-1, 1, (2, b.n_agents, b.act_dim))).obs[0])
        runs.append(np.stack(obs))
    np.testing.assert_array_equal(runs[0], runs[1])
