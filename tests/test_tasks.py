"""Task tests: each scripted baseline does its job on its scenario's default config."""

from __future__ import annotations

import numpy as np

import agentsim_env
from agentsim_env.policies.registry import make_policy
from agentsim_env.policies.rollout import run_episode


def test_navigation_go_to_goal_reaches_90_percent_over_20_seeds() -> None:
    env = agentsim_env.make("navigation")
    policy = make_policy("navigation", env, "go_to_goal")
    arrived = [run_episode(env, policy, seed).info_sums.get("arrived", 0.0) for seed in range(20)]
    rate = sum(arrived) / (20 * env.scenario.n_agents)
    assert rate >= 0.9, f"go-to-goal reached {rate:.1%} of goals"


def test_navigation_random_policy_is_far_worse() -> None:
    """The task is not trivial: random actions reach almost no goal."""
    env = agentsim_env.make("navigation")
    policy = make_policy("navigation", env, "random")
    arrived = [run_episode(env, policy, seed).info_sums.get("arrived", 0.0) for seed in range(5)]
    assert np.mean(arrived) / env.scenario.n_agents < 0.3
