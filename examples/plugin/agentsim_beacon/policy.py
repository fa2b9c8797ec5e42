"""The ``to_beacon`` policy of the ``beacon`` scenario: fly straight at the beacon, slowing down near it."""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.policies.parts import ActionParts


class ToBeaconPolicy:
    """Velocity toward the ``task`` vector (beacon - position), full speed beyond ``slow_radius`` metres."""

    scenarios = ("beacon",)  # the scenarios this policy serves (read for the entry point)

    def __init__(self, side: float, slow_radius: float, parts: ActionParts) -> None:
        self.side, self.slow_radius, self.parts = side, slow_radius, parts

    @classmethod
    def for_env(cls, env: Any, **options: Any) -> ToBeaconPolicy:
        """The policy configured from a beacon env's scenario config."""
        c = env.scenario.config
        return cls(side=c.side, slow_radius=c.radius, parts=ActionParts.for_env(env, "ToBeaconPolicy"))

    def reset(self, seed: int | None = None) -> None:
        """Stateless: nothing to reset."""

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Every observed agent's action: its velocity as ``motion`` (and a silent ``comm`` with comms on)."""
        names = list(observations)
        d = np.array([observations[a]["task"] for a in names], dtype=np.float64).reshape(-1, 3) * self.side
        dist = np.linalg.norm(d, axis=1, keepdims=True)
        velocity = d / np.maximum(dist, 1e-9) * np.minimum(1.0, dist / self.slow_radius)
        return self.parts.pack(names, velocity)
