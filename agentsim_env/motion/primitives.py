"""Setters that start motion primitives on a set of slots (vectorised, no per-slot loops).

Every setter takes ``slots`` (``k`` unique integer indices) and per-slot arguments of shape
``(k,)`` or ``(k, 3)``; scalars and single rows broadcast. ``pos`` is always the world's full
``(S, 3)`` position array: rows ``slots`` are read as the start positions. Setting a primitive
restarts its clock (``t = 0``) and clears ``done``. Bad input raises ``ValueError`` naming the
argument.

Speed limits: the integrator clips linear speed, circular tangential speed, path speed and
velocity commands to each slot's ``max_speed``; ballistic (parabolic) motion is not clipped.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.motion.state import (
    CIRCULAR,
    HOLD,
    LINEAR,
    PARABOLIC,
    PATH,
    VELOCITY,
    MotionState,
    check_slots,
)

ArrayLike = np.ndarray | float | list


def per_slot(name: str, value: ArrayLike, shape: tuple[int, ...], nonneg: bool = False) -> np.ndarray:
    """Broadcast ``value`` to ``shape`` as finite ``float64``.

    Args:
        name: argument name used in error messages.
        value: scalar or array broadcastable to ``shape``.
        shape: target shape, e.g. ``(k,)`` or ``(k, 3)``.
        nonneg: also require every value ``>= 0``.

    Returns:
        A ``float64`` array of ``shape`` (read-only view when broadcast).

    Raises:
        ValueError: on a shape that does not broadcast, non-numeric, non-finite or negative values.
    """
    try:
        arr = np.asarray(value, dtype=np.float64)
        out = np.broadcast_to(arr, shape)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be finite numbers broadcastable to shape {shape}: {exc}") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN/inf)")
    if nonneg and np.any(arr < 0):
        raise ValueError(f"{name} must be >= 0, got min {arr.min()}")
    return out


def start_pos(ms: MotionState, idx: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """Validate the world position array and return the rows of ``idx`` (a copy).

    Args:
        ms: motion state (gives ``S``).
        idx: validated slot indices.
        pos: world positions ``(S, 3)``.

    Returns:
        ``(k, 3) float64`` start positions.

    Raises:
        ValueError: if ``pos`` is not ``(S, 3)`` or the selected rows are not finite.
    """
    p = np.asarray(pos, dtype=np.float64)
    if p.shape != (ms.n_slots, 3):
        raise ValueError(f"pos must be the world position array of shape ({ms.n_slots}, 3), got {p.shape}")
    rows = p[idx]
    if not np.all(np.isfinite(rows)):
        raise ValueError("pos must be finite (no NaN/inf) for the given slots")
    return rows


def _start(ms: MotionState, idx: np.ndarray, kind: int) -> None:
    """Common reset of the per-slot bookkeeping when a new primitive begins."""
    ms.kind[idx] = kind
    ms.params[idx] = 0.0
    ms.t[idx] = 0.0
    ms.n_waypoints[idx] = 0
    ms.wp_index[idx] = 0
    ms.loop[idx] = False
    ms.done[idx] = False


def set_velocity(ms: MotionState, slots: np.ndarray | list[int], target_vel: ArrayLike) -> None:
    """Command a target velocity; the integrator approaches it under ``max_accel``/``max_speed``.

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        target_vel: ``(k, 3)`` target velocity (m/s).
    """
    idx = check_slots(ms, slots)
    v = per_slot("target_vel", target_vel, (idx.size, 3))
    _start(ms, idx, VELOCITY)
    ms.params[idx, 0:3] = v


def set_linear(
    ms: MotionState,
    slots: np.ndarray | list[int],
    pos: np.ndarray,
    direction: ArrayLike,
    speed: ArrayLike,
    duration: ArrayLike,
) -> None:
    """Move at constant velocity along ``direction`` for ``duration`` s, then hover (``done``).

    A zero ``direction`` means no motion (the slot stays put until the duration elapses).

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        pos: world positions ``(S, 3)``; the start point is ``pos[slots]``.
        direction: ``(k, 3)`` direction, normalised here.
        speed: ``(k,)`` speed (m/s, >= 0).
        duration: ``(k,)`` duration (s, >= 0).
    """
    idx = check_slots(ms, slots)
    k = idx.size
    p0 = start_pos(ms, idx, pos)
    d = per_slot("direction", direction, (k, 3))
    sp = per_slot("speed", speed, (k,), nonneg=True)
    dur = per_slot("duration", duration, (k,), nonneg=True)
    norm = np.linalg.norm(d, axis=1)
    # Zero directions give zero velocity rather than NaN.
    unit = np.divide(d, norm[:, None], out=np.zeros((k, 3)), where=norm[:, None] > 1e-12)
    _start(ms, idx, LINEAR)
    ms.params[idx, 0:3] = p0
    ms.params[idx, 3:6] = unit * sp[:, None]
    ms.params[idx, 6] = dur


def set_circular(
    ms: MotionState,
    slots: np.ndarray | list[int],
    pos: np.ndarray,
    centre: ArrayLike,
    radius: ArrayLike,
    omega: ArrayLike,
    altitude: ArrayLike,
) -> None:
    """Uniform circular motion in the horizontal plane: ``angle = phase0 + omega * t``.

    ``phase0`` is the angle of the slot's current position about ``centre`` (0 when it sits on
    the centre); the slot is snapped onto the circle at the next integration step.

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        pos: world positions ``(S, 3)``.
        centre: ``(k, 2)`` circle centre xy (m).
        radius: ``(k,)`` radius (m, >= 0).
        omega: ``(k,)`` angular rate (rad/s, positive is counter-clockwise).
        altitude: ``(k,)`` flight altitude z (m).
    """
    idx = check_slots(ms, slots)
    k = idx.size
    p0 = start_pos(ms, idx, pos)
    c = per_slot("centre", centre, (k, 2))
    r = per_slot("radius", radius, (k,), nonneg=True)
    w = per_slot("omega", omega, (k,))
    z = per_slot("altitude", altitude, (k,))
    phase0 = np.arctan2(p0[:, 1] - c[:, 1], p0[:, 0] - c[:, 0])
    _start(ms, idx, CIRCULAR)
    ms.params[idx, 0:2] = c
    ms.params[idx, 2] = r
    ms.params[idx, 3] = w
    ms.params[idx, 4] = z
    ms.params[idx, 5] = phase0


def set_parabolic(
    ms: MotionState,
    slots: np.ndarray | list[int],
    pos: np.ndarray,
    v0: ArrayLike,
    gravity: ArrayLike = 9.81,
) -> None:
    """Ballistic flight ``p0 + v0 t - 0.5 g t^2 e_z`` until ``z`` reaches 0, then rest on the ground.

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        pos: world positions ``(S, 3)``; ``p0 = pos[slots]``.
        v0: ``(k, 3)`` initial velocity (m/s).
        gravity: ``(k,)`` gravitational acceleration (m/s^2, >= 0).
    """
    idx = check_slots(ms, slots)
    k = idx.size
    p0 = start_pos(ms, idx, pos)
    v = per_slot("v0", v0, (k, 3))
    g = per_slot("gravity", gravity, (k,), nonneg=True)
    _start(ms, idx, PARABOLIC)
    ms.params[idx, 0:3] = p0
    ms.params[idx, 3:6] = v
    ms.params[idx, 6] = g


def set_path(
    ms: MotionState,
    slots: np.ndarray | list[int],
    waypoints: np.ndarray | list[np.ndarray],
    counts: ArrayLike | None = None,
    speed: ArrayLike = 1.0,
    arrival_radius: ArrayLike = 0.0,
    loop: ArrayLike = False,
) -> None:
    """Follow waypoints in straight lines at ``speed``; loop or stop (``done``) at the end.

    The slot heads for waypoint ``wp_index``; a step never overshoots it, and the index advances
    once the slot is within ``arrival_radius`` of it.

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
        waypoints: ``(k, W, 3)`` or ``(W, 3)`` (same path for all) array, or a list of ``k``
            arrays of shape ``(n_i, 3)``; ``W <= ms.max_waypoints``.
        counts: ``(k,)`` valid waypoints per slot, in ``[1, W]``; defaults to ``W`` (array form)
            or ``n_i`` (list form).
        speed: ``(k,)`` travel speed (m/s, >= 0).
        arrival_radius: ``(k,)`` distance at which a waypoint counts as reached (m, >= 0).
        loop: ``(k,)`` wrap to the first waypoint after the last.
    """
    idx = check_slots(ms, slots)
    k = idx.size
    cap = ms.max_waypoints
    if isinstance(waypoints, (list, tuple)):
        if len(waypoints) != k:
            raise ValueError(f"waypoints list must have one array per slot ({k}), got {len(waypoints)}")
        rows = [np.asarray(w, dtype=np.float64) for w in waypoints]
        for w in rows:
            if w.ndim != 2 or w.shape[1] != 3 or not 1 <= w.shape[0] <= cap:
                raise ValueError(f"each waypoints entry must have shape (n, 3) with 1 <= n <= {cap}")
        n_max = max((w.shape[0] for w in rows), default=1)
        wp = np.zeros((k, n_max, 3))
        for i, w in enumerate(rows):  # setup-time only, not on the step path
            wp[i, : w.shape[0]] = w
        default_counts = np.array([w.shape[0] for w in rows], dtype=np.int64)
    else:
        wp = np.asarray(waypoints, dtype=np.float64)
        if wp.ndim == 2:
            wp = np.broadcast_to(wp, (k, *wp.shape))
        if wp.ndim != 3 or wp.shape[0] != k or wp.shape[2] != 3 or not 1 <= wp.shape[1] <= cap:
            raise ValueError(f"waypoints must have shape ({k}, W, 3) with 1 <= W <= {cap}, got {wp.shape}")
        default_counts = np.full(k, wp.shape[1], dtype=np.int64)
    n_w = wp.shape[1]
    if counts is None:
        cnt = default_counts
    else:
        c = np.asarray(counts)
        if c.size and not np.issubdtype(c.dtype, np.integer):
            raise ValueError(f"counts must be integers in [1, {n_w}], got dtype {c.dtype}")
        try:
            cnt = np.broadcast_to(c, (k,)).astype(np.int64)
        except ValueError:
            raise ValueError(f"counts must have shape ({k},), got {c.shape}") from None
    if k and (cnt.min() < 1 or cnt.max() > n_w):
        raise ValueError(f"counts must be in [1, {n_w}], got min {cnt.min()} max {cnt.max()}")
    used = np.arange(n_w)[None, :] < cnt[:, None]
    if not np.all(np.isfinite(wp[used])):
        raise ValueError("waypoints must be finite (no NaN/inf) in their used rows")
    sp = per_slot("speed", speed, (k,), nonneg=True)
    ar = per_slot("arrival_radius", arrival_radius, (k,), nonneg=True)
    try:
        lp = np.broadcast_to(np.asarray(loop, dtype=np.bool_), (k,))
    except ValueError:
        raise ValueError(f"loop must be bools broadcastable to ({k},)") from None
    _start(ms, idx, PATH)
    ms.waypoints[idx] = 0.0
    ms.waypoints[idx, :n_w] = np.where(used[:, :, None], wp, 0.0)
    ms.n_waypoints[idx] = cnt
    ms.loop[idx] = lp
    ms.params[idx, 0] = sp
    ms.params[idx, 1] = ar


def set_hold(ms: MotionState, slots: np.ndarray | list[int]) -> None:
    """Hover in place (velocity zero).

    Args:
        ms: motion state, modified in place.
        slots: ``(k,)`` slot indices.
    """
    idx = check_slots(ms, slots)
    _start(ms, idx, HOLD)
