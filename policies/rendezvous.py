"""The scripted baseline of ``rendezvous``: fly straight at the centroid, slowing down near it."""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.policies.parts import ActionParts


class MeetPolicy:
    """Velocity toward the ``task`` vector (centroid - position), full speed beyond ``slow_radius``.

    Silent with comms on; in primitive mode it flies the "velocity" primitive (``policies.parts``).

    Args:
        side: Map side (m): the ``task`` part is scaled by it.
        max_speed: The body's maximum speed (m/s).
        slow_radius: Distance (m) under which the agent slows down.
        parts: The env's action parts (default: velocity mode, no comms).
    """

    def __init__(
        self, side: float, max_speed: float, slow_radius: float = 3.0, parts: ActionParts | None = None
    ) -> None:
        self.side, self.max_speed, self.slow_radius = side, max_speed, slow_radius
        self.parts = parts if parts is not None else ActionParts({"motion": (3,)}, "MeetPolicy")

    @classmethod
    def for_env(cls, env: Any) -> MeetPolicy:
        """A policy configured from a rendezvous env's scenario config."""
        c = env.scenario.config
        return cls(side=c.side, max_speed=c.body.max_speed, slow_radius=c.radius / 2,
                   parts=ActionParts.for_env(env, "MeetPolicy"))  # fmt: skip

    def reset(self, seed: int | None = None) -> None:
        """Stateless: nothing to reset."""

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Every observed agent's action (Dict observations): its velocity as ``motion``, a silent ``comm``."""
        names = list(observations)
        v = np.zeros((len(names), 3))
        for i, a in enumerate(names):
            d = np.asarray(observations[a]["task"], dtype=np.float64) * self.side  # metres to the centroid
            speed = min(self.max_speed, float(np.linalg.norm(d)) / self.slow_radius * self.max_speed)
            v[i] = np.clip(d / max(float(np.linalg.norm(d)), 1e-9) * speed / self.max_speed, -1.0, 1.0)
        return self.parts.pack(names, v)
