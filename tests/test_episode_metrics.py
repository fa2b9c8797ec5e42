"""``EpisodeMetrics`` tallies what ``agentsim train``'s evaluation reports of an episode, from the infos alone."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.policies.registry import baseline_names, make_policy
from agentsim_env.policies.rollout import run_episode
from agentsim_env.train.evaluate import _play
from agentsim_env.wrappers import EpisodeMetrics, ParallelEnvWrapper

# small worlds whose episodes end quickly; the first baseline of each scenario does its job in them
CASES: list[tuple[str, dict[str, Any]]] = [
    ("navigation", {"n_agents": 3, "max_steps": 60}),
    ("relay", {"n_groups": 1, "group_size": 2, "max_steps": 40}),
    ("rendezvous", {"n_agents": 3, "max_steps": 60}),
    ("uav_release", {"max_steps": 300}),
]


@pytest.mark.parametrize(("scenario", "cfg"), CASES, ids=[c[0] for c in CASES])
def test_the_tally_equals_the_evaluation_row(scenario: str, cfg: dict[str, Any]) -> None:
    env = agentsim_env.make(scenario, **cfg)
    name = baseline_names(scenario)[0]
    row = _play(env, make_policy(scenario, env, name), name, "baseline", [3], None)
    wrapped = EpisodeMetrics(agentsim_env.make(scenario, **cfg))
    assert isinstance(wrapped, ParallelEnvWrapper)
    run_episode(wrapped, make_policy(scenario, wrapped.unwrapped, name), 3)
    got = wrapped.summary()
    want = {k: v for k, v in row.items() if k not in ("policy", "kind", "episodes", "mean_return", "std_return")}
    assert set(got) == set(want), (got, want)
    for k, v in want.items():
        assert got[k] == pytest.approx(v), k
    assert any(np.isfinite(v) for v in got.values())
    wrapped.reset(seed=4)  # a new episode starts a fresh tally
    assert {k: v for k, v in wrapped.summary().items() if k.endswith("_per_agent")} == {}
