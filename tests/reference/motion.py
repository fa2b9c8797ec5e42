"""Plain numpy statements of the motion kernels of :mod:`agentsim_env.motion.integrate` (``integrate``,
``clip_box``); the tests check the kernels against them."""

from __future__ import annotations

import numpy as np

from agentsim_env.motion.integrate import HEADING_EPS, T_EPS, _landing_time, _validate
from agentsim_env.motion.state import CIRCULAR, LINEAR, PARABOLIC, PATH, VELOCITY, MotionState


def clip_box_reference(pos: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Plain numpy statement of :func:`agentsim_env.motion.integrate.clip_box`."""
    for a in range(3):
        np.clip(pos[:, a], lo[a], hi[a], out=pos[:, a])


def integrate_reference(
    ms: MotionState,
    pos: np.ndarray,
    vel: np.ndarray,
    heading: np.ndarray,
    max_speed: np.ndarray,
    max_accel: np.ndarray,
    online: np.ndarray,
    dt: float,
) -> None:
    """Plain numpy reference of :func:`integrate` (same contract).

    Args:
        ms: motion state, updated.
        pos: positions, updated.
        vel: velocities, updated.
        heading: headings, updated.
        max_speed: speed limits.
        max_accel: acceleration limits.
        online: online mask.
        dt: step (s, > 0).
    """
    dt = _validate(ms, pos, vel, heading, max_speed, max_accel, online, dt)
    p = ms.params
    vel[~online] = 0.0
    ms.t[online] += dt
    t = ms.t
    new_vel = np.zeros_like(vel)

    def clip_norm(v: np.ndarray, vmax: np.ndarray) -> np.ndarray:
        n = np.linalg.norm(v, axis=1)
        f = np.where(n > vmax, vmax / np.where(n > 0, n, 1.0), 1.0)
        return v * f[:, None]

    m = online & (ms.kind == VELOCITY)
    if m.any():
        vmax, target = max_speed[m], clip_norm(p[m, 0:3], max_speed[m])
        dv = target - vel[m]
        dn = np.linalg.norm(dv, axis=1)
        amax = max_accel[m] * dt
        step = np.where((dn <= amax)[:, None], dv, dv * (amax / np.where(dn > 0, dn, 1.0))[:, None])
        v = clip_norm(vel[m] + step, vmax)
        v[dn <= amax] = target[dn <= amax]
        pos[m] += v * dt
        new_vel[m] = v

    m = online & (ms.kind == LINEAR)
    if m.any():
        v = clip_norm(p[m, 3:6], max_speed[m])
        fin = t[m] + T_EPS >= p[m, 6]
        te = np.where(fin, p[m, 6], t[m])
        pos[m] = p[m, 0:3] + v * te[:, None]
        new_vel[m] = np.where(fin[:, None], 0.0, v)
        ms.done[np.flatnonzero(m)[fin]] = True

    m = online & (ms.kind == CIRCULAR)
    if m.any():
        r, w = p[m, 2], p[m, 3]
        lim = max_speed[m] / np.where(r > 0, r, 1.0)
        w = np.where(r * np.abs(w) > max_speed[m], np.copysign(lim, w), w)
        ang = p[m, 5] + w * t[m]
        pos[m] = np.stack([p[m, 0] + r * np.cos(ang), p[m, 1] + r * np.sin(ang), p[m, 4]], axis=1)
        new_vel[m] = np.stack([-r * w * np.sin(ang), r * w * np.cos(ang), np.zeros_like(r)], axis=1)

    m = online & (ms.kind == PARABOLIC)
    if m.any():
        tm, g = t[m], p[m, 6]
        z = p[m, 2] + p[m, 5] * tm - 0.5 * g * tm * tm
        landed = z <= 0.0
        te = tm.copy()
        for j in np.flatnonzero(landed):  # rare event; scalar formula shared with the kernel
            te[j] = _landing_time(p[m, 2][j], p[m, 5][j], g[j], tm[j])
        pos[m] = np.stack([p[m, 0] + p[m, 3] * te, p[m, 1] + p[m, 4] * te, np.where(landed, 0.0, z)], axis=1)
        v = np.stack([p[m, 3], p[m, 4], p[m, 5] - g * tm], axis=1)
        new_vel[m] = np.where(landed[:, None], 0.0, v)
        ms.done[np.flatnonzero(m)[landed]] = True

    m = online & (ms.kind == PATH) & ~ms.done
    if m.any():
        idx = np.flatnonzero(m)
        target = ms.waypoints[idx, ms.wp_index[idx]]
        d = target - pos[idx]
        dist = np.linalg.norm(d, axis=1)
        spd = np.minimum(p[idx, 0], max_speed[idx])
        arrive = spd * dt >= dist
        v = d * (spd / np.where(dist > 0, dist, 1.0))[:, None]
        v[arrive] = d[arrive] / dt
        newp = pos[idx] + v * dt
        newp[arrive] = target[arrive]
        pos[idx] = newp
        new_vel[idx] = v
        rest = np.where(arrive, 0.0, dist - spd * dt)
        adv = idx[rest <= p[idx, 1]]
        nxt = ms.wp_index[adv] + 1
        end = nxt >= ms.n_waypoints[adv]
        wrap = end & ms.loop[adv]
        stop = end & ~ms.loop[adv]
        nxt[wrap] = 0
        nxt[stop] = ms.n_waypoints[adv][stop] - 1
        ms.wp_index[adv] = nxt
        ms.done[adv[stop]] = True

    # HOLD and finished PATH keep new_vel = 0.
    vel[online] = new_vel[online]
    hs = np.hypot(vel[:, 0], vel[:, 1])
    turn = online & (hs > HEADING_EPS)
    heading[turn] = np.arctan2(vel[turn, 1], vel[turn, 0])
