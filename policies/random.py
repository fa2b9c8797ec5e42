"""Uniform random actions from each agent's action space (a floor for every scenario).

Every action value is drawn by a counter-based hash of ``(seed, step, agent index, column)`` rather than from
one generator stream, so an agent's action does not depend on which other agents act in the same call: a shard
that acts only for its own agents draws exactly the values a single process draws for them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.policies.parts import rows_to_dicts

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _mix(x: np.ndarray) -> np.ndarray:
    """The splitmix64 finaliser, elementwise on uint64 (wraps around, as intended)."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def keyed_uniform(seed: int, step: int, slots: np.ndarray, width: int) -> np.ndarray:
    """``(len(slots), width)`` uniform floats in [0, 1), each a function of (seed, step, slot, column) only.

    Args:
        seed: The episode's policy seed (>= 0).
        step: Steps since the reset.
        slots: ``(n,)`` agent indices.
        width: Values per agent.

    Returns:
        float64 values; row ``i`` depends on ``slots[i]`` and not on the other rows.
    """
    s = np.asarray(slots, dtype=np.uint64).reshape(-1, 1)
    col = np.arange(width, dtype=np.uint64).reshape(1, -1)
    key = _mix(np.array([seed & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64) + _GOLDEN)
    key = _mix(key ^ (np.array([step & 0xFFFFFFFFFFFFFFFF], dtype=np.uint64) * _GOLDEN))
    x = _mix(_mix(key ^ (s * np.uint64(0xD6E8FEB86659FD93))) + col * _GOLDEN)
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


class RandomPolicy:
    """Uniform actions in every action part's bounds, keyed by (seed, step, agent) (module docstring).

    Args:
        env: The env (or anything with ``scenario`` and ``possible_agents``).
    """

    def __init__(self, env: Any) -> None:
        self.env = env
        self.index = {a: i for i, a in enumerate(env.possible_agents)}
        self.parts = env.scenario.act_parts()
        self.seed = 0
        self.step = 0
        self.reset(None)

    @classmethod
    def for_env(cls, env: Any) -> RandomPolicy:
        """A random policy over ``env``'s action spaces."""
        return cls(env)

    def reset(self, seed: int | None = None) -> None:
        """Start an episode: draws are keyed by ``seed`` (None: fresh entropy, so every episode differs)."""
        if seed is None:
            seed = int(np.random.SeedSequence().generate_state(1, np.uint64)[0])
        self.seed = int(seed)
        self.step = 0

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """A random action for every observed agent (one step of ``act_rows``)."""
        names = list(observations)
        slots = np.array([self.index[a] for a in names], dtype=np.int64)
        out = self.act_rows({}, slots, self.step)
        self.step += 1
        return rows_to_dicts(names, out) if names else {}

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """Random action parts of the agents ``slots`` at ``step`` (observations are not read).

        Args:
            obs: Ignored.
            slots: ``(n,)`` the agents' indices in ``possible_agents``.
            step: Steps since the reset.

        Returns:
            ``{part: (n, *shape)}`` float32 arrays, uniform in each part's bounds.
        """
        total = sum(p.size for p in self.parts.values())
        u = keyed_uniform(self.seed, step, slots, total)
        out, start = {}, 0
        for name, p in self.parts.items():
            cols = u[:, start : start + p.size]
            start += p.size
            out[name] = (p.low + (p.high - p.low) * cols).astype(np.float32).reshape(-1, *p.shape)
        return out
