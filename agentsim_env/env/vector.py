"""Batched stepping: B independent worlds of N agents in one call, arrays in and arrays out.

No per-agent dicts are built, which is what makes large-batch training fast. Observations and actions use the
scenario's flat layout (parts concatenated in declaration order, as in the flat-Box ParallelEnv modes).
A world whose agents are all done is reset automatically at the end of the step; the observation returned for
it is the first of the new episode and the last one of the finished episode is in ``final_obs``.
Agents that ended earlier in a still-running world are masked out (``alive`` is False): their actions are
ignored and their observations are zeros (SuperSuit's "black death" convention).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from agentsim_env.core.pipeline import EpisodeSeeds
from agentsim_env.core.threads import check_num_threads
from agentsim_env.core.validation import check_int, is_int, short_repr
from agentsim_env.env.batch_kernels import finish_step, prepare_actions
from agentsim_env.env.buffers import ArraySource, Recycled
from agentsim_env.env.finite import assert_finite, check_finite_default
from agentsim_env.env.guard import CallGuard
from agentsim_env.env.spaces import ACTION_RULE, REAL_KINDS, as_array, flat_layout
from agentsim_env.scenarios.base import reset_worlds, run_step
from agentsim_env.scenarios.flat_layout import flat_parts
from agentsim_env.scenarios.registry import make_scenario

MAX_WORLDS = 1_000_000
"""Most worlds in one batch (the memory they need is also checked before allocating: ``core.budget``)."""


@dataclass(slots=True)
class BatchStep:
    """The result of one batched step (B worlds x N agents).

    Attributes:
        obs: ``(B, N, obs_dim)`` float32.
        rewards: ``(B, N)`` float32.
        terminated: ``(B, N)`` bool: the agent's episode ended this step (goal, collision...).
        truncated: ``(B, N)`` bool: the time limit ended it.
        alive: ``(B, N)`` bool: the agent acts in the next step.
        final_obs: ``(B, N, obs_dim)``: the last observation of worlds reset in this step (zeros elsewhere).
        reset_worlds: ``(B,)`` bool: which worlds were reset.
        info: Per-slot scenario info arrays reshaped to ``(B, N)``.
    """

    obs: np.ndarray
    rewards: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    alive: np.ndarray
    final_obs: np.ndarray
    reset_worlds: np.ndarray
    info: dict[str, np.ndarray]


class BatchedEnv:
    """B worlds of one scenario stepped together.

    Args:
        name: Scenario name.
        n_worlds: Number of worlds B, 1..1,000,000.
        check_finite: Debug switch: raise ``FloatingPointError`` naming the part, the agent and the world when
            an observation, reward or info of a live agent is NaN or inf (``None``: from ``AGENTSIM_CHECK_FINITE``).
        num_threads: Threads for the per-slot kernels, 1..256 (default 1); results are identical for every count.
        **config: Scenario config keys.
    """

    def __init__(
        self,
        name: str,
        n_worlds: int,
        *,
        check_finite: bool | None = None,
        num_threads: int = 1,
        **config: Any,
    ) -> None:
        check_int("n_worlds", n_worlds, 1, MAX_WORLDS)
        n_worlds = int(n_worlds)
        num_threads = check_num_threads(num_threads)
        self.check_finite = check_finite_default(check_finite)
        self.scenario = make_scenario(name, **config)
        self.world = self.scenario.build(n_worlds)
        self.world.set_num_threads(num_threads)
        self.n_worlds = n_worlds
        self.n_agents = self.scenario.n_agents
        self._obs_parts = self.scenario.obs_parts()
        self._act_parts = self.scenario.act_parts()
        self._act_layout = flat_layout(self._act_parts)
        self.obs_dim = sum(p.size for p in self._obs_parts.values())
        self.act_dim = sum(p.size for p in self._act_parts.values())
        self.render_mode: str | None = None  # batched worlds are not rendered (read by vector-env adapters)
        self.alive = np.zeros((n_worlds, self.n_agents), dtype=bool)
        self.steps = np.zeros(n_worlds, dtype=np.int64)
        self._seeds = [EpisodeSeeds() for _ in range(n_worlds)]
        self._started = False
        self._obs_out: ArraySource = Recycled((self.world.state.n_slots, self.obs_dim), np.float32)
        self._guard = CallGuard()  # reset and step: one thread at a time

    @property
    def unwrapped(self) -> BatchedEnv:
        """This env (a wrapper's ``unwrapped`` is the innermost env: see ``agentsim_env.wrappers``)."""
        return self

    def close(self) -> None:
        """Release what the env holds: nothing here (a sharded batched env stops its shards)."""

    def _flat_obs(
        self, rows: np.ndarray | None = None, step: int = 0, result: Any = None, out: np.ndarray | None = None
    ) -> np.ndarray:
        """Flat observations of every slot (into ``out`` when given); with ``check_finite``, ``rows`` (and
        ``result``) are checked."""
        if self.check_finite and rows is not None:
            parts = self.scenario.observation(self.world)
            assert_finite(self.scenario, rows, step, parts, result)
            flat = flat_parts(parts, self.world.state.n_slots, out, self.world.threads)
        else:
            flat = self.scenario.flat_observation(self.world, out)
        return flat.reshape(self.n_worlds, self.n_agents, self.obs_dim)

    def _reset_worlds(self, worlds: np.ndarray) -> None:
        self._reset_core(worlds.tolist(), [self._seeds[w].next() for w in worlds])
        self.steps[worlds] = 0
        self.alive[worlds] = True

    def _reset_core(self, worlds: list[int], seeds: list[np.random.SeedSequence]) -> None:
        """Start the episodes of ``worlds`` (the distributed front end runs them over its shards)."""
        reset_worlds(self.scenario, self.world, worlds, seeds)

    def _step_core(
        self, parts: dict[str, np.ndarray], acting: np.ndarray, out: np.ndarray | None = None
    ) -> tuple[Any, np.ndarray]:
        """Stages 1-10 for clipped action parts (the distributed front end runs them over its shards, and
        writes the observation rows into ``out``, the array ``_flat_obs`` then gets)."""
        return run_step(self.scenario, self.world, parts, acting)

    def reset(self, seed: int | Sequence[int] | None = None) -> np.ndarray:
        """Reset every world; world ``w`` then behaves exactly like a ``ParallelEnv`` reset with its seed.

        Args:
            seed: ``None`` (fresh entropy per world), an int ``s`` (world ``w`` gets ``s + w``) or a sequence of
                B ints (one per world). Later automatic resets of world ``w`` continue its seed's episodes, as
                ``reset()`` without a seed continues a ``ParallelEnv``'s.

        Returns:
            Observations ``(B, N, obs_dim)``.

        Raises:
            ValueError: A bad seed (the message names the world).
            RuntimeError: Another thread is inside ``reset`` or ``step`` of this env.
        """
        self._guard.enter("reset")
        try:
            return self._reset(seed)
        finally:
            self._guard.exit()

    def _reset(self, seed: int | Sequence[int] | None) -> np.ndarray:
        b = self.n_worlds
        if seed is None:
            seeds: list[int | None] = [None] * b
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + w for w in range(b)]
        else:
            if isinstance(seed, (str, bytes)) or not isinstance(seed, (Sequence, np.ndarray)):
                raise ValueError(
                    f"seed must be None, an int or a sequence of {b} ints (one per world), "
                    f"got {type(seed).__name__} {short_repr(seed)}"
                )
            seeds = list(seed)
            if len(seeds) != b or not all(is_int(s) for s in seeds):
                raise ValueError(
                    f"seed must be None, an int or a sequence of {b} ints (one per world), got {short_repr(seed)}"
                )
        for w, s in enumerate(seeds):
            try:
                self._seeds[w].reset(s)
            except ValueError as exc:
                raise ValueError(f"world {w}: {exc}") from None
        self._started = True
        self._reset_worlds(np.arange(b))
        return self._flat_obs(np.ones(self.world.state.n_slots, dtype=bool))

    def step(self, actions: np.ndarray) -> BatchStep:
        """Advance every world by one step.

        Args:
            actions: ``(B, N, act_dim)`` real numbers (ints or floats, not bools; an array, nested sequences or
                a tensor) in [-1, 1] (clipped); rows of dead agents are ignored.

        Returns:
            The batch step result.

        Raises:
            ValueError: Wrong shape or dtype, or a NaN/inf action of a live agent (the message names world
                and agent).
            RuntimeError: Another thread is inside ``reset`` or ``step`` of this env.
        """
        self._guard.enter("step")
        try:
            return self._step(actions)
        finally:
            self._guard.exit()

    def _step(self, actions: np.ndarray) -> BatchStep:
        if not self._started:
            raise ValueError("call reset() before step()")
        try:
            a = as_array(actions)  # a tensor (gradients, any device) is read as its values
        except (TypeError, ValueError, RuntimeError) as exc:
            raise ValueError(f"actions must be an array of real numbers ({ACTION_RULE}): {exc}") from None
        if a.dtype.kind not in REAL_KINDS:
            raise ValueError(f"actions must be real numbers (ints or floats), got dtype {a.dtype} ({ACTION_RULE})")
        if a.shape != (self.n_worlds, self.n_agents, self.act_dim):
            raise ValueError(f"actions must have shape {(self.n_worlds, self.n_agents, self.act_dim)}, got {a.shape}")
        acting = self.alive.reshape(-1).copy()
        a, bad = prepare_actions(a.reshape(-1, self.act_dim), acting)
        if bad >= 0:
            w, i = divmod(bad, self.n_agents)
            raise ValueError(f"actions of world {w}, agent {i} contain NaN or inf")
        parts = {k: a[:, sl] for k, sl in self._act_layout.items()}
        out = self._obs_out.get()
        res, term = self._step_core(parts, acting, out)
        self.steps += 1
        obs = self._flat_obs(acting, int(self.steps.max()) if self.check_finite else 0, res, out)
        term = np.asarray(term, dtype=bool)
        trunc, done_worlds, n_done = finish_step(
            term, acting, self.steps >= self.scenario.max_steps, self.alive, obs.reshape(-1, self.obs_dim)
        )
        # Taken before the automatic reset, which starts the next episode of the finished worlds: the step's
        # results are the ended episode's (the scenario's info arrays are fresh each step, never its state).
        shape = (self.n_worlds, self.n_agents)
        info = {k: v.reshape(shape) for k, v in res.info.items()}
        rewards = res.rewards.reshape(shape).astype(np.float32)
        final = np.zeros(obs.shape, dtype=obs.dtype)  # calloc: pages stay untouched unless a world resets
        if n_done:
            final[done_worlds] = obs[done_worlds]
            self._reset_worlds(np.flatnonzero(done_worlds))
            fresh = np.repeat(done_worlds, self.n_agents)
            obs[done_worlds] = self._flat_obs(fresh)[done_worlds]
        return BatchStep(
            obs,
            rewards,
            term.reshape(shape),
            trunc.reshape(shape),
            self.alive.copy(),
            final,
            done_worlds,
            info,
        )
