"""Uniform random actions from each agent's action space (a floor for every scenario)."""

from __future__ import annotations

from typing import Any


class RandomPolicy:
    """Samples every agent's action space; ``reset(seed)`` seeds the spaces for reproducibility."""

    def __init__(self, env: Any) -> None:
        self.env = env

    @classmethod
    def for_env(cls, env: Any) -> RandomPolicy:
        """A random policy over ``env``'s action spaces."""
        return cls(env)

    def reset(self, seed: int | None = None) -> None:
        """Seed each agent's action space (agent k gets ``seed + k``)."""
        if seed is not None:
            for k, a in enumerate(self.env.possible_agents):
                self.env.action_space(a).seed(seed + k)

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """A random action for every observed agent."""
        return {a: self.env.action_space(a).sample() for a in observations}
