"""``ParallelEnvWrapper``: the base of every wrapper of an ``AgentSimParallelEnv`` (a PettingZoo ``ParallelEnv``).

Every public method and attribute of the env is written out here and forwarded to the wrapped env; a subclass
overrides only what it adds. Attributes are properties, so a wrapper always reads the env's current value (its
``agents`` after a step, the very ``metadata`` dict). The env's own extras beyond ``AgentSimParallelEnv``'s API
(a sharded env's ``coordinator``, ``shards``, ``add_objects``) are reached through ``unwrapped``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from agentsim_env.scenarios.base import Scenario
from agentsim_env.sim.world import World

__all__ = ["ParallelEnvWrapper"]


class ParallelEnvWrapper(ParallelEnv):
    """A PettingZoo ``ParallelEnv`` that forwards everything to the env it wraps.

    Subclasses override ``reset``, ``step``, ``close`` (and ``rollout`` when a rollout must run through their
    ``step``) and call the wrapped env as ``self.env``.

    Args:
        env: An ``AgentSimParallelEnv`` or another ``ParallelEnvWrapper`` (wrappers nest).

    Attributes:
        env: The wrapped env (the next one in; ``unwrapped`` is the innermost).

    Raises:
        ValueError: When ``env`` is not a PettingZoo ``ParallelEnv`` (the message names its type).
    """

    def __init__(self, env: ParallelEnv) -> None:
        if not isinstance(env, ParallelEnv):
            raise ValueError(
                f"env must be a PettingZoo ParallelEnv (an AgentSimParallelEnv or a ParallelEnvWrapper), "
                f"got {type(env).__name__}"
            )
        self.env = env

    # ------------------------------------------------------------------ the env itself
    @property
    def unwrapped(self) -> Any:
        """The innermost env (an ``AgentSimParallelEnv``): what every wrapper around it forwards to."""
        return self.env.unwrapped

    @property
    def world(self) -> World:
        """The world the env steps (its state, scene, subsystems and step hooks)."""
        return self.env.world

    @property
    def scenario(self) -> Scenario:
        """The scenario, with its validated config."""
        return self.env.scenario

    @property
    def viewer(self) -> Any:
        """The web viewer (``render_mode="web"``, started by the first ``reset``), else None."""
        return self.env.viewer

    # ------------------------------------------------------------------ episode
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """Start an episode (``AgentSimParallelEnv.reset``)."""
        return self.env.reset(seed=seed, options=options)

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Advance one step: observations, rewards, terminations, truncations, infos (``AgentSimParallelEnv.step``)."""
        return self.env.step(actions)

    def rollout(self, policy: Any, steps: int, seed: int | None = None, *, on_step: Any = None) -> Any:
        """Run ``policy`` on arrays from ``reset(seed=seed)`` (``AgentSimParallelEnv.rollout``).

        The wrapped env runs it: a wrapper whose ``reset`` or ``step`` must see every step of the rollout
        overrides this (the recorder runs it through its ``step``).

        Returns:
            The ``RolloutResult``.
        """
        return self.env.rollout(policy, steps, seed, on_step=on_step)

    def close(self) -> None:
        """Close the wrapped env (and, through it, every env inside)."""
        self.env.close()

    def render(self) -> np.ndarray | None:
        """A frame in ``"rgb_array"`` mode, else None (``AgentSimParallelEnv.render``)."""
        return self.env.render()

    def state(self) -> np.ndarray:
        """Global state of the world for centralised critics (see ``state_space``)."""
        return self.env.state()

    # ------------------------------------------------------------------ calls beside step
    def send_message(self, sender: str, payload: Any, *, to: str | None = None, group: int | None = None) -> bool:
        """Send a bus message from code, to one agent or a group (``AgentSimParallelEnv.send_message``)."""
        return bool(self.env.send_message(sender, payload, to=to, group=group))

    def assign_group(self, agent: str, group: int) -> None:
        """Move ``agent`` to ``group`` for the rest of the episode (``AgentSimParallelEnv.assign_group``)."""
        self.env.assign_group(agent, group)

    # ------------------------------------------------------------------ agents
    @property
    def agents(self) -> list[str]:
        """The live agents (the wrapped env's list, current after every ``reset`` and ``step``)."""
        return self.env.agents

    @property
    def possible_agents(self) -> list[str]:
        """Every agent id of the scenario, in slot order."""
        return self.env.possible_agents

    @property
    def num_agents(self) -> int:
        """Number of live agents."""
        return int(self.env.num_agents)

    @property
    def max_num_agents(self) -> int:
        """Number of possible agents."""
        return int(self.env.max_num_agents)

    # ------------------------------------------------------------------ spaces
    def observation_space(self, agent: str) -> spaces.Space:
        """The observation space of ``agent`` (one object shared by every agent)."""
        return self.env.observation_space(agent)

    def action_space(self, agent: str) -> spaces.Space:
        """The action space of ``agent`` (one object shared by every agent)."""
        return self.env.action_space(agent)

    @property
    def observation_spaces(self) -> dict[str, spaces.Space]:
        """``{agent: space}`` for every possible agent (what ``observation_space`` returns)."""
        return self.env.observation_spaces

    @property
    def action_spaces(self) -> dict[str, spaces.Space]:
        """``{agent: space}`` for every possible agent (what ``action_space`` returns)."""
        return self.env.action_spaces

    @property
    def state_space(self) -> spaces.Space:
        """The space of ``state()``."""
        return self.env.state_space

    # ------------------------------------------------------------------ settings
    @property
    def metadata(self) -> dict[str, Any]:
        """The env's metadata dict itself (``name``, ``render_modes``, ``render_fps``, ...)."""
        return self.env.metadata

    @property
    def render_mode(self) -> str | None:
        """``None``, ``"rgb_array"``, ``"human"`` or ``"web"``."""
        return self.env.render_mode

    @property
    def obs_format(self) -> str:
        """``"dict"`` or ``"flat"``: the layout of observations."""
        return self.env.obs_format

    @property
    def action_format(self) -> str:
        """``"dict"`` or ``"flat"``: the layout of actions."""
        return self.env.action_format

    @property
    def ended_agents(self) -> str:
        """``"leave"`` or ``"stay"``: what becomes of an agent that ends before its episode does."""
        return self.env.ended_agents

    @property
    def check_finite(self) -> bool:
        """Whether observations, rewards and infos are checked for NaN and inf after every reset and step."""
        return bool(self.env.check_finite)
