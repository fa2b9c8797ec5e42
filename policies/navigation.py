"""Scripted baseline for ``navigation``: go to the goal, steer around what the proximity scan sees.

A potential field on the Dict observation: attraction toward the goal plus repulsion from every ray of the
horizontal ring that hits an agent or an object, with a sideways component so an agent facing an obstacle head
on slides around it instead of stalling. Works with Dict observations, in either action mode, with or without
comms (it stays silent: ``policies.parts``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.policies.parts import ActionParts, rows_to_dicts, stack_parts


class GoToGoalPolicy:
    """Go-to-goal with scan-based avoidance.

    Args:
        n_azimuth: Rays per elevation ring (the scenario's ``n_azimuth``); ring 0 is the horizontal one.
        sensor_range: The scenario's sensor range in metres (to turn distances into metres).
        map_diagonal: The map diagonal in metres (the ``task`` part is scaled by it).
        avoid_gain: Strength of the repulsion.
        influence: Distance (m) under which obstacles repel.
        parts: The env's action parts (default: velocity mode, no comms).
    """

    def __init__(
        self,
        n_azimuth: int = 16,
        sensor_range: float = 10.0,
        map_diagonal: float = 60.0 * np.sqrt(2.0),
        avoid_gain: float = 1.6,
        influence: float = 5.0,
        parts: ActionParts | None = None,
    ) -> None:
        self.n_azimuth = n_azimuth
        self.sensor_range = sensor_range
        self.map_diagonal = map_diagonal
        self.avoid_gain = avoid_gain
        self.influence = influence
        self._az = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
        self.parts = parts if parts is not None else ActionParts({"motion": (3,)}, "GoToGoalPolicy")

    @classmethod
    def for_env(cls, env: Any) -> GoToGoalPolicy:
        """A policy configured from a navigation env's scenario config."""
        c = env.scenario.config
        return cls(
            n_azimuth=c.sensing.n_azimuth,
            sensor_range=c.sensing.range,
            map_diagonal=c.side * np.sqrt(2.0),
            parts=ActionParts.for_env(env, "GoToGoalPolicy"),
        )

    def reset(self, seed: int | None = None) -> None:
        """No state to reset (the policy is deterministic)."""

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Every observed agent's action: its velocity as ``motion`` (and a silent ``comm`` with comms on)."""
        if not observations:
            return {}
        names = list(observations)
        parts = stack_parts(observations, names, ("self", "lidar", "task"))
        return rows_to_dicts(names, self.act_rows(parts, np.zeros(0, dtype=np.int64), 0))

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The action parts of a batch of agents (one row each; rows are independent of each other).

        Args:
            obs: Observation parts ``self``, ``lidar`` and ``task`` as ``(n, ...)`` arrays.
            slots: The agents' slots (unused: the policy is the same for every agent).
            step: Steps since the reset (unused).

        Returns:
            ``{"motion": (n, 3 or 8)}`` (and ``"comm"``, silent, with comms on).
        """
        selfp, lidar, task = obs["self"], obs["lidar"], obs["task"]
        if selfp.shape[0] == 0:
            return self.parts.arrays(np.zeros((0, 3)))
        heading = np.arctan2(selfp[:, 7], selfp[:, 6])
        goal = task[:, :3] * self.map_diagonal
        dist = np.linalg.norm(goal, axis=1, keepdims=True)
        # slow down near the goal so the agent stops inside the goal radius instead of overshooting
        attract = goal / np.maximum(dist, 1e-6) * np.clip(dist / 3.0, 0.3, 1.0)
        ring = lidar[:, : self.n_azimuth]
        d = ring[:, :, 0] * self.sensor_range
        solid = (ring[:, :, 1] > 0.2) & (ring[:, :, 1] < 0.9)  # agents and objects, not the ground
        ang = heading[:, None] + self._az[None, :]
        dirs = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
        w = np.where(solid & (d < self.influence), (self.influence - d) / np.maximum(d, 0.3), 0.0)
        push = -(w[:, :, None] * dirs).sum(axis=1)
        side = np.stack([push[:, 1], -push[:, 0]], axis=-1)  # turn right around what is ahead
        v = attract.copy()
        v[:, :2] += self.avoid_gain * (push + 0.5 * side) / self.n_azimuth * 4.0
        norm = np.linalg.norm(v, axis=1, keepdims=True)
        v = np.where(norm > 1.0, v / np.maximum(norm, 1e-9), v)
        return self.parts.arrays(v)
