"""The scripted baseline of ``rendezvous``: fly straight at the centroid, slowing down near it."""

from __future__ import annotations

from typing import Any

import numpy as np


class MeetPolicy:
    """Velocity toward the ``task`` vector (centroid - position), full speed beyond ``slow_radius``."""

    def __init__(self, side: float, max_speed: float, slow_radius: float = 3.0) -> None:
        self.side, self.max_speed, self.slow_radius = side, max_speed, slow_radius

    @classmethod
    def for_env(cls, env: Any) -> MeetPolicy:
        """A policy configured from a rendezvous env's scenario config."""
        c = env.scenario.config
        return cls(side=c.side, max_speed=c.body.max_speed, slow_radius=c.radius / 2)

    def reset(self, seed: int | None = None) -> None:
        """Stateless: nothing to reset."""

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """A ``motion`` action for every observed agent (Dict observations)."""
        out = {}
        for a, o in observations.items():
            d = np.asarray(o["task"], dtype=np.float64) * self.side  # metres to the centroid
            speed = min(self.max_speed, float(np.linalg.norm(d)) / self.slow_radius * self.max_speed)
            v = d / max(float(np.linalg.norm(d)), 1e-9) * speed / self.max_speed
            out[a] = {"motion": np.clip(v, -1.0, 1.0).astype(np.float32)}
        return out
