"""Run a policy for one episode and summarise what happened."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from agentsim_env.policies.base import Policy


@dataclass
class EpisodeSummary:
    """Totals of one episode.

    Attributes:
        seed: The reset seed.
        steps: Steps taken.
        returns: Undiscounted return per agent.
        info_sums: Per info key, the sum over agents and steps (e.g. ``arrived``, ``collided``).
        frames: Rendered frames when requested.
    """

    seed: int
    steps: int
    returns: dict[str, float]
    info_sums: dict[str, float]
    frames: list[np.ndarray] = field(default_factory=list)


#: ``on_step(env, infos)``: called after the reset (``infos`` empty) and after every step (the step's infos).
StepCallback = Callable[[Any, dict[str, dict[str, Any]]], None]


def run_episode(
    env: Any, policy: Policy, seed: int, *, render_every: int = 0, on_step: StepCallback | None = None
) -> EpisodeSummary:
    """Reset ``env`` with ``seed`` and step ``policy`` until every agent is done.

    Args:
        env: A ParallelEnv.
        policy: Acts on the observations of live agents.
        seed: Reset seed (also passed to ``policy.reset``).
        render_every: Keep a frame every this many steps (0: none; the last frame is always kept when > 0).
        on_step: Optional observer, called with ``(env, {})`` after the reset and with ``(env, infos)`` after
            every step (e.g. to record positions from ``env.world.state``); it must not change the env.

    Returns:
        The episode summary.
    """
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    returns = dict.fromkeys(env.possible_agents, 0.0)
    sums: dict[str, float] = {}
    frames: list[np.ndarray] = []
    steps = 0
    if on_step is not None:
        on_step(env, {})
    while env.agents:
        live = {a: obs[a] for a in env.agents}
        obs, rew, _, _, infos = env.step(policy.act(live))
        steps += 1
        if on_step is not None:
            on_step(env, infos)
        for a, r in rew.items():
            returns[a] += r
        for info in infos.values():
            for k, v in info.items():
                if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool):
                    sums[k] = sums.get(k, 0.0) + float(v)
        if render_every and steps % render_every == 0:
            frames.append(env.render())
    if render_every:
        frames.append(env.render())
    return EpisodeSummary(seed, steps, returns, sums, frames)
