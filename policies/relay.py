"""Scripted baselines for ``relay``: flood the target's position over relays, or search in silence.

Target report (the payload both ends of :class:`FloodPolicy` agree on; needs ``comms.payload_dim >= 4``):

| payload index | meaning                                                                 |
|---------------|-------------------------------------------------------------------------|
| 0, 1          | target x, y normalised to the map: ``2 x / length - 1``, ``2 y / width - 1`` |
| 2             | the group code of the target's group (as in the ``self`` part)           |
| 3             | 1.0: marks the message as a target report                                |
| 4..           | 0                                                                       |

A receiver takes the newest valid AGENT, GROUP or OVERLAY message of its inbox whose marker is 1 and whose
group code is its own; once known, a target is remembered for the rest of the episode.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from agentsim_env.comms.stack import CHANNELS
from agentsim_env.policies.parts import ActionParts, rows_to_dicts, stack_parts

_KIND_AGENT, _KIND_GROUP, _KIND_OVERLAY = 1, 2, 4  # one-hot columns of an inbox row (comms.messages)
_PAYLOAD0 = 11  # first payload column of an inbox row
# channel values at the centre of each of the 5 equal bins of [-1, 1] (comms.stack)
_CH = {name: -1.0 + (2 * i + 1) / len(CHANNELS) for i, name in enumerate(CHANNELS)}


def _avoidance(
    lidar: np.ndarray, heading: np.ndarray, n_azimuth: int, sensor_range: float, influence: float
) -> np.ndarray:
    """Horizontal push away from agents and objects seen by the horizontal ring (as in GoToGoalPolicy).

    Returns:
        ``(n, 2)`` push, already scaled like the navigation baseline's avoidance term.
    """
    az = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
    ring = lidar[:, :n_azimuth]
    d = ring[:, :, 0] * sensor_range
    solid = (ring[:, :, 1] > 0.2) & (ring[:, :, 1] < 0.9)  # agents and objects, not the ground
    ang = heading[:, None] + az[None, :]
    dirs = np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    w = np.where(solid & (d < influence), (influence - d) / np.maximum(d, 0.3), 0.0)
    push = -(w[:, :, None] * dirs).sum(axis=1)
    side = np.stack([push[:, 1], -push[:, 0]], axis=-1)  # turn right around what is ahead
    return 1.6 * (push + 0.5 * side) / n_azimuth * 4.0


class _RelayBase(ABC):
    """What both baselines share: the map scale, agent indices and the Dict-observation plumbing; each baseline
    gives ``act_rows``."""

    def __init__(
        self,
        agents: list[str],
        length: float,
        width: float,
        n_groups: int,
        n_azimuth: int,
        sensor_range: float,
        payload_dim: int,
        parts: ActionParts | None = None,
    ) -> None:
        self.index = {a: i for i, a in enumerate(agents)}
        # the env's action parts (default: velocity mode; relay always has comms)
        self.parts = parts if parts is not None else ActionParts({"motion": (3,), "comm": (3 + payload_dim,)})
        self.scale = np.array([length, width])
        self.diag = float(np.hypot(length, width))
        self.n_groups = n_groups
        self.n_azimuth = n_azimuth
        self.sensor_range = sensor_range
        self.payload_dim = payload_dim
        self.step = 0

    @staticmethod
    def _env_args(env: Any) -> dict[str, Any]:
        c = env.scenario.config
        return {
            "agents": list(env.possible_agents),
            "length": c.length,
            "width": c.corridor_width,
            "n_groups": c.n_groups,
            "n_azimuth": c.sensing.n_azimuth,
            "sensor_range": c.sensing.range,
            "payload_dim": c.comms.payload_dim,
            "parts": ActionParts.for_env(env, "the relay baselines"),
        }

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """``{"motion": (3,), "comm": (3 + D,)}`` for every observed agent (one step: see ``act_rows``)."""
        if not observations:
            return {}
        names = list(observations)
        parts = stack_parts(observations, names, ("self", "lidar", "task", "inbox"))
        slots = np.array([self.index[a] for a in names], dtype=np.int64)
        out = self.act_rows(parts, slots, self.step)
        self.step += 1
        return rows_to_dicts(names, out)

    @abstractmethod
    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The action parts of the agents in ``slots`` at ``step`` (rows independent of each other)."""

    def _move(self, parts: dict[str, np.ndarray], goal: np.ndarray | None, active: np.ndarray) -> np.ndarray:
        """Velocity actions: toward ``goal`` (absolute x, y) where ``active``, else hover; plus avoidance."""
        selfp = parts["self"]
        v = np.zeros((selfp.shape[0], 3))
        if goal is not None:
            pos = (selfp[:, :2] + 1.0) / 2.0 * self.scale
            d = goal - pos
            dist = np.linalg.norm(d, axis=1, keepdims=True)
            # slow down near the target so the agent stops inside the arrival radius instead of overshooting
            att = d / np.maximum(dist, 1e-6) * np.clip(dist / 3.0, 0.3, 1.0)
            v[:, :2] = np.where(active[:, None], att, 0.0)
        heading = np.arctan2(selfp[:, 7], selfp[:, 6])
        v[:, :2] += _avoidance(parts["lidar"], heading, self.n_azimuth, self.sensor_range, 4.0)
        norm = np.linalg.norm(v, axis=1, keepdims=True)
        return np.where(norm > 1.0, v / np.maximum(norm, 1e-9), v)


