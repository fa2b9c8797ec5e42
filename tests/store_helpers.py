"""A small recorded store shared by the store tests."""

from __future__ import annotations

from pathlib import Path

import agentsim_env
from agentsim_env.recorder import record


def small_store(path: Path) -> Path:
    """Record one 5-step episode of ``navigation`` with 3 agents and random actions into ``path``."""
    env = record(agentsim_env.make("navigation", n_agents=3, max_steps=5), path)
    env.reset(seed=0)
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
    env.close()
    return path
