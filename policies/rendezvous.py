"""The scripted baseline of ``rendezvous``: fly straight at the centroid, slowing down near it."""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.policies.parts import ActionParts, rows_to_dicts


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
        return cls(
            side=c.side,
            max_speed=c.body.max_speed,
            slow_radius=c.radius / 2,
            parts=ActionParts.for_env(env, "MeetPolicy"),
        )

    def reset(self, seed: int | None = None) -> None:
        """Stateless: nothing to reset."""

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Every observed agent's action (Dict observations): its velocity as ``motion``, a silent ``comm``."""
        names = list(observations)
        if not names:
            return {}
        task = np.stack([np.asarray(observations[a]["task"]) for a in names])
        return rows_to_dicts(names, self.act_rows({"task": task}, np.zeros(0, dtype=np.int64), 0))

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The action parts of a batch of agents (one row each; rows are independent of each other).

        Args:
            obs: Observation parts as ``(n, ...)`` arrays; only ``task`` is read.
            slots: The agents' slots (unused).
            step: Steps since the reset (unused).

        Returns:
            ``{"motion": (n, 3 or 8)}`` (and a silent ``"comm"`` with comms on).
        """
        d = np.asarray(obs["task"], dtype=np.float64).reshape(-1, 3) * self.side  # metres to the centroid
        # per-row norms written out (not a BLAS dot), so a row's value does not depend on the batch
        dist = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
        speed = np.minimum(self.max_speed, dist / self.slow_radius * self.max_speed)
        v = np.clip(d / np.maximum(dist, 1e-9)[:, None] * speed[:, None] / self.max_speed, -1.0, 1.0)
        return self.parts.arrays(v)
