"""Advance every online slot's motion primitive by one step (a numba kernel; its numpy reference is in tests).

Per kind (``t`` is advanced by ``dt`` first, then the state is evaluated at the new ``t``):

- VELOCITY: the target is clipped to ``max_speed``; ``vel`` moves toward it by at most
  ``max_accel * dt``, is clipped to ``max_speed``, then ``pos += vel * dt`` (semi-implicit Euler).
- LINEAR: closed form ``p0 + v * min(t, duration)`` with ``|v|`` clipped to ``max_speed``; at the
  end ``vel = 0`` and ``done``.
- CIRCULAR: closed form ``angle = phase0 + omega_eff * t`` where ``|omega_eff| * radius`` is clipped
  to ``max_speed``; ``z = altitude``.
- PARABOLIC: closed form ``p0 + v0 t - 0.5 g t^2 e_z``; when ``z <= 0`` the slot rests at the exact
  landing point (``z = 0``), ``vel = 0``, ``done``. Not speed-limited.
- PATH: a straight step toward the current waypoint at ``min(speed, max_speed)`` that never
  overshoots it; within ``arrival_radius`` the index advances (wraps if ``loop``, else ``done``).
  A finished path hovers.
- HOLD: ``vel = 0``, ``pos`` unchanged.

Offline slots keep ``pos``, their clock does not run and ``vel`` is set to 0. ``heading`` becomes
``atan2(vy, vx)`` when the horizontal speed exceeds 1e-9, else it is unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from agentsim_env.core.threads import RowThreads
from agentsim_env.motion.state import CIRCULAR, LINEAR, PARABOLIC, PATH, VELOCITY, MotionState

_ONE = RowThreads(1)

# Slack on "duration elapsed" so that n * dt == duration finishes on step n despite rounding of t.
T_EPS = 1e-9
HEADING_EPS = 1e-9
# Cody-Waite split of pi/2 (fdlibm): q * PIO2_HI is exact for |q| < 2^20, so angle reduction stays
# accurate to ~1e-16 for angles up to ~1e6 rad.
PIO2_HI = 1.57079632673412561417e00
PIO2_LO = 6.07710050650619224932e-11
TWO_OVER_PI = 2.0 / math.pi
HALF_PI = 0.5 * math.pi
TWO_PI = 2.0 * math.pi
# fdlibm __kernel_sin / __kernel_cos coefficients on [-pi/4, pi/4].
_S1, _S2, _S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
_S4, _S5, _S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
_C1, _C2, _C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
_C4, _C5, _C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11
# fdlibm atan coefficients, valid for |u| <= 7/16 (we use |u| <= tan(pi/8)).
_A0, _A1, _A2 = 3.33333333333329318027e-01, -1.99999999998764832476e-01, 1.42857142725034663711e-01
_A3, _A4, _A5 = -1.11111104054623557880e-01, 9.09088713343650656196e-02, -7.69187620504482999495e-02
_A6, _A7, _A8 = 6.66107313738753120669e-02, -5.83357013379057348645e-02, 4.97687799461593236017e-02
_A9, _A10 = -3.65315727442169155270e-02, 1.62858201153657823623e-02
TAN_PI_8 = math.tan(math.pi / 8.0)


@njit(cache=True, inline="always")
def _sincos(ang: float) -> tuple[float, float, float, int]:
    """``sin``, ``cos`` of ``ang`` and its reduction ``ang = q pi/2 + x``, ``|x| <= pi/4``.

    fdlibm kernels on the reduced argument (< 1 ulp there), branch-free quadrant selection: about
    2x faster than libm on the growing angles of circular motion. Returns ``(sin, cos, x, q & 3)``.
    """
    q = math.floor(ang * TWO_OVER_PI + 0.5)
    x = (ang - q * PIO2_HI) - q * PIO2_LO
    z = x * x
    w = z * z
    s0 = x + z * x * (_S1 + z * (_S2 + z * (_S3 + z * _S4) + z * w * (_S5 + z * _S6)))
    r = z * (_C1 + z * (_C2 + z * _C3)) + w * w * (_C4 + z * (_C5 + z * _C6))
    hz = 0.5 * z
    c1 = 1.0 - hz
    c0 = c1 + (((1.0 - c1) - hz) + z * r)
    qi = int(q) & 3
    odd = float(qi & 1)
    sign = 1.0 - float(qi & 2)
    return sign * (s0 + odd * (c0 - s0)), sign * (c0 - odd * (c0 + s0)), x, qi


@njit(cache=True, inline="always")
def _atan2(y: float, x: float) -> float:
    """``atan2(y, x)`` within ~4e-16 for ``max(|x|, |y|) > 0``; about 2x faster than libm here.

    Octant folding plus ``atan(t) = pi/4 + atan((t-1)/(t+1))`` keeps the fdlibm polynomial on
    ``|u| <= tan(pi/8)``; signs follow libm (``copysign`` handles signed zeros).
    """
    ax, ay = abs(x), abs(y)
    swap = ay > ax
    t = (ax / ay) if swap else (ay / ax)
    big = t > TAN_PI_8
    u = (t - 1.0) / (t + 1.0) if big else t
    z = u * u
    w = z * z
    s1 = z * (_A0 + w * (_A2 + w * (_A4 + w * (_A6 + w * (_A8 + w * _A10)))))
    s2 = w * (_A1 + w * (_A3 + w * (_A5 + w * (_A7 + w * _A9))))
    a = u - u * (s1 + s2)
    if big:
        a += 0.25 * math.pi
    if swap:
        a = HALF_PI - a
    if x < 0.0:
        a = math.pi - a
    return math.copysign(a, y)


def _landing_time(z0: float, vz: float, g: float, t: float) -> float:
    """Time in ``[0, t]`` at which ``z0 + vz s - 0.5 g s^2`` reaches 0 (``t`` if no root)."""
    if g > 0.0:
        disc = vz * vz + 2.0 * g * z0
        tl = (vz + math.sqrt(disc)) / g if disc >= 0.0 else t
    elif vz < 0.0:
        tl = -z0 / vz
    else:
        tl = t
    return min(max(tl, 0.0), t)


_landing_time_nb = njit(cache=True)(_landing_time)


@njit(cache=True, nogil=True)
def _integrate_kernel(
    lo: int,
    hi: int,
    kind: np.ndarray,
    params: np.ndarray,
    t: np.ndarray,
    waypoints: np.ndarray,
    n_waypoints: np.ndarray,
    wp_index: np.ndarray,
    done: np.ndarray,
    loop: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    max_speed: np.ndarray,
    max_accel: np.ndarray,
    online: np.ndarray,
    dt: float,
) -> None:
    # Slots lo..hi-1 (rows are independent: ranges may run on different threads).
    for s in range(lo, hi):
        if not online[s]:
            vel[s, 0] = 0.0
            vel[s, 1] = 0.0
            vel[s, 2] = 0.0
            continue
        tt = t[s] + dt
        t[s] = tt
        k = kind[s]
        vmax = max_speed[s]
        if k == VELOCITY:
            tx, ty, tz = params[s, 0], params[s, 1], params[s, 2]
            tn = math.sqrt(tx * tx + ty * ty + tz * tz)
            if tn > vmax:
                f = vmax / tn
                tx, ty, tz = tx * f, ty * f, tz * f
            dx, dy, dz = tx - vel[s, 0], ty - vel[s, 1], tz - vel[s, 2]
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            amax = max_accel[s] * dt
            if dn <= amax:
                vx, vy, vz = tx, ty, tz
            else:
                f = amax / dn
                vx, vy, vz = vel[s, 0] + dx * f, vel[s, 1] + dy * f, vel[s, 2] + dz * f
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            if vn > vmax:
                f = vmax / vn
                vx, vy, vz = vx * f, vy * f, vz * f
            pos[s, 0] += vx * dt
            pos[s, 1] += vy * dt
            pos[s, 2] += vz * dt
        elif k == LINEAR:
            vx, vy, vz = params[s, 3], params[s, 4], params[s, 5]
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            if vn > vmax:
                f = vmax / vn
                vx, vy, vz = vx * f, vy * f, vz * f
            dur = params[s, 6]
            te = tt
            if tt + T_EPS >= dur:
                te = dur
                done[s] = True
            pos[s, 0] = params[s, 0] + vx * te
            pos[s, 1] = params[s, 1] + vy * te
            pos[s, 2] = params[s, 2] + vz * te
            if done[s]:
                vx, vy, vz = 0.0, 0.0, 0.0
        elif k == CIRCULAR:
            r = params[s, 2]
            w = params[s, 3]
            if r * abs(w) > vmax:
                w = math.copysign(vmax / r, w)
            ang = params[s, 5] + w * tt
            sn, c, x, qi = _sincos(ang)
            pos[s, 0] = params[s, 0] + r * c
            pos[s, 1] = params[s, 1] + r * sn
            pos[s, 2] = params[s, 4]
            vel[s, 0], vel[s, 1], vel[s, 2] = -r * w * sn, r * w * c, 0.0
            if abs(r * w) > HEADING_EPS:
                # Velocity leads the radius by +-pi/2: heading = ang +- pi/2, wrapped to (-pi, pi].
                h = float((qi + (1 if w > 0.0 else 3)) & 3) * HALF_PI + x
                heading[s] = h - TWO_PI if h > math.pi else h
            continue
        elif k == PARABOLIC:
            g = params[s, 6]
            z = params[s, 2] + params[s, 5] * tt - 0.5 * g * tt * tt
            if z <= 0.0:
                te = _landing_time_nb(params[s, 2], params[s, 5], g, tt)
                pos[s, 0] = params[s, 0] + params[s, 3] * te
                pos[s, 1] = params[s, 1] + params[s, 4] * te
                pos[s, 2] = 0.0
                vx, vy, vz = 0.0, 0.0, 0.0
                done[s] = True
            else:
                pos[s, 0] = params[s, 0] + params[s, 3] * tt
                pos[s, 1] = params[s, 1] + params[s, 4] * tt
                pos[s, 2] = z
                vx, vy, vz = params[s, 3], params[s, 4], params[s, 5] - g * tt
        elif k == PATH and not done[s]:
            i = wp_index[s]
            wx, wy, wz = waypoints[s, i, 0], waypoints[s, i, 1], waypoints[s, i, 2]
            dx, dy, dz = wx - pos[s, 0], wy - pos[s, 1], wz - pos[s, 2]
            dist = math.sqrt(dx * dx + dy * dy + dz * dz)
            spd = min(params[s, 0], vmax)
            if spd * dt >= dist:
                # Arrive exactly: no overshoot, no rounding residue.
                vx, vy, vz = dx / dt, dy / dt, dz / dt
                pos[s, 0], pos[s, 1], pos[s, 2] = wx, wy, wz
                dist = 0.0
            else:
                f = spd / dist
                vx, vy, vz = dx * f, dy * f, dz * f
                pos[s, 0] += vx * dt
                pos[s, 1] += vy * dt
                pos[s, 2] += vz * dt
                dist -= spd * dt
            if dist <= params[s, 1]:
                i += 1
                if i >= n_waypoints[s]:
                    if loop[s]:
                        i = 0
                    else:
                        i = n_waypoints[s] - 1
                        done[s] = True
                wp_index[s] = i
        else:  # HOLD, or a finished PATH: hover
            vx, vy, vz = 0.0, 0.0, 0.0
        vel[s, 0], vel[s, 1], vel[s, 2] = vx, vy, vz
        if math.sqrt(vx * vx + vy * vy) > HEADING_EPS:
            heading[s] = _atan2(vy, vx)


def _check(name: str, arr: np.ndarray, shape: tuple[int, ...], dtype: type) -> None:
    if not isinstance(arr, np.ndarray) or arr.shape != shape or arr.dtype != dtype:
        got = (getattr(arr, "shape", None), getattr(arr, "dtype", type(arr)))
        raise ValueError(f"{name} must be a {np.dtype(dtype)} array of shape {shape}, got {got}")


def _validate(
    ms: MotionState,
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    max_speed: np.ndarray,
    max_accel: np.ndarray,
    online: np.ndarray,
    dt: float,
) -> float:
    s = ms.n_slots
    _check("pos", pos, (s, 3), np.float64)
    _check("vel", vel, (s, 3), np.float64)
    _check("heading", heading, (s,), np.float64)
    _check("max_speed", max_speed, (s,), np.float64)
    _check("max_accel", max_accel, (s,), np.float64)
    _check("online", online, (s,), np.bool_)
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be finite and > 0, got {dt}")
    return dt


def integrate(
    ms: MotionState,
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    max_speed: np.ndarray,
    max_accel: np.ndarray,
    online: np.ndarray,
    dt: float,
) -> None:
    """Advance every online slot by one step of ``dt``, in place (numba kernel).

    Args:
        ms: motion state (``t``, ``wp_index``, ``done`` are updated).
        pos: ``(S, 3) float64`` positions, updated.
        vel: ``(S, 3) float64`` velocities, updated (0 for offline slots).
        heading: ``(S,) float64`` yaw (rad), updated from the horizontal velocity.
        max_speed: ``(S,) float64`` speed limits (m/s).
        max_accel: ``(S,) float64`` acceleration limits for velocity commands (m/s^2).
        online: ``(S,) bool``; offline slots do not move.
        dt: step (s, > 0).

    Raises:
        ValueError: on wrong shapes/dtypes or a non-positive ``dt``.
    """
    dt = _validate(ms, pos, vel, heading, max_speed, max_accel, online, dt)
    integrate_unchecked(ms, pos, vel, heading, max_speed, max_accel, online, dt)


def integrate_unchecked(
    ms: MotionState,
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    max_speed: np.ndarray,
    max_accel: np.ndarray,
    online: np.ndarray,
    dt: float,
    threads: RowThreads | None = None,
) -> None:
    """:func:`integrate` without the checks, for a caller that already validated these very arrays and ``dt``;
    ``threads`` splits the slots into row ranges (the result does not depend on it)."""
    (threads or _ONE).run(
        lambda lo, hi, _: _integrate_kernel(
            lo,
            hi,
            ms.kind,
            ms.params,
            ms.t,
            ms.waypoints,
            ms.n_waypoints,
            ms.wp_index,
            ms.done,
            ms.loop,
            pos,
            vel,
            heading,
            max_speed,
            max_accel,
            online,
            dt,
        ),
        ms.kind.shape[0],
    )


@njit(cache=True)
def _clip_box_kernel(pos, lo, hi):  # type: ignore[no-untyped-def]
    # max then min with NaN kept, as np.clip evaluates it (signed zeros included)
    for s in range(pos.shape[0]):
        for a in range(3):
            x = pos[s, a]
            m = x if (x >= lo[a] or x != x) else lo[a]
            pos[s, a] = m if (m <= hi[a] or m != m) else hi[a]


def clip_box(pos: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Clip every position into the box ``[lo, hi]`` per axis, in place (one kernel).

    Args:
        pos: ``(S, 3)`` float64 positions, updated.
        lo: ``(3,)`` float64 lower corner.
        hi: ``(3,)`` float64 upper corner.
    """
    _clip_box_kernel(pos, lo, hi)
