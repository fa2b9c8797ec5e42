"""Numba kernel that advances falling objects (the hot path of ``PayloadSet.step``).

It runs the same scheme as the numpy functions in ``ballistic`` (classical RK4 sub-steps, then the
root of the cubic Hermite interpolant of the crossing sub-step), one object at a time with no
temporaries; those numpy functions are its reference in the differential tests.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["PROFILE_CODES", "fall_substeps"]

#: Wind height profile name -> kernel code.
PROFILE_CODES: dict[str, int] = {"log": 0, "power": 1, "uniform": 2}


@njit(cache=True)
def _profile(z: float, code: int, z0: float, z_ref: float, log_ref: float) -> float:
    """Height-profile factor ``u(z) / u(z_ref)`` as in ``WindConfig`` (``log_ref = ln(z_ref / z0)``)."""
    if code == 2:
        return 1.0
    if code == 1:
        return (max(z, 0.0) / z_ref) ** (1.0 / 7.0)
    return math.log(max(z, z0) / z0) / log_ref


@njit(cache=True)
def _acc(
    z: float,
    vx: float,
    vy: float,
    vz: float,
    mx: float,
    my: float,
    gx: float,
    gy: float,
    k: float,
    g: float,
    code: int,
    z0: float,
    z_ref: float,
    log_ref: float,
) -> tuple[float, float, float]:
    """Gravity plus quadratic drag on the velocity relative to the wind ``mean * profile(z) + gust``."""
    f = _profile(z, code, z0, z_ref, log_ref)
    rx = vx - (mx * f + gx)
    ry = vy - (my * f + gy)
    s = k * math.sqrt(rx * rx + ry * ry + vz * vz)
    return -s * rx, -s * ry, -s * vz - g


@njit(cache=True)
def _herm(y0: float, d0: float, y1: float, d1: float, s: float) -> float:
    """Cubic Hermite interpolant on ``s in [0, 1]``."""
    s2 = s * s
    s3 = s2 * s
    return (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * d0 + (3 * s2 - 2 * s3) * y1 + (s3 - s2) * d1


@njit(cache=True)
def _herm_root(z0: float, d0: float, z1: float, d1: float) -> float:
    """Root in ``[0, 1]`` of the Hermite cubic with ``z0 > 0 >= z1``: Newton, bisection-safeguarded."""
    lo, hi = 0.0, 1.0
    s = min(max(z0 / max(z0 - z1, 1e-300), 0.0), 1.0)
    for _ in range(30):
        f = _herm(z0, d0, z1, d1, s)
        if f > 0.0:
            lo = s
        else:
            hi = s
        s2 = s * s
        df = (6 * s2 - 6 * s) * (z0 - z1) + (3 * s2 - 4 * s + 1) * d0 + (3 * s2 - 2 * s) * d1
        s_new = s - f / df if df != 0.0 else -1.0
        if not (lo < s_new < hi):
            s_new = 0.5 * (lo + hi)
        if abs(s_new - s) <= 1e-15:
            return s_new
        s = s_new
    return s


@njit(cache=True)
def fall_substeps(
    pos: np.ndarray,
    vel: np.ndarray,
    fall_time: np.ndarray,
    mean_xy: np.ndarray,
    gust_xy: np.ndarray,
    k: float,
    g: float,
    h: float,
    m: int,
    code: int,
    z0: float,
    z_ref: float,
    landed: np.ndarray,
    land_xy: np.ndarray,
) -> None:
    """Advance ``n`` objects by ``m`` RK4 sub-steps of ``h`` seconds, in place.

    An object that starts at or below ``z = 0`` lands where it is; one that crosses during a sub-step
    lands at the Hermite root, gets ``pos = (x, y, 0)``, ``vel = 0`` and its crossing time in
    ``fall_time``, and is not advanced further.

    Args:
        pos: ``(n, 3)`` positions (updated).
        vel: ``(n, 3)`` velocities (updated).
        fall_time: ``(n,)`` time since release (updated).
        mean_xy: ``(n, 2)`` mean wind at ``z_ref`` per object.
        gust_xy: ``(n, 2)`` gusts per object, held over the call.
        k: Drag constant per unit mass.
        g: Gravitational acceleration.
        h: Sub-step in seconds.
        m: Number of sub-steps.
        code: Wind profile code (``PROFILE_CODES``).
        z0: Roughness length.
        z_ref: Reference height.
        landed: ``(n,)`` bool output, True where the object landed in this call.
        land_xy: ``(n, 2)`` output landing points (written where ``landed``).
    """
    n = pos.shape[0]
    log_ref = math.log(z_ref / z0)  # hoisted: the log law's denominator, the same for every call
    for i in range(n):
        landed[i] = pos[i, 2] <= 0.0
        if landed[i]:
            land_xy[i, 0], land_xy[i, 1] = pos[i, 0], pos[i, 1]
    # Sub-steps outside, objects inside: consecutive objects are independent, so the CPU overlaps
    # their dependency chains (one object's RK4 stages are strictly serial and latency-bound).
    for _ in range(m):
        for i in range(n):
            if landed[i]:
                continue
            x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
            vx, vy, vz = vel[i, 0], vel[i, 1], vel[i, 2]
            mx, my, gx, gy = mean_xy[i, 0], mean_xy[i, 1], gust_xy[i, 0], gust_xy[i, 1]
            a1x, a1y, a1z = _acc(z, vx, vy, vz, mx, my, gx, gy, k, g, code, z0, z_ref, log_ref)
            v2x, v2y, v2z = vx + 0.5 * h * a1x, vy + 0.5 * h * a1y, vz + 0.5 * h * a1z
            a2x, a2y, a2z = _acc(z + 0.5 * h * vz, v2x, v2y, v2z, mx, my, gx, gy, k, g, code, z0, z_ref, log_ref)
            v3x, v3y, v3z = vx + 0.5 * h * a2x, vy + 0.5 * h * a2y, vz + 0.5 * h * a2z
            a3x, a3y, a3z = _acc(z + 0.5 * h * v2z, v3x, v3y, v3z, mx, my, gx, gy, k, g, code, z0, z_ref, log_ref)
            v4x, v4y, v4z = vx + h * a3x, vy + h * a3y, vz + h * a3z
            a4x, a4y, a4z = _acc(z + h * v3z, v4x, v4y, v4z, mx, my, gx, gy, k, g, code, z0, z_ref, log_ref)
            c = h / 6.0
            x1 = x + c * (vx + 2.0 * v2x + 2.0 * v3x + v4x)
            y1 = y + c * (vy + 2.0 * v2y + 2.0 * v3y + v4y)
            z1 = z + c * (vz + 2.0 * v2z + 2.0 * v3z + v4z)
            wx = vx + c * (a1x + 2.0 * a2x + 2.0 * a3x + a4x)
            wy = vy + c * (a1y + 2.0 * a2y + 2.0 * a3y + a4y)
            wz = vz + c * (a1z + 2.0 * a2z + 2.0 * a3z + a4z)
            if z1 <= 0.0:
                s = _herm_root(z, vz * h, z1, wz * h)
                x1 = _herm(x, vx * h, x1, wx * h, s)
                y1 = _herm(y, vy * h, y1, wy * h, s)
                z1, wx, wy, wz = 0.0, 0.0, 0.0, 0.0
                fall_time[i] += s * h
                landed[i] = True
                land_xy[i, 0], land_xy[i, 1] = x1, y1
            else:
                fall_time[i] += h
            pos[i, 0], pos[i, 1], pos[i, 2] = x1, y1, z1
            vel[i, 0], vel[i, 1], vel[i, 2] = wx, wy, wz
