"""``BatchedEnvWrapper``: the base of every wrapper of a ``BatchedEnv`` (B worlds stepped on arrays).

Every public method and attribute of ``BatchedEnv`` is written out here and forwarded to the wrapped env; a
subclass overrides only what it adds. Attributes are properties over the env's own objects (``alive`` and
``steps`` are its arrays, updated in place by every step). A sharded batched env's extras (``coordinator``,
``shards``) are reached through ``unwrapped``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from agentsim_env.scenarios.base import Scenario
from agentsim_env.sim.world import World

__all__ = ["BatchedEnvWrapper"]

#: What the base reads of the env it wraps: checked at construction, so a wrong object fails there, named.
_REQUIRED = ("reset", "step", "close", "unwrapped", "n_worlds", "n_agents", "world", "scenario")


class BatchedEnvWrapper:
    """A batched env that forwards everything to the one it wraps.

    Subclasses override ``reset``, ``step`` or ``close`` and call the wrapped env as ``self.env``.

    Args:
        env: A ``BatchedEnv`` or another ``BatchedEnvWrapper`` (wrappers nest).

    Attributes:
        env: The wrapped env (the next one in; ``unwrapped`` is the innermost).

    Raises:
        ValueError: When ``env`` lacks the batched env's API (the message names what is missing).
    """

    def __init__(self, env: Any) -> None:
        missing = [name for name in _REQUIRED if not hasattr(env, name)]
        if missing:
            raise ValueError(
                f"env must be a BatchedEnv or a BatchedEnvWrapper, got {type(env).__name__} without {missing}"
            )
        self.env = env

    # ------------------------------------------------------------------ the env itself
    @property
    def unwrapped(self) -> Any:
        """The innermost env (a ``BatchedEnv``)."""
        return self.env.unwrapped

    @property
    def world(self) -> World:
        """The world of the B worlds' slots (state, scene, subsystems, step hooks)."""
        return self.env.world

    @property
    def scenario(self) -> Scenario:
        """The scenario, with its validated config."""
        return self.env.scenario

    # ------------------------------------------------------------------ stepping
    def reset(self, seed: int | Sequence[int] | None = None) -> np.ndarray:
        """Reset every world: observations ``(B, N, obs_dim)`` (``BatchedEnv.reset``)."""
        return self.env.reset(seed)

    def step(self, actions: np.ndarray) -> Any:
        """Advance every world by one step (``BatchedEnv.step``).

        Returns:
            The ``BatchStep`` of the step.
        """
        return self.env.step(actions)

    def close(self) -> None:
        """Close the wrapped env (and, through it, every env inside)."""
        self.env.close()

    # ------------------------------------------------------------------ sizes and state
    @property
    def n_worlds(self) -> int:
        """Number of worlds B."""
        return int(self.env.n_worlds)

    @property
    def n_agents(self) -> int:
        """Agents per world N."""
        return int(self.env.n_agents)

    @property
    def obs_dim(self) -> int:
        """Width of one agent's flat observation."""
        return int(self.env.obs_dim)

    @property
    def act_dim(self) -> int:
        """Width of one agent's flat action."""
        return int(self.env.act_dim)

    @property
    def alive(self) -> np.ndarray:
        """``(B, N)`` bool: the agents that act in the next step (the env's array)."""
        return self.env.alive

    @property
    def steps(self) -> np.ndarray:
        """``(B,)`` int64: steps of each world's current episode (the env's array)."""
        return self.env.steps

    @property
    def render_mode(self) -> str | None:
        """Always None: batched worlds are not rendered (read by vector-env adapters)."""
        return self.env.render_mode

    @property
    def check_finite(self) -> bool:
        """Whether observations, rewards and infos of live agents are checked for NaN and inf."""
        return bool(self.env.check_finite)
