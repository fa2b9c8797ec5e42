"""``EpisodeMetrics``: what an evaluation reports of an episode, tallied from the infos the env hands back.

An evaluation (``agentsim train``'s, the learning benchmark's) reports, per episode: the scenario's event counters
per agent (``scenario.event_keys``, e.g. ``arrived``: the sum of the numeric info values over the episode and the
agents, over the number of agents, as ``arrived_per_agent``), the last value of its final keys
(``scenario.final_keys``, e.g. ``coverage_weighted``: the mean over the agents of the last infos that carry it) and
the scenario's outcome (:func:`outcome`: ``relay``'s groups at their target). The wrapper collects these whatever
steps the env (a TorchRL or other framework's loop that never shows the infos to the caller).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.wrappers.parallel import ParallelEnvWrapper

__all__ = ["EpisodeMetrics", "final_values", "outcome"]


def outcome(env: Any) -> dict[str, float]:
    """The scenario's own outcome of the episode just played in world 0 of ``env`` (a ParallelEnv or wrapper):
    ``groups_reached`` (share of groups at their target) and ``all_groups_reached`` for a scenario with
    ``group_success`` (``relay``), else nothing."""
    sc = env.scenario
    if hasattr(sc, "group_success"):
        ok = np.asarray(sc.group_success(env.world, 0), dtype=bool)
        return {"groups_reached": float(ok.mean()), "all_groups_reached": float(ok.all())}
    return {}


def final_values(infos: dict[str, dict[str, Any]], keys: Any) -> dict[str, float]:
    """Each of ``keys`` that this step's ``infos`` carry: its mean over the agents that carry it."""
    out = {}
    for k in keys:
        vals = [float(i[k]) for i in infos.values() if k in i]
        if vals:
            out[k] = float(np.mean(vals))
    return out


def _number(v: Any) -> bool:
    """Whether an info value counts in a sum (a number, not a flag)."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


class EpisodeMetrics(ParallelEnvWrapper):
    """Tallies the current episode's event counters and final values from the infos of ``reset`` and ``step``.

    Args:
        env: An ``AgentSimParallelEnv`` or a wrapper of one.
    """

    def __init__(self, env: Any) -> None:
        super().__init__(env)
        self._sums: dict[str, float] = {}
        self._last: dict[str, float] = {}

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """Start an episode and a fresh tally."""
        self._sums, self._last = {}, {}
        return self.env.reset(seed=seed, options=options)

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Step the env and add this step's infos to the tally."""
        out = self.env.step(actions)
        self._note(out[4])
        return out

    def _note(self, infos: dict[str, dict[str, Any]]) -> None:
        sc = self.env.scenario
        for k in sc.event_keys:
            vals = [float(i[k]) for i in infos.values() if k in i and _number(i[k])]
            if vals:
                self._sums[k] = self._sums.get(k, 0.0) + sum(vals)
        self._last.update(final_values(infos, sc.final_keys))

    def summary(self) -> dict[str, float]:
        """The episode so far: ``{event}_per_agent`` for each event counter that fired, the final keys' last
        values, then :func:`outcome`."""
        n = len(self.env.possible_agents)
        out = {f"{k}_per_agent": v / n for k, v in sorted(self._sums.items())}
        return {**out, **self._last, **outcome(self.env)}
