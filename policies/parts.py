"""Complete actions for the velocity baselines, whatever action parts the env's config creates.

A baseline steers with a velocity per agent (``(3,)`` in units of the maximum speed) and, where it talks, a
``comm`` vector. The config decides the parts the env expects: ``motion`` is ``(3,)`` in velocity mode and
``(8,)`` in primitive mode, and ``comm`` exists exactly when ``comms`` is set. :class:`ActionParts` turns what
the baseline decided into every part:

| part     | from the baseline's velocity ``v`` and ``comm``                                              |
|----------|-----------------------------------------------------------------------------------------------|
| motion   | velocity mode: ``v``; primitive mode: the "velocity" primitive ``[sel, vx, vy, vz, 0, 0, 0, 0]`` |
|          | (the same target velocity, hence the same flight)                                             |
| comm     | ``comm`` when given, else silence: channel "none", zeros elsewhere                            |

A part it does not know (a scenario's own, such as ``uav_release``'s ``release``) is an error when the policy
is built, naming the part, rather than a guess.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.comms.stack import CHANNELS
from agentsim_env.motion.actions import (
    PRIMITIVE_ACTION_DIM,
    SEL_VELOCITY,
    VELOCITY_ACTION_DIM,
    selector_action,
)

SILENT_CHANNEL = -1.0 + 1.0 / len(CHANNELS)
"""The ``comm[0]`` value at the centre of the "none" bin: the agent sends nothing."""


class ActionParts:
    """The action parts of an env, filled from a velocity (and optional comm) per agent.

    Args:
        shapes: Part name -> shape, in the env's layout (``env.scenario.act_parts()``).
        owner: The policy's name, for the error about a part it cannot fill.

    Raises:
        ValueError: A part other than ``motion`` and ``comm``, or a ``motion`` that is neither (3,) nor (8,).
    """

    def __init__(self, shapes: dict[str, tuple[int, ...]], owner: str = "this baseline") -> None:
        unknown = [k for k in shapes if k not in ("motion", "comm")]
        if unknown:
            raise ValueError(f"{owner} fills the action parts 'motion' and 'comm' only; this env also has {unknown}")
        motion = shapes.get("motion")
        if motion not in ((VELOCITY_ACTION_DIM,), (PRIMITIVE_ACTION_DIM,)):
            raise ValueError(f"{owner} needs a 'motion' part of shape (3,) or (8,), got {motion}")
        self.primitive = motion == (PRIMITIVE_ACTION_DIM,)
        comm = shapes.get("comm")
        self.comm_dim = int(comm[0]) if comm is not None else 0

    @classmethod
    def for_env(cls, env: Any, owner: str = "this baseline") -> ActionParts:
        """The parts of ``env``'s scenario config."""
        return cls({k: p.shape for k, p in env.scenario.act_parts().items()}, owner)

    def silence(self, n: int) -> np.ndarray:
        """``(n, comm_dim)`` comm rows that send nothing (channel "none")."""
        out = np.zeros((n, self.comm_dim), dtype=np.float32)
        out[:, 0] = SILENT_CHANNEL
        return out

    def arrays(self, velocity: np.ndarray, comm: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The action parts of ``n`` agents as arrays (float32, one row per agent).

        Args:
            velocity: ``(n, 3)`` target velocities in units of the maximum speed.
            comm: ``(n, comm_dim)`` comm rows, or None for silence; dropped when the env has no comms.

        Returns:
            ``{"motion": (n, 3 or 8), "comm": (n, comm_dim)}`` with exactly the env's parts.
        """
        v = np.asarray(velocity, dtype=np.float32).reshape(-1, VELOCITY_ACTION_DIM)
        n = v.shape[0]
        if self.primitive:
            motion = np.zeros((n, PRIMITIVE_ACTION_DIM), dtype=np.float32)
            motion[:, 0] = selector_action(SEL_VELOCITY)
            motion[:, 1:4] = v
        else:
            motion = v
        if not self.comm_dim:
            return {"motion": motion}
        rows = self.silence(n) if comm is None else np.asarray(comm, dtype=np.float32)
        return {"motion": motion, "comm": rows}

    def pack(self, names: list[str], velocity: np.ndarray, comm: np.ndarray | None = None) -> dict[str, Any]:
        """Every agent's complete action (float32 arrays, one dict per agent).

        Args:
            names: The agents, in the row order of ``velocity``.
            velocity: ``(n, 3)`` target velocities in units of the maximum speed.
            comm: ``(n, comm_dim)`` comm rows, or None for silence; dropped when the env has no comms.

        Returns:
            ``{agent: {"motion": ..., "comm": ...}}`` with exactly the env's parts.
        """
        return rows_to_dicts(names, self.arrays(np.reshape(velocity, (len(names), VELOCITY_ACTION_DIM)), comm))


def rows_to_dicts(names: list[str], parts: dict[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
    """Per-agent action dicts from per-part row arrays (row ``i`` is agent ``names[i]``)."""
    keys = list(parts)
    cols = [parts[k] for k in keys]
    return {a: {k: c[i] for k, c in zip(keys, cols)} for i, a in enumerate(names)}


def stack_parts(observations: dict[str, Any], names: list[str], keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The observation parts ``keys`` of agents ``names`` stacked into ``(n, ...)`` arrays."""
    return {k: np.stack([observations[a][k] for a in names]) for k in keys}
