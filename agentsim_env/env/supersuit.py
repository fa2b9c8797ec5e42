"""SuperSuit bridge: a scenario as an SB3 ``VecEnv`` built the PettingZoo tutorial way (the only supersuit importer).

The chain is the one of PettingZoo's SB3 tutorials: the ``ParallelEnv`` in flat modes -> ``black_death`` ->
``pettingzoo_env_to_vec_env_v1`` (one entry per agent: parameter sharing) -> ``concat_vec_envs_v1(n_envs,
num_cpus=0, base_class="stable_baselines3")``. Entry ``c * N + i`` is agent ``i`` of copy ``c``, the order of
``AgentSimVecEnv``. Two defects of SuperSuit 3.11 are patched here and nowhere else:

- **Seeding.** SB3 2.x seeds a vec env with ``venv.seed(seed)`` (``PPO(seed=...)`` does) and then calls
  ``reset()`` with no argument. SuperSuit's SB3 wrapper forwards ``seed`` to its ``ConcatVecEnv``, which has no
  ``seed`` method (``AttributeError``), and its ``reset()`` without a seed draws fresh entropy, so runs cannot be
  repeated. Here ``seed(s)`` stores ``s`` for the next ``reset()``, which resets copy ``c`` with seed ``s + c``
  (SB3's ``DummyVecEnv`` convention, and ``BatchedEnv.reset(s)``'s for world ``c``); later automatic resets
  continue each copy's seed sequence. The constructor's ``seed`` is stored the same way.
- **Episode end under black death.** SuperSuit 3.11's ``black_death`` ends the episode when every agent is
  terminated *and* truncated (SuperSuit pull request 265 changed it to *or*); with agents that are terminated or
  truncated, the end was only seen one step later, as a step of all-zero observations. The wrapper here is
  ``black_death_v3`` with *or*.

Conventions (SuperSuit's): an agent that ended while its copy goes on observes zeros and gets reward 0, and its
entry's ``done`` stays False; every entry of a copy reports ``done`` (with ``terminal_observation``) in the step
where the copy's last agents end, and the copy restarts in that step.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.env.parallel_env import AgentSimParallelEnv
from agentsim_env.scenarios.registry import make_scenario

_HINT = 'the SuperSuit bridge needs supersuit and stable-baselines3: pip install "agentsim-env[train]"'
try:
    import supersuit
    from stable_baselines3.common.vec_env import VecEnv
    from supersuit.multiagent_wrappers.black_death import black_death_par
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError(_HINT) from exc


class BlackDeath(black_death_par):
    """SuperSuit's ``black_death_v3`` wrapper; the episode ends when every live agent is terminated or truncated."""

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Step the live agents; ended agents observe zeros and get reward 0."""
        obss, rews, terms, truncs, infos = self.env.step({a: actions[a] for a in self.env.agents})
        done = all(terms[a] or truncs[a] for a in terms)
        zeros = {a: np.zeros_like(self.observation_space(a).low) for a in self.agents if a not in obss}
        dones = dict.fromkeys(self.agents, done)
        total_obs = {**zeros, **obss}
        total_rews = {**dict.fromkeys(zeros, 0.0), **rews}
        total_infos = {**{a: {} for a in zeros}, **infos}
        if done:
            self.agents.clear()
        return total_obs, total_rews, dones, dict(dones), total_infos


class SeededSB3VecEnv(SB3VecEnvWrapper):
    """SuperSuit's SB3 wrapper whose ``seed`` / ``reset`` follow SB3 2.x (see the module docstring).

    Args:
        venv: The ``ConcatVecEnv`` made by ``concat_vec_envs_v1``.
        seed: Seed of the first reset (``None``: fresh entropy).
        agents_per_copy: Entries per copy of the ParallelEnv (its agent count).
    """

    def __init__(self, venv: Any, seed: int | None, agents_per_copy: int) -> None:
        super().__init__(venv)
        self._next_seed = seed
        self._next_options: dict[str, Any] | None = None
        self._per_copy = agents_per_copy

    def seed(self, seed: int | None = None) -> list[int | None]:
        """Store the seed of the next ``reset()`` (``None``: draw one, as SB3 does); the seed of each entry."""
        if seed is None:  # SB3's draw, from the global generator that its set_random_seed seeds
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))  # noqa: NPY002
        self._next_seed = int(seed)
        return [self._next_seed + i // self._per_copy for i in range(self.num_envs)]

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """Options of the next ``reset()`` (one dict for every copy)."""
        self._next_options = options[0] if isinstance(options, list) else options

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """An attribute of the ParallelEnv copy behind each entry (``ConcatVecEnv`` has no ``get_attr``)."""
        copies = self.venv.vec_envs
        return [getattr(copies[i // self._per_copy].par_env.unwrapped, attr_name) for i in self._get_indices(indices)]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> np.ndarray:
        """Reset every copy: with ``seed``, else with the stored seed (used once), else continuing each copy."""
        if seed is None:
            seed = self._next_seed
        if options is None:
            options = self._next_options
        self._next_seed = None
        self._next_options = None
        obs, self.reset_infos = self.venv.reset(seed=seed, options=options)
        return obs


def supersuit_vec_env(scenario: str, n_envs: int = 1, seed: int | None = 0, **config: Any) -> VecEnv:
    """A scenario as an SB3 ``VecEnv`` of ``n_envs`` ParallelEnv copies x N agents, through SuperSuit.

    Args:
        scenario: Scenario name.
        n_envs: Copies of the ParallelEnv, stepped one after the other in this process.
        seed: Seed of the first reset (copy ``c`` gets ``seed + c``); ``None``: fresh entropy. ``PPO(seed=s)``
            replaces it with ``s``.
        **config: Scenario config keys.

    Returns:
        A ``VecEnv`` with ``num_envs = n_envs * n_agents``; entry ``c * N + i`` is agent ``i`` of copy ``c``.

    Raises:
        ValueError: ``n_envs`` below 1, or a bad scenario config.
    """
    if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
        raise ValueError(f"n_envs must be an integer >= 1, got {n_envs!r}")
    env = AgentSimParallelEnv(make_scenario(scenario, **config), obs_format="flat", action_format="flat")
    agents = len(env.possible_agents)
    vec = supersuit.pettingzoo_env_to_vec_env_v1(BlackDeath(env))
    sb3 = supersuit.concat_vec_envs_v1(vec, int(n_envs), num_cpus=0, base_class="stable_baselines3")
    return SeededSB3VecEnv(sb3.venv, seed, agents)  # the same ConcatVecEnv under the seeding-aware wrapper