class FloodPolicy(_RelayBase):
    """Scouts flood their target's position; members go to the newest report and pass it on.

    Every ``period`` steps (staggered by agent index) an agent that knows its group's target sends a report
    (layout in the module docstring) as an overlay flood with the largest hop limit, and half a period later
    the same report to its group on the bus. Scouts hover; members that know the target fly to it with
    scan-based avoidance, members that do not yet know it hover (keeping the relay chain in place).

    Args:
        agents: The env's ``possible_agents``.
        length: Corridor length (m).
        width: Corridor width (m).
        n_groups: Groups per world.
        n_azimuth: Rays of the horizontal ring.
        sensor_range: Sensor range (m).
        payload_dim: Payload width D (>= 4).
        period: Steps between two reports of one agent on the same channel.
        parts: The env's action parts (default: velocity mode; in primitive mode the velocity is flown as the
            "velocity" primitive, ``policies.parts``).
    """

    def __init__(
        self,
        agents: list[str],
        length: float,
        width: float,
        n_groups: int,
        n_azimuth: int,
        sensor_range: float,
        payload_dim: int,
        period: int = 6,
        parts: ActionParts | None = None,
    ) -> None:
        if payload_dim < 4:
            raise ValueError(f"comms.payload_dim must be >= 4 for the target report, got {payload_dim}")
        super().__init__(agents, length, width, n_groups, n_azimuth, sensor_range, payload_dim, parts)
        self.period = period
        self.known = np.full((len(agents), 2), np.nan)

    @classmethod
    def for_env(cls, env: Any) -> FloodPolicy:
        """A flooding policy configured from a relay env's scenario config."""
        return cls(**cls._env_args(env))

    def reset(self, seed: int | None = None) -> None:
        """Forget every known target (the policy is otherwise deterministic)."""
        self.known[:] = np.nan
        self.step = 0

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The action parts of the agents in ``slots`` at ``step`` (steps since the reset).

        Rows are independent: an agent's row depends on its own observation, its own remembered target and
        ``step`` only, so acting on a subset of the agents gives those agents' rows of acting on all.

        Args:
            obs: Observation parts ``self``, ``lidar``, ``task`` and ``inbox`` as ``(n, ...)`` arrays.
            slots: ``(n,)`` the agents' indices in ``possible_agents``.
            step: Steps since the reset (staggers the reports).

        Returns:
            ``{"motion": (n, 3 or 8), "comm": (n, 3 + D)}``.
        """
        idx = np.asarray(slots, dtype=np.int64)
        n = idx.shape[0]
        selfp, task, inbox = obs["self"], obs["task"], obs["inbox"]
        scout = task[:, 0] > 0.5
        pos = (selfp[:, :2] + 1.0) / 2.0 * self.scale
        own = np.where(scout[:, None], pos + task[:, 1:3] * self.diag, np.nan)
        # newest report of my own group in the inbox (rows are newest first)
        pay = inbox[:, :, _PAYLOAD0:]
        ok = (inbox[:, :, 0] > 0.5) & (inbox[:, :, [_KIND_AGENT, _KIND_GROUP, _KIND_OVERLAY]].max(axis=2) > 0.5)
        ok &= (np.abs(pay[:, :, 3] - 1.0) < 1e-3) & (
            np.abs(pay[:, :, 2] - selfp[:, None, 8]) < 0.5 / max(self.n_groups, 2)
        )
        first = np.argmax(ok, axis=1) if n else np.zeros(0, dtype=np.int64)
        heard = ok.any(axis=1)
        got = (pay[np.arange(n), first, :2] + 1.0) / 2.0 * self.scale
        known = self.known[idx]
        known = np.where(heard[:, None], got, known)
        known = np.where(scout[:, None], own, known)
        self.known[idx] = known
        has = ~np.isnan(known[:, 0])
        motion = self._move(obs, np.nan_to_num(known), has & ~scout)
        # reports: overlay flood at phase 0, group bus at half a period, staggered by agent index
        phase = (step + idx) % self.period
        comm = np.zeros((n, 3 + self.payload_dim))
        comm[:, 0] = _CH["none"]
        comm[has & (phase == 0), 0] = _CH["overlay"]
        comm[has & (phase == self.period // 2), 0] = _CH["group"]
        comm[:, 2] = 1.0  # hop limit: the largest allowed
        comm[:, 3:5] = np.where(has[:, None], np.nan_to_num(known) / self.scale * 2.0 - 1.0, 0.0)
        comm[:, 5] = selfp[:, 8]
        comm[:, 6] = 1.0
        return self.parts.arrays(motion, comm)


class SilentPolicy(_RelayBase):
    """Never communicates: scouts hover, members sweep the corridor in a zig-zag and arrive only by chance.

    Each member flies along x (direction drawn per episode), crossing the corridor at ``sweep_deg`` to the
    axis and turning back at the walls and the ends, so it covers a band of the map; it never learns where
    the target is, so it arrives only if its sweep passes within the arrival radius.

    Args:
        agents: The env's ``possible_agents``.
        length: Corridor length (m).
        width: Corridor width (m).
        n_groups: Groups per world.
        n_azimuth: Rays of the horizontal ring.
        sensor_range: Sensor range (m).
        payload_dim: Payload width D.
        sweep_deg: Angle between the sweep and the corridor axis.
        parts: The env's action parts (default: velocity mode; see :class:`FloodPolicy`).
    """

    def __init__(
        self,
        agents: list[str],
        length: float,
        width: float,
        n_groups: int,
        n_azimuth: int,
        sensor_range: float,
        payload_dim: int,
        sweep_deg: float = 35.0,
        parts: ActionParts | None = None,
    ) -> None:
        super().__init__(agents, length, width, n_groups, n_azimuth, sensor_range, payload_dim, parts)
        self.sweep = np.radians(sweep_deg)
        self.direction = np.ones((len(agents), 2))
        self.rng = np.random.default_rng(0)

    @classmethod
    def for_env(cls, env: Any) -> SilentPolicy:
        """A silent search policy configured from a relay env's scenario config."""
        return cls(**cls._env_args(env))

    def reset(self, seed: int | None = None) -> None:
        """Draw each agent's initial sweep directions from ``seed``."""
        self.rng = np.random.default_rng(seed)
        self.direction = self.rng.choice([-1.0, 1.0], size=self.direction.shape)
        self.step = 0

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The action parts of the agents in ``slots`` (channel none; rows independent of each other).

        Args:
            obs: Observation parts ``self``, ``lidar`` and ``task`` as ``(n, ...)`` arrays.
            slots: ``(n,)`` the agents' indices in ``possible_agents`` (their sweep directions).
            step: Steps since the reset (unused).

        Returns:
            ``{"motion": (n, 3 or 8), "comm": (n, 3 + D)}``.
        """
        idx = np.asarray(slots, dtype=np.int64)
        selfp = obs["self"]
        member = obs["task"][:, 0] < 0.5
        d = self.direction[idx]
        # turn back near the ends of the corridor and near its walls
        d[:, 0] = np.where(selfp[:, 0] > 0.95, -1.0, np.where(selfp[:, 0] < -0.95, 1.0, d[:, 0]))
        d[:, 1] = np.where(selfp[:, 1] > 0.85, -1.0, np.where(selfp[:, 1] < -0.85, 1.0, d[:, 1]))
        self.direction[idx] = d
        pos = (selfp[:, :2] + 1.0) / 2.0 * self.scale
        goal = pos + 10.0 * d * np.array([np.cos(self.sweep), np.sin(self.sweep)])
        motion = self._move(obs, goal, member)
        comm = np.zeros((idx.shape[0], 3 + self.payload_dim))
        comm[:, 0] = _CH["none"]
        return self.parts.arrays(motion, comm)
