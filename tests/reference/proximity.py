"""Brute-force numpy reference of the proximity sensor (no grid; used by the tests and ``bench_lidar``).

It follows the conventions of :mod:`agentsim_env.sensors.proximity` exactly (ring-major rays, normalised
distances, ``0`` from inside a shape, ties to the lower ``(hit_kind, hit_id)``) and applies the same
parallel-direction threshold as the kernels, so both take the same branch.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.sensors.proximity import ProximityConfig, ScanResult, _check_inputs
from agentsim_env.sensors.raycast import _BOX, _CYL, _EPS, _SPH, HIT_AGENT, HIT_GROUND, HIT_NONE, HIT_OBJECT


def _ref_slab(p: np.ndarray, d: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    par = np.abs(d) < _EPS
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t1, t2 = (-h - p) * inv, (h - p) * inv
    lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
    inside = np.abs(p) <= h
    lo = np.where(par, np.where(inside, -np.inf, np.inf), lo)
    hi = np.where(par, np.where(inside, np.inf, -np.inf), hi)
    return lo, hi


def _ref_t(shape: int, p: np.ndarray, d: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Ray-shape distances, broadcast: ``p`` = origin - centre, ``d`` directions, ``h`` half extents."""
    p, d, h = np.broadcast_arrays(p, d, h)
    if shape == _SPH:
        b = (p * d).sum(-1)
        disc = b * b - ((p * p).sum(-1) - h[..., 0] ** 2)
        sq = np.sqrt(np.maximum(disc, 0.0))
        return np.where((disc >= 0.0) & (-b + sq >= 0.0), np.maximum(-b - sq, 0.0), np.inf)
    if shape == _BOX:
        lo, hi = _ref_slab(p[..., 0], d[..., 0], h[..., 0])
        lo2, hi2 = _ref_slab(p[..., 1], d[..., 1], h[..., 1])
        lo, hi = np.maximum(lo, lo2), np.minimum(hi, hi2)
    else:
        a = d[..., 0] ** 2 + d[..., 1] ** 2
        b = p[..., 0] * d[..., 0] + p[..., 1] * d[..., 1]
        c = p[..., 0] ** 2 + p[..., 1] ** 2 - h[..., 0] ** 2
        disc = b * b - a * c
        sq = np.sqrt(np.maximum(disc, 0.0))
        vert = a < _EPS * _EPS
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / a
            lo = np.where(vert, np.where(c > 0, np.inf, -np.inf), np.where(disc < 0, np.inf, (-b - sq) * inv))
            hi = np.where(vert, np.where(c > 0, -np.inf, np.inf), np.where(disc < 0, -np.inf, (-b + sq) * inv))
    lo3, hi3 = _ref_slab(p[..., 2], d[..., 2], h[..., 2])
    lo, hi = np.maximum(lo, lo3), np.minimum(hi, hi3)
    return np.where((lo <= hi) & (hi >= 0.0), np.maximum(lo, 0.0), np.inf)


def scan_reference(
    config: ProximityConfig,
    pos: np.ndarray,
    heading: np.ndarray,
    sensor_range: np.ndarray,
    radius: np.ndarray,
    online: np.ndarray,
    world: np.ndarray,
    kind: np.ndarray,
    centre: np.ndarray,
    half: np.ndarray,
    obj_world: np.ndarray,
    ground: bool,
    second: np.ndarray | None = None,
) -> ScanResult:
    """Brute-force numpy reference of :meth:`ProximitySensor.scan` (no grid; for tests only).

    Args:
        config: Ray layout and detection flags.
        pos, heading, sensor_range, radius, online, world: As for ``scan``.
        kind, centre, half, obj_world: Scene object arrays, as for ``scan``.
        ground: Whether the plane ``z = 0`` is solid.
        second: Optional ``(S, K)`` float array filled with the normalised distance of the second-nearest
            candidate (``inf`` when none), so tests can tell near-ties apart.

    Returns:
        A fresh :class:`ScanResult`.
    """
    arrays, _ = _check_inputs(pos, heading, sensor_range, radius, online, world, kind, centre, half, obj_world)
    pos, heading, srange, radius, online, world, kind, centre, half, obj_world = arrays
    dirs = config.ray_directions()
    res = ScanResult.empty(pos.shape[0], config.n_rays)
    if second is not None:
        second[...] = np.inf
    bound3 = np.select(
        [kind == _BOX, kind == _CYL],
        [np.linalg.norm(half, axis=1), np.hypot(half[:, 0], half[:, 2])],
        half[:, 0],
    )
    for i in np.flatnonzero(online):
        c, s = np.cos(heading[i]), np.sin(heading[i])
        wd = np.column_stack([c * dirs[:, 0] - s * dirs[:, 1], s * dirs[:, 0] + c * dirs[:, 1], dirs[:, 2]])
        cols, kinds, ids = [], [], []
        if config.detect_agents:
            js = np.flatnonzero(online & (world == world[i]))
            js = js[js != i]
            js = js[np.linalg.norm(pos[js] - pos[i], axis=1) - radius[js] <= srange[i]]
            rr = np.repeat(radius[js, None], 3, axis=1)
            cols.append(_ref_t(_SPH, (pos[i] - pos[js])[None], wd[:, None], rr[None]))
            kinds.append(np.full(js.size, HIT_AGENT))
            ids.append(js)
        if config.detect_objects:
            os_ = np.flatnonzero(obj_world == world[i])
            os_ = os_[np.linalg.norm(centre[os_] - pos[i], axis=1) - bound3[os_] <= srange[i]]
            t = np.full((dirs.shape[0], os_.size), np.inf)
            for sh in (_BOX, _CYL, _SPH):
                m = kind[os_] == sh
                t[:, m] = _ref_t(sh, (pos[i] - centre[os_[m]])[None], wd[:, None], half[os_[m]][None])
            cols.append(t)
            kinds.append(np.full(os_.size, HIT_OBJECT))
            ids.append(os_)
        if config.detect_ground and ground:
            with np.errstate(divide="ignore"):
                tg = np.where(wd[:, 2] < -_EPS, pos[i, 2] / -wd[:, 2], np.inf)
            cols.append((np.zeros_like(tg) if pos[i, 2] < 0.0 else tg)[:, None])
            kinds.append(np.array([HIT_GROUND]))
            ids.append(np.array([-1]))
        if not cols:
            continue
        t_all = np.concatenate(cols, axis=1)
        if t_all.shape[1] == 0:
            continue
        kind_all, id_all = np.concatenate(kinds), np.concatenate(ids)
        best = np.argmin(t_all, axis=1)  # first minimum: candidates are ordered by (kind, id)
        tb = t_all[np.arange(t_all.shape[0]), best]
        hit = tb <= srange[i]
        res.distance[i] = np.where(hit, tb / srange[i], 1.0)
        res.hit_kind[i] = np.where(hit, kind_all[best], HIT_NONE)
        res.hit_id[i] = np.where(hit, id_all[best], -1)
        if second is not None and t_all.shape[1] > 1:
            second[i] = np.partition(t_all, 1, axis=1)[:, 1] / srange[i]
    return res
