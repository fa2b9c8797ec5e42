"""Decode RL actions (float32 Box, every value in ``[-1, 1]``) into motion primitives.

Two modes:

**Velocity mode** (``VELOCITY_ACTION_DIM = 3``): ``target_vel = a * max_speed`` per axis, then the
norm is clipped to ``max_speed``; a ``VELOCITY`` primitive is set.

**Primitive mode** (``PRIMITIVE_ACTION_DIM = 8``): ``a[0]`` selects the primitive, split into six
equal bins of ``[-1, 1]`` in this order: keep, velocity, linear, circular, parabolic, goto.
Notation: ``u(x) = (x + 1) / 2`` maps ``[-1, 1]`` to ``[0, 1]``; ``p`` is the agent's current
position; with ``L`` a :class:`MotionLimits`: ``S = L.max_speed``, ``R = L.max_radius``,
``T = L.max_duration``, ``W = L.max_omega``, ``zr(x) = L.z_min + u(x) (L.z_max - L.z_min)``.

| idx | name     | velocity | linear        | circular            | parabolic  | goto (1 waypoint) |
|-----|----------|----------|---------------|---------------------|------------|-------------------|
| 0   | selector | bin 1    | bin 2         | bin 3               | bin 4      | bin 5             |
| 1   | x        | vx a1 S  | direction x   | centre x p.x + a1 R | v0x a1 S   | wp x p.x + a1 R   |
| 2   | y        | vy a2 S  | direction y   | centre y p.y + a2 R | v0y a2 S   | wp y p.y + a2 R   |
| 3   | z        | vz a3 S  | direction z   | -                   | v0z a3 S   | -                 |
| 4   | speed    | -        | u(a4) S       | -                   | -          | u(a4) S           |
| 5   | rate     | -        | dur u(a5) T   | omega a5 W          | -          | -                 |
| 6   | altitude | -        | -             | z zr(a6)            | -          | wp z zr(a6)       |
| 7   | radius   | -        | -             | radius u(a7) R      | -          | -                 |

Bin 0 of the selector is "keep": it leaves the running primitive untouched, which is how an
agent continues a circle or a path. Velocity-like vectors (velocity target, parabolic ``v0``) have
their norm clipped to ``L.max_speed``. A zero linear direction means "stay". Parabolic flight uses
``L.gravity``; goto arrives within ``L.arrival_radius`` and then hovers (``done``). Out-of-range
values are clipped to ``[-1, 1]``; NaN/inf and wrong shapes raise ``ValueError`` naming ``actions``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from agentsim_env.motion.primitives import (
    set_circular,
    set_linear,
    set_parabolic,
    set_path,
    set_velocity,
)
from agentsim_env.motion.state import VELOCITY, MotionState, check_slots

VELOCITY_ACTION_DIM = 3
PRIMITIVE_ACTION_DIM = 8

SEL_KEEP = 0
SEL_VELOCITY = 1
SEL_LINEAR = 2
SEL_CIRCULAR = 3
SEL_PARABOLIC = 4
SEL_GOTO = 5
N_SELECTORS = 6
SELECTOR_NAMES: tuple[str, ...] = ("keep", "velocity", "linear", "circular", "parabolic", "goto")


@dataclass(frozen=True, slots=True)
class MotionLimits:
    """Scales that map primitive-mode actions from ``[-1, 1]`` to physical parameters.

    Attributes:
        max_speed: speed scale for velocities, linear/goto speeds and ``v0`` (m/s, > 0).
        max_accel: nominal acceleration limit (m/s^2, > 0); the integrator applies the world's
            per-slot ``max_accel``, this value documents the scenario's setting.
        max_radius: largest circle radius and largest centre / goto offset (m, > 0).
        max_duration: longest linear duration (s, > 0).
        z_min: lowest commanded altitude (m).
        z_max: highest commanded altitude (m, >= z_min).
        max_omega: largest circular angular rate (rad/s, > 0).
        gravity: gravity for parabolic flight (m/s^2, >= 0).
        arrival_radius: goto arrival radius (m, >= 0).
    """

    max_speed: float
    max_accel: float
    max_radius: float
    max_duration: float
    z_min: float
    z_max: float
    max_omega: float
    gravity: float = 9.81
    arrival_radius: float = 0.0

    def __post_init__(self) -> None:
        """Validate every field (finite; positivity as documented)."""
        for name in ("max_speed", "max_accel", "max_radius", "max_duration", "max_omega"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"MotionLimits.{name} must be a finite number > 0, got {v!r}")
        for name in ("gravity", "arrival_radius"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"MotionLimits.{name} must be a finite number >= 0, got {v!r}")
        for name in ("z_min", "z_max"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v)):
                raise ValueError(f"MotionLimits.{name} must be a finite number, got {v!r}")
        if self.z_max < self.z_min:
            raise ValueError(f"MotionLimits.z_max must be >= z_min ({self.z_min}), got {self.z_max}")


def selector_action(choice: int) -> float:
    """Return the ``a[0]`` value at the centre of the bin for ``choice`` (``SEL_KEEP`` .. ``SEL_GOTO``).

    Args:
        choice: selector index in ``[0, N_SELECTORS)``.

    Returns:
        A value in ``(-1, 1)`` that :func:`decode_primitive` maps back to ``choice``.
    """
    if not 0 <= int(choice) < N_SELECTORS:
        raise ValueError(f"choice must be in [0, {N_SELECTORS}), got {choice!r}")
    return -1.0 + (int(choice) + 0.5) * 2.0 / N_SELECTORS


def _check_actions(actions: np.ndarray, k: int, dim: int) -> np.ndarray:
    """Validate ``(k, dim)`` finite actions and clip them to ``[-1, 1]`` (fresh float64 array)."""
    try:
        a = np.asarray(actions, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"actions must be a numeric array of shape ({k}, {dim})") from None
    if a.shape != (k, dim):
        raise ValueError(f"actions must have shape ({k}, {dim}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("actions must be finite (no NaN/inf); values are expected in [-1, 1]")
    return np.clip(a, -1.0, 1.0)


def _clip_norm(v: np.ndarray, vmax: np.ndarray | float) -> np.ndarray:
    """Scale rows of ``v`` whose norm exceeds ``vmax`` back onto the ball."""
    n = np.linalg.norm(v, axis=1)
    vmax = np.broadcast_to(vmax, n.shape)
    f = np.where(n > vmax, vmax / np.where(n > 0, n, 1.0), 1.0)
    return v * f[:, None]


def decode_velocity(
    ms: MotionState, slots: np.ndarray | list[int], actions: np.ndarray, max_speed: np.ndarray | float
) -> None:
    """Set ``VELOCITY`` primitives from ``(k, 3)`` actions.

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        actions: ``(k, 3)`` values in ``[-1, 1]``.
        max_speed: scalar or ``(k,)`` speed scale (m/s, >= 0).

    Raises:
        ValueError: on NaN/inf or a wrong shape in ``actions`` or ``max_speed``.
    """
    idx = check_slots(ms, slots)
    a = _check_actions(actions, idx.size, VELOCITY_ACTION_DIM)
    vmax = np.asarray(max_speed, dtype=np.float64)
    try:
        vmax = np.broadcast_to(vmax, (idx.size,))
    except ValueError:
        raise ValueError(f"max_speed must be a scalar or shape ({idx.size},), got {vmax.shape}") from None
    if not np.all(np.isfinite(vmax)) or np.any(vmax < 0):
        raise ValueError("max_speed must be finite and >= 0")
    set_velocity(ms, idx, _clip_norm(a * vmax[:, None], vmax))


@njit(cache=True, error_model="numpy")  # its one division is by a norm > max_speed >= 0
def _velocity_kernel(kind, params, t, n_waypoints, wp_index, loop, done, acting, actions, max_speed):  # type: ignore[no-untyped-def]
    # Same arithmetic, in the same order, as decode_velocity: clip to [-1, 1], scale by max_speed, then
    # scale back onto the max_speed ball; so both paths give bit-identical targets.
    for s in range(kind.shape[0]):
        if not acting[s]:
            continue
        vmax = max_speed[s]
        x = min(max(actions[s, 0], -1.0), 1.0) * vmax
        y = min(max(actions[s, 1], -1.0), 1.0) * vmax
        z = min(max(actions[s, 2], -1.0), 1.0) * vmax
        n = math.sqrt(x * x + y * y + z * z)
        if n > vmax:
            f = vmax / n
            x, y, z = x * f, y * f, z * f
        kind[s] = VELOCITY
        params[s, :] = 0.0
        params[s, 0], params[s, 1], params[s, 2] = x, y, z
        t[s] = 0.0
        n_waypoints[s] = 0
        wp_index[s] = 0
        loop[s] = False
        done[s] = False


def decode_velocity_unchecked(ms: MotionState, acting: np.ndarray, actions: np.ndarray, max_speed: np.ndarray) -> None:
    """Hot-path twin of :func:`decode_velocity` over every slot at once (one kernel, no validation).

    Gives exactly the targets :func:`decode_velocity` gives; the caller guarantees the input (the env has
    already checked shapes and finiteness), so nothing is re-validated here.

    Args:
        ms: motion state, modified in place.
        acting: ``(S,) bool`` slots whose primitive is set; the others keep theirs.
        actions: ``(S, 3)`` finite float64 values (clipped to ``[-1, 1]`` here); rows of non-acting slots
            are ignored.
        max_speed: ``(S,)`` float64 speed scale per slot (m/s, >= 0).
    """
    _velocity_kernel(
        ms.kind, ms.params, ms.t, ms.n_waypoints, ms.wp_index, ms.loop, ms.done, acting, actions, max_speed
    )


def decode_primitive(
    ms: MotionState,
    slots: np.ndarray | list[int],
    actions: np.ndarray,
    pos: np.ndarray,
    limits: MotionLimits,
) -> np.ndarray:
    """Set the primitives chosen by ``(k, PRIMITIVE_ACTION_DIM)`` actions (layout in the module doc).

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        actions: ``(k, 8)`` values in ``[-1, 1]``.
        pos: world positions ``(S, 3)`` (offsets are relative to ``pos[slots]``).
        limits: scales for the parameters.

    Returns:
        ``(k,) int64`` selector per slot (``SEL_KEEP`` .. ``SEL_GOTO``).

    Raises:
        ValueError: on NaN/inf or a wrong shape in ``actions`` or ``pos``.
    """
    idx = check_slots(ms, slots)
    a = _check_actions(actions, idx.size, PRIMITIVE_ACTION_DIM)
    p = np.asarray(pos, dtype=np.float64)
    if p.shape != (ms.n_slots, 3):
        raise ValueError(f"pos must be the world position array of shape ({ms.n_slots}, 3), got {p.shape}")
    sel = np.minimum(((a[:, 0] + 1.0) * (N_SELECTORS / 2.0)).astype(np.int64), N_SELECTORS - 1)
    u = (a + 1.0) * 0.5
    zr = limits.z_min + u[:, 6] * (limits.z_max - limits.z_min)
    vs = limits.max_speed

    m = sel == SEL_VELOCITY
    if m.any():
        set_velocity(ms, idx[m], _clip_norm(a[m, 1:4] * vs, vs))
    m = sel == SEL_LINEAR
    if m.any():
        set_linear(ms, idx[m], p, a[m, 1:4], u[m, 4] * vs, u[m, 5] * limits.max_duration)
    m = sel == SEL_CIRCULAR
    if m.any():
        centre = p[idx[m], 0:2] + a[m, 1:3] * limits.max_radius
        radius = u[m, 7] * limits.max_radius
        set_circular(ms, idx[m], p, centre, radius, a[m, 5] * limits.max_omega, zr[m])
    m = sel == SEL_PARABOLIC
    if m.any():
        set_parabolic(ms, idx[m], p, _clip_norm(a[m, 1:4] * vs, vs), limits.gravity)
    m = sel == SEL_GOTO
    if m.any():
        wp = np.empty((int(m.sum()), 1, 3))
        wp[:, 0, 0:2] = p[idx[m], 0:2] + a[m, 1:3] * limits.max_radius
        wp[:, 0, 2] = zr[m]
        set_path(ms, idx[m], wp, 1, u[m, 4] * vs, limits.arrival_radius, False)
    return sel
