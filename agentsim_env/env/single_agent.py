"""A single-agent Gymnasium view of a scenario, for libraries that train one agent (SB3, CleanRL, ...).

``SingleAgentEnv`` controls one agent of the ParallelEnv with the flat float32 Boxes of the flat modes; the
other agents of the scenario (if any) act by a callable ``others`` that maps their observations to actions
(default: zero actions, which hold them still). The episode ends when the controlled agent's does:
``terminated`` when it reached its goal or went offline (collision, ...), ``truncated`` at the time limit; the
others may end earlier and simply leave the world. No ``TimeLimit`` wrapper is needed (the scenario's
``max_steps`` truncates).

Without ``gymnasium.make``::

    from agentsim_env.env.single_agent import SingleAgentEnv

    env = SingleAgentEnv("navigation", n_agents=1)
    obs, info = env.reset(seed=0)

With it, after ``register_gymnasium_envs()``: ``gymnasium.make("agentsim/navigation-v0", n_agents=1)`` (one id
per registered scenario, ``agentsim/<scenario>-v<version>``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, SupportsFloat

import gymnasium
import numpy as np

from agentsim_env.env.parallel_env import AgentSimParallelEnv, available_render_modes
from agentsim_env.scenarios.registry import make_scenario, scenario_class, usable_scenarios

OthersPolicy = Callable[[dict[str, np.ndarray]], dict[str, Any]]
"""How the agents not controlled act: ``{agent id: flat observation} -> {agent id: flat action}``, called every
step with the live ones only; it must return an action for each of them."""


class SingleAgentEnv(gymnasium.Env):
    """One agent of a scenario as a ``gymnasium.Env`` with flat Box observations and actions.

    Args:
        scenario: Scenario name (see ``agentsim_env.list_scenarios()``).
        agent: The controlled agent id (``None``: the first, ``possible_agents[0]``).
        others: How the other agents act (``OthersPolicy``); ``None``: zero actions. Called with the flat
            observations of the live others and must return a flat action for each.
        render_mode: ``None`` or ``"rgb_array"`` / ``"human"`` (a top-down frame of the whole world).
        check_finite: The ParallelEnv's debug switch (fail fast on NaN or inf).
        **config: Scenario config keys (``n_agents``, ``max_steps``, ...); the formats are always flat.

    Raises:
        ValueError: Unknown scenario, agent id or config key, or ``obs_format`` / ``action_format`` given.
    """

    metadata: dict[str, Any] = {"render_modes": available_render_modes(), "render_fps": 10}

    def __init__(
        self,
        scenario: str,
        agent: str | None = None,
        others: OthersPolicy | None = None,
        render_mode: str | None = None,
        check_finite: bool | None = None,
        **config: Any,
    ) -> None:
        for key in ("obs_format", "action_format"):
            if key in config:
                raise ValueError(f"{key}: SingleAgentEnv always uses the flat format; leave it out")
        self.par_env = AgentSimParallelEnv(
            make_scenario(scenario, **config),
            render_mode=render_mode,
            obs_format="flat",
            action_format="flat",
            check_finite=check_finite,
        )
        agents = self.par_env.possible_agents
        self.agent = agents[0] if agent is None else agent
        if self.agent not in agents:
            raise ValueError(f"agent: unknown agent id {self.agent!r}; agents are {agents[0]!r}...{agents[-1]!r}")
        if others is not None and not callable(others):
            raise ValueError(f"others must be a callable (observations -> actions), got {type(others).__name__}")
        self.others = others
        self.render_mode = render_mode
        self.metadata = dict(self.par_env.metadata)
        self.observation_space = self.par_env.observation_space(self.agent)
        self.action_space = self.par_env.action_space(self.agent)
        self._zero = np.zeros(self.action_space.shape or (), dtype=np.float32)
        self._obs: dict[str, np.ndarray] = {}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode; ``seed`` re-seeds the world's generator (otherwise it continues).

        Returns:
            The controlled agent's observation and info.
        """
        super().reset(seed=seed)
        self._obs, infos = self.par_env.reset(seed=seed, options=options)
        return self._obs[self.agent], infos[self.agent]

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        """Step the world: ``action`` for the controlled agent, ``others`` for the rest.

        Returns:
            ``(obs, reward, terminated, truncated, info)`` of the controlled agent.

        Raises:
            RuntimeError: The controlled agent's episode is over (call ``reset()``).
            ValueError: A bad action (the message names the agent and the part).
        """
        live = self.par_env.agents
        if self.agent not in live:
            raise RuntimeError("the controlled agent's episode is over (or never started): call reset()")
        actions = self._other_actions([a for a in live if a != self.agent])
        actions[self.agent] = action
        self._obs, rewards, terms, truncs, infos = self.par_env.step(actions)
        a = self.agent
        return self._obs[a], float(rewards[a]), bool(terms[a]), bool(truncs[a]), infos[a]

    def _other_actions(self, others: list[str]) -> dict[str, Any]:
        """Actions of the live agents not controlled: by ``self.others``, or zeros."""
        if not others:
            return {}
        if self.others is None:
            return dict.fromkeys(others, self._zero)
        return dict(self.others({a: self._obs[a] for a in others}))

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """A top-down frame of the whole world (``render_mode="rgb_array"``), or None."""
        return self.par_env.render()

    def close(self) -> None:
        """Close the live window, if any."""
        self.par_env.close()


def register_gymnasium_envs() -> list[str]:
    """Register ``agentsim/<scenario>-v<version>`` with Gymnasium for every scenario (idempotent).

    ``gymnasium.make(id, **config)`` then builds a ``SingleAgentEnv`` (config as in its constructor). Nothing is
    registered on import: call this first.

    Returns:
        The registered ids.
    """
    ids = []
    for name in usable_scenarios():  # a plug-in that does not load is left out
        env_id = f"agentsim/{name}-v{scenario_class(name).version}"
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point="agentsim_env.env.single_agent:SingleAgentEnv",
                kwargs={"scenario": name},
                disable_env_checker=True,  # the env passes check_env (tests); skip the per-step passive checks
            )
        ids.append(env_id)
    return ids
