"""Recording front ends: ``record(env_or_world, path)`` for a ``ParallelEnv``, a ``BatchedEnv`` or a ``World``.

The front ends are wrappers (``agentsim_env.wrappers``): the ParallelEnv one is a PettingZoo ``ParallelEnv`` whose
spaces, agents and every other method are the wrapped env's, so anything that trains or runs on the env runs on
the recorded one. Nothing is added to an env that is not recorded: the recorder is a stage-10 hook of the env's
world, attached here and removed on ``close``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from agentsim_env.env.parallel_env import AgentSimParallelEnv
from agentsim_env.env.rollout import RolloutCallback, RolloutResult, run_rollout
from agentsim_env.env.vector import BatchedEnv, BatchStep
from agentsim_env.recorder.writer import Recorder
from agentsim_env.sim.world import World
from agentsim_env.wrappers import BatchedEnvWrapper, ParallelEnvWrapper


class RecordedParallelEnv(ParallelEnvWrapper):
    """A ``ParallelEnv`` whose every episode is written to a store (see ``record``).

    Args:
        env: The env to record (its world gets the recorder's hook), or a wrapper of one.
        recorder: An open recorder.

    Attributes:
        recorder: The recorder (its ``run``, ``error``, ``path``; ``close`` finishes it).
    """

    def __init__(self, env: AgentSimParallelEnv | ParallelEnvWrapper, recorder: Recorder) -> None:  # noqa: D107
        super().__init__(env)
        self.recorder = recorder
        self._slot = {a: i for i, a in enumerate(env.possible_agents)}
        recorder.begin(env.world, scenario=env.scenario)

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
        """Reset the env and start a recorded episode (its step-0 state is written)."""
        obs, infos = self.env.reset(seed=seed, options=options)
        self.recorder.reset([0], [seed])
        self._record_obs(obs)
        return obs, infos

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """Step the env; the world's stage-10 hook writes the step."""
        out = self.env.step(actions)
        self._record_obs(out[0])
        return out

    def rollout(
        self, policy: Any, steps: int, seed: int | None = None, *, on_step: RolloutCallback | None = None
    ) -> RolloutResult:
        """``AgentSimParallelEnv.rollout`` run through this front end's ``reset`` and ``step`` (same results),
        so that its episode and observations are written."""
        return run_rollout(self, policy, steps, seed, on_step=on_step, through_step=True)

    def _record_obs(self, obs: dict[str, Any]) -> None:
        rec = self.recorder
        if rec.observe_agents is None or not obs:
            return
        observed = set(rec.observe_agents.tolist())
        names = [a for a in obs if self._slot[a] in observed]
        if not names:
            return
        flat = [
            np.concatenate([np.ravel(v) for v in o.values()]) if isinstance(o, dict) else np.ravel(o)
            for o in (obs[a] for a in names)
        ]
        rec.observations(np.array([self._slot[a] for a in names]), np.stack(flat))

    def close(self) -> None:
        """Mark the run complete, detach the recorder and close the env."""
        self.recorder.finish("complete")
        self.env.close()


class RecordedBatchedEnv(BatchedEnvWrapper):
    """A ``BatchedEnv`` whose worlds are recorded (automatic resets start new episodes); see ``record``.

    Args:
        env: The batched env to record (its world gets the recorder's hook), or a wrapper of one.
        recorder: An open recorder.

    Attributes:
        recorder: The recorder (``close`` finishes it).
    """

    def __init__(self, env: BatchedEnv | BatchedEnvWrapper, recorder: Recorder) -> None:  # noqa: D107
        super().__init__(env)
        self.recorder = recorder
        recorder.begin(env.world, scenario=env.scenario)

    def reset(self, seed: int | Sequence[int] | None = None) -> np.ndarray:
        """Reset every world; each starts a recorded episode."""
        obs = self.env.reset(seed)
        b = self.env.n_worlds
        seeds: list[Any]
        if seed is None:
            seeds = [None] * b
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + w for w in range(b)]
        else:
            seeds = list(seed)
        self.recorder.reset(range(b), seeds)
        self._record_obs(obs, np.ones(b, dtype=bool))
        return obs

    def step(self, actions: np.ndarray) -> BatchStep:
        """Step every world (the hook writes the step); worlds reset automatically start new episodes."""
        out: BatchStep = self.env.step(actions)
        if out.reset_worlds.any():
            self.recorder.reset(np.flatnonzero(out.reset_worlds))
        self._record_obs(out.obs, np.ones(self.env.n_worlds, dtype=bool))
        return out

    def _record_obs(self, obs: np.ndarray, worlds: np.ndarray) -> None:
        rec = self.recorder
        if rec.observe_agents is None:
            return
        n = self.env.n_agents
        ws = np.flatnonzero(worlds)
        slots = (ws[:, None] * n + rec.observe_agents[None, :]).ravel()
        rec.observations(slots, obs.reshape(-1, obs.shape[-1])[slots])

    def close(self) -> None:
        """Mark the run complete, detach the recorder and close the env (a sharded one stops its shards)."""
        self.recorder.finish("complete")
        self.env.close()


def record(
    target: Any,
    path: str | os.PathLike[str],
    *,
    commit_every: int = 1,
    observations: Sequence[int] | None = None,
    label: str | None = None,
) -> Any:
    """Record ``target`` to the SQLite store at ``path``.

    Args:
        target: An ``AgentSimParallelEnv`` or a wrapper of one (returns a recording ParallelEnv), a
            ``BatchedEnv`` or a wrapper of one (returns a recording batched env) or a ``World`` (returns the
            ``Recorder``; its hook records every step of
            every world as episode 0 onwards, ``recorder.reset(worlds)`` marks new episodes).
        path: The store file (created with its tables when missing; its folder must exist).
        commit_every: Steps per transaction (1: every step is durable once ``step`` returns).
        observations: Agent indices whose flat observations are stored every step (env front ends only).
        label: Free text stored with the run.

    Returns:
        The recording front end (call ``close()`` to mark the run complete).

    Raises:
        StoreError: When the store cannot be opened or written (the message names the path and the reason).
        TypeError: For a target that is none of the three.
    """
    rec = Recorder(path, commit_every=commit_every, observations=observations, label=label)
    if isinstance(target, (AgentSimParallelEnv, ParallelEnvWrapper)):
        return RecordedParallelEnv(target, rec)
    if isinstance(target, (BatchedEnv, BatchedEnvWrapper)):
        return RecordedBatchedEnv(target, rec)
    if isinstance(target, World):
        rec.begin(target)
        rec.reset(range(target.n_worlds))
        return rec
    rec.finish("incomplete")
    raise TypeError(
        "record() takes an AgentSimParallelEnv, a BatchedEnv (or a wrapper of either) or a World, got "
        f"{type(target).__name__}"
    )


__all__ = ["RecordedBatchedEnv", "RecordedParallelEnv", "record"]
