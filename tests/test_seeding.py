"""One random stream per world: world w of a batch reset with seed s behaves exactly like a ParallelEnv reset
with seed s, given the same actions, for every registered scenario, with every source of randomness on (a
lossy, delayed channel, heartbeats, wind with gusts, release scatter); automatic resets continue the seed's
episodes as ``reset()`` without a seed does. Collisions with objects of worlds other than 0 name the object as the
single env does, and the infos of a step that resets a world are those of the episode that ended."""

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


CRASH_CONFIG: dict[str, Any] = {
    "n_agents": 4,
    "comms": NOISY_COMMS,
    "max_steps": 45,
    "map_size": 60.0,
    "obstacle_density": 0.005,
    "obstacle_height": (20.0, 30.0),
}
"""Navigation with tall obstacles, flown into by ``crash_actions``: agents of every world hit objects."""


def random_actions(batch: BatchedEnv, rng: np.random.Generator) -> np.ndarray:
    """Uniform actions for every agent of every world."""
    return rng.uniform(-1, 1, (batch.n_worlds, batch.n_agents, batch.act_dim)).astype(np.float32)


def crash_actions(batch: BatchedEnv, rng: np.random.Generator) -> np.ndarray:
    """Random actions whose navigation velocity (the first 3 values) heads for the nearest object of the world."""
    acts = random_actions(batch, rng)
    st, scene = batch.world.state, batch.world.scene
    for s in range(st.n_slots):
        w, i = divmod(s, batch.n_agents)
        mine = np.flatnonzero(scene.world == w)
        if mine.size:
            d = scene.centre[mine, :2] - st.pos[s, :2]
            v = d[np.argmin(np.hypot(d[:, 0], d[:, 1]))]
            acts[w, i, :3] = [*(v / max(float(np.hypot(*v)), 1e-9)), 0.0]
    return acts


CASES = [pytest.param(name, noisy_config(name), random_actions, id=name) for name in list_scenarios()] + [
    pytest.param("navigation", CRASH_CONFIG, crash_actions, id="navigation-object-collisions")
]


@pytest.mark.parametrize(("name", "cfg", "policy"), CASES)
def test_world_of_a_batch_equals_a_single_env(name: str, cfg: dict[str, Any], policy: Any) -> None:
    """Every world of the batch against its own single env: observations (inboxes with their collision
    messages included), rewards, flags and infos at every step, automatic-reset steps included."""
    seeds = [21, 7, 1234]
    batch = BatchedEnv(name, len(seeds), **cfg)
    singles = [agentsim_env.make(name, obs_format="flat", action_format="flat", **cfg) for _ in seeds]
    obs_b = batch.reset(seed=seeds)
    obs_s = [env.reset(seed=s)[0] for env, s in zip(singles, seeds)]
    agents = singles[0].possible_agents
    rng = np.random.default_rng(3)
    episodes = [0] * len(seeds)
    object_hits = [0] * len(seeds)
    for step in range(200):
        for w in range(len(seeds)):
            for i, a in enumerate(agents):
                if a in obs_s[w]:
                    np.testing.assert_array_equal(
                        obs_b[w, i], obs_s[w][a], err_msg=f"{name}: world {w}, obs of {a} at step {step}"
                    )
        acts = policy(batch, rng)
        out = batch.step(acts)
        col = batch.world.last_events.collisions
        for w in (col.agent[col.obj >= 0] // batch.n_agents).tolist():
            object_hits[w] += 1
        for w, single in enumerate(singles):
            live = list(single.agents)
            obs_s[w], rew, term, trunc, info = single.step({a: acts[w, agents.index(a)] for a in live})
            where = f"{name}: world {w} at step {step}"
            for a in live:
                i = agents.index(a)
                assert np.float32(rew[a]) == out.rewards[w, i], f"{where}: reward of {a}"
                assert term[a] == out.terminated[w, i] and trunc[a] == out.truncated[w, i], f"{where}: {a}"
                got = {k: out.info[k][w, i].item() for k in out.info}
                assert got == info[a], f"{where}: infos of {a} (reset {bool(out.reset_worlds[w])})"
            if out.reset_worlds[w]:
                for a in live:
                    np.testing.assert_array_equal(out.final_obs[w, agents.index(a)], obs_s[w][a], err_msg=where)
                assert not single.agents
                obs_s[w], _ = single.reset()  # the next episode of the same seed
                episodes[w] += 1
        obs_b = out.obs
    assert min(episodes) >= 2, f"{name}: the test should cross automatic resets in every world"
    if policy is crash_actions:
        assert min(object_hits[1:]) > 0, f"agents should hit objects in worlds other than 0: {object_hits}"


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
