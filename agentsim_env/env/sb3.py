"""Stable-Baselines3 adapter: B worlds x N agents presented as one ``VecEnv`` of B*N environments.

Parameter sharing comes for free: every agent of every world is one entry of the vector, all driven by the same
policy. No per-agent dicts are built (the batched array API underneath). Conventions follow SuperSuit's
``black_death``: an agent that ended while its world goes on observes zeros and gets reward 0; its entry reports
``done`` once when it ends (with ``terminal_observation``) and once more when its world restarts, so the zero
padding never leaks into a real episode. stable-baselines3 is imported here only.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from agentsim_env.env.vector import BatchedEnv
from agentsim_env.wrappers import BatchedEnvWrapper

try:
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError('the SB3 adapter needs stable-baselines3: pip install "agentsim-env[train]"') from exc


class AgentSimVecEnv(VecEnv):
    """A ``VecEnv`` over a ``BatchedEnv``: entry ``w * N + i`` is agent ``i`` of world ``w``.

    Args:
        name: Scenario name.
        n_worlds: Worlds B.
        seed: Seed of the first reset.
        batch: A batched env to drive instead of building one from ``name`` and ``n_worlds`` (e.g. a
            ``distributed.DistributedBatchedEnv``: the same training over shards, or a wrapper of one such as a
            recorded env); ``close()`` closes it.
        **config: Scenario config keys.
    """

    def __init__(
        self,
        name: str,
        n_worlds: int,
        seed: int | None = 0,
        *,
        batch: BatchedEnv | BatchedEnvWrapper | None = None,
        **config: Any,
    ) -> None:
        self.batch = batch if batch is not None else BatchedEnv(name, n_worlds, **config)
        b = self.batch
        n_worlds = b.n_worlds
        obs_parts = b.scenario.obs_parts()  # through the public API: a wrapped batched env has no private parts
        lows = np.concatenate([np.full(p.size, p.low) for p in obs_parts.values()]).astype(np.float32)
        highs = np.concatenate([np.full(p.size, p.high) for p in obs_parts.values()]).astype(np.float32)
        obs_space = spaces.Box(lows, highs, dtype=np.float32)
        act_space = spaces.Box(-1.0, 1.0, shape=(b.act_dim,), dtype=np.float32)
        super().__init__(n_worlds * b.n_agents, obs_space, act_space)
        self._seed = seed
        self._actions = np.zeros((n_worlds, b.n_agents, b.act_dim))
        self._ep_ret = np.zeros(self.num_envs)
        self._ep_len = np.zeros(self.num_envs, dtype=np.int64)

    def reset(self) -> np.ndarray:
        """Reset every world (the seed given to ``seed()`` or the constructor, then fresh draws)."""
        obs = self.batch.reset(self._seed)
        self._seed = None if self._seed is None else self._seed + 1
        self._ep_ret[:] = 0.0
        self._ep_len[:] = 0
        return obs.reshape(self.num_envs, -1)

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions ``(B*N, act_dim)``."""
        self._actions = np.asarray(actions, dtype=np.float64).reshape(self._actions.shape)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Step every world; ``done`` per agent as described in the module docstring."""
        b = self.batch
        alive_before = b.alive.reshape(-1).copy()
        out = b.step(self._actions)
        n = self.num_envs
        obs = out.obs.reshape(n, -1)
        rew = out.rewards.reshape(n).astype(np.float32)
        ended = (out.terminated | out.truncated).reshape(n)
        restarted = np.repeat(out.reset_worlds, b.n_agents) & ~ended & ~alive_before
        dones = ended | restarted
        self._ep_ret += np.where(alive_before, rew, 0.0)
        self._ep_len += alive_before
        infos: list[dict[str, Any]] = [{} for _ in range(n)]
        final = out.final_obs.reshape(n, -1)
        for i in np.flatnonzero(ended):
            w = i // b.n_agents
            last = final[i] if out.reset_worlds[w] else obs[i]
            infos[i] = {
                "terminal_observation": last.copy(),
                "TimeLimit.truncated": bool(out.truncated.reshape(n)[i]),
                "episode": {"r": float(self._ep_ret[i]), "l": int(self._ep_len[i])},
            }
            self._ep_ret[i] = 0.0
            self._ep_len[i] = 0
        for i in np.flatnonzero(restarted):
            infos[i] = {"terminal_observation": np.zeros_like(obs[i]), "TimeLimit.truncated": False}
        return obs, rew, dones, infos

    def close(self) -> None:
        """Close the batched env when it holds anything (the shards of a distributed one)."""
        close = getattr(self.batch, "close", None)
        if close is not None:
            close()

    def seed(self, seed: int | None = None) -> list[int | None]:
        """Seed of the next reset."""
        self._seed = seed
        return [seed] * self.num_envs

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """Attribute of the underlying batched env, repeated per entry."""
        return [getattr(self.batch, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set an attribute of the underlying batched env."""
        setattr(self.batch, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
        """Call a method of the underlying batched env once, repeated per entry."""
        res = getattr(self.batch, method_name)(*args, **kwargs)
        return [res] * len(self._indices(indices))

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        """No gymnasium wrappers are involved."""
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)
