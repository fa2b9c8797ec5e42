"""Proximity-sensor benchmark: numba grid kernel vs numpy brute force vs cKDTree candidates + numpy.

Scenes keep a constant density (1 agent per 100 m^2 at 1..20 m altitude, 1 obstacle per 400 m^2, range
10 m, radius 0.5 m), so the work per agent is constant and a good kernel scales linearly. Systems are
timed interleaved (one call each per round) on one thread; the table reports medians and ratios to the
numba kernel. The grid build (shared with collisions and comms each step) is timed separately.

Run: ``.venv/bin/python benchmarks/bench_lidar.py [--sizes 100 1000 10000] [--rounds 15] [--ref-max 1000]``
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # before numba is imported: one core, as documented

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from agentsim_env.core.scene import Scene  # noqa: E402
from agentsim_env.core.spatial import GridSpec, build_grid, build_object_grid  # noqa: E402
from agentsim_env.sensors.proximity import (  # noqa: E402
    _BOX,
    _CYL,
    _EPS,
    _SPH,
    HIT_AGENT,
    HIT_GROUND,
    HIT_NONE,
    HIT_OBJECT,
    ProximityConfig,
    ProximitySensor,
    ScanResult,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the tests' references
from tests.reference.proximity import _ref_t, scan_reference  # noqa: E402

RANGE, RADIUS, CELL = 10.0, 0.5, 5.0


def make_scene(n: int, seed: int = 0) -> tuple:
    """Agents and obstacles at constant density on a square map; returns (arrays..., scene, bounds)."""
    g = np.random.default_rng(seed)
    side = float(np.sqrt(n * 100.0))
    pos = np.column_stack([g.uniform(0, side, (n, 2)), g.uniform(1.0, 20.0, n)])
    heading = g.uniform(-np.pi, np.pi, n)
    srange = np.full(n, RANGE)
    radius = np.full(n, RADIUS)
    online = np.ones(n, dtype=bool)
    world = np.zeros(n, dtype=np.int32)
    n_obj = max(1, n // 4)
    kind = g.choice([0, 1, 2], n_obj, p=[0.45, 0.45, 0.1]).astype(np.int8)
    half = np.column_stack([g.uniform(0.5, 3.0, (n_obj, 2)), g.uniform(2.5, 15.0, n_obj)])
    centre = np.column_stack([g.uniform(0, side, (n_obj, 2)), half[:, 2]])  # standing on the ground
    sph = kind == 2
    centre[sph, 2] = g.uniform(2.0, 20.0, sph.sum())  # floating spheres (balloons)
    scene = Scene(ground=True)
    scene.add(kind, centre, half, 0)
    return pos, heading, srange, radius, online, world, scene, (0.0, side, 0.0, side)


def scan_kdtree(cfg: ProximityConfig, pos, heading, srange, radius, online, world, scene) -> ScanResult:  # type: ignore[no-untyped-def]
    """Candidates from scipy cKDTree pair queries, then every (candidate, ray) test vectorised in numpy."""
    s, k = pos.shape[0], cfg.n_rays
    on = np.flatnonzero(online)
    dirs = cfg.ray_directions()
    c, sn = np.cos(heading[on])[:, None], np.sin(heading[on])[:, None]
    wd = np.stack(
        [
            c * dirs[:, 0] - sn * dirs[:, 1],
            sn * dirs[:, 0] + c * dirs[:, 1],
            np.broadcast_to(dirs[:, 2], c.shape[:1] + dirs[:, 2].shape),
        ],
        axis=-1,
    )
    sep = np.array([1e7, 0.0, 0.0])  # worlds far apart along x never pair up
    p_on = pos[on] + world[on, None] * sep
    rows_t, rows_o, rows_kind, rows_id = [], [], [], []
    if cfg.detect_agents and on.size > 1:
        pr = cKDTree(p_on).query_pairs(srange[on].max() + radius[on].max(), output_type="ndarray")
        a, b = np.concatenate([pr[:, 0], pr[:, 1]]), np.concatenate([pr[:, 1], pr[:, 0]])
        keep = np.linalg.norm(p_on[a] - p_on[b], axis=1) - radius[on[b]] <= srange[on[a]]
        a, b = a[keep], b[keep]
        rr = np.repeat(radius[on[b], None], 3, axis=1)[:, None]
        rows_t.append(_ref_t(_SPH, (p_on[a] - p_on[b])[:, None], wd[a], rr))
        rows_o += [a]
        rows_kind += [np.full(a.size, HIT_AGENT)]
        rows_id += [on[b]]
    if cfg.detect_objects and scene.n_objects:
        half = scene.half
        bound = [np.linalg.norm(half, axis=1), np.hypot(half[:, 0], half[:, 2])]
        b3 = np.select([scene.kind == _BOX, scene.kind == _CYL], bound, half[:, 0])
        p_obj = scene.centre + scene.world[:, None] * sep
        sdm = cKDTree(p_on).sparse_distance_matrix(cKDTree(p_obj), srange[on].max() + b3.max(), output_type="ndarray")
        a, o = sdm["i"], sdm["j"]
        keep = sdm["v"] - b3[o] <= srange[on[a]]
        a, o = a[keep], o[keep]
        t = np.full((a.size, k), np.inf)
        for sh in (_BOX, _CYL, _SPH):
            m = scene.kind[o] == sh
            t[m] = _ref_t(sh, (p_on[a[m]] - p_obj[o[m]])[:, None], wd[a[m]], half[o[m]][:, None])
        rows_t.append(t)
        rows_o += [a]
        rows_kind += [np.full(a.size, HIT_OBJECT)]
        rows_id += [o]
    if cfg.detect_ground and scene.ground:
        with np.errstate(divide="ignore"):
            tg = np.where(wd[..., 2] < -_EPS, pos[on, 2, None] / -wd[..., 2], np.inf)
        rows_t.append(np.where(pos[on, 2, None] < 0.0, 0.0, tg))
        rows_o += [np.arange(on.size)]
        rows_kind += [np.full(on.size, HIT_GROUND)]
        rows_id += [np.full(on.size, -1)]
    res = ScanResult.empty(s, k)
    if not rows_t:
        return res
    t, owner = np.concatenate(rows_t), np.concatenate(rows_o)
    kinds, ids = np.concatenate(rows_kind), np.concatenate(rows_id)
    order = np.lexsort((ids, kinds, owner))  # group rows by owner, (kind, id) order inside for ties
    t, owner, kinds, ids = t[order], owner[order], kinds[order], ids[order]
    starts = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
    best = np.minimum.reduceat(t, starts, axis=0)
    first = np.where(
        t == best[np.cumsum(np.r_[False, owner[1:] != owner[:-1]])],
        np.arange(t.shape[0])[:, None],
        t.shape[0],
    )
    arg = np.minimum.reduceat(first, starts, axis=0)
    slots = on[owner[starts]]
    hit = best <= srange[slots, None]
    res.distance[slots] = np.where(hit, best / srange[slots, None], 1.0)
    res.hit_kind[slots] = np.where(hit, kinds[np.minimum(arg, t.shape[0] - 1)], HIT_NONE)
    res.hit_id[slots] = np.where(hit, ids[np.minimum(arg, t.shape[0] - 1)], -1)
    return res


def make_systems(cfg: ProximityConfig, sensor: ProximitySensor, n: int, with_reference: bool) -> dict:
    """Zero-argument callables for every system at size ``n`` (one shared scene)."""
    pos, heading, srange, radius, online, world, scene, bounds = make_scene(n)
    spec = GridSpec.for_bounds(bounds, CELL, 1)
    og = build_object_grid(spec, scene.centre, scene.footprint_radius(), scene.world)
    ag = build_grid(spec, pos, world, online)
    agents = (pos, heading, srange, radius, online, world)
    objects = (scene.kind, scene.centre, scene.half, scene.world)
    systems = {
        "numba grid (scan)": lambda: sensor.scan(*agents, ag, *objects, og, True),
        "grid build (per step)": lambda: build_grid(spec, pos, world, online),
        "cKDTree + numpy": lambda: scan_kdtree(cfg, *agents, scene),
    }
    if with_reference:
        systems["numpy brute force"] = lambda: scan_reference(cfg, *agents, *objects, True)
    return systems


def main() -> None:
    """Time the systems at each size and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--rounds", type=int, default=21)
    ap.add_argument("--ref-max", type=int, default=1000, help="largest N the numpy brute force runs at")
    ap.add_argument("--elevations", type=float, nargs="+", default=[0.0])
    args = ap.parse_args()
    cfg = ProximityConfig(n_azimuth=32, elevations_deg=tuple(args.elevations))
    print(
        f"rays/agent K={cfg.n_rays}  range={RANGE} m  grid cell={CELL} m  NUMBA_NUM_THREADS="
        f"{os.environ['NUMBA_NUM_THREADS']}  load avg at start {os.getloadavg()[0]:.2f}"
    )
    head = ("N", "system", "cpu ms", "wall ms", "us/agent", "x numba", "max|dd|", "kind ok")
    print("{:>7} {:<22} {:>9} {:>9} {:>9} {:>8} {:>8} {:>8}".format(*head))
    sensor = ProximitySensor(cfg)
    for n in args.sizes:
        systems = make_systems(cfg, sensor, n, n <= args.ref_max)
        results = {name: fn() for name, fn in systems.items()}  # warm up (numba compile, caches)
        r0 = results["numba grid (scan)"]
        base = ScanResult(r0.distance.copy(), r0.hit_kind.copy(), r0.hit_id.copy())
        # CPU time of this process is the headline (robust on a shared machine); wall time is shown too.
        cpu: dict[str, list[float]] = {name: [] for name in systems}
        wall: dict[str, list[float]] = {name: [] for name in systems}
        for _ in range(args.rounds):
            for name, fn in systems.items():  # interleaved, so load drifts hit every system alike
                if name == "numpy brute force" and len(cpu[name]) >= 3 and n > 100:
                    continue  # seconds per call: three samples are enough
                t0, c0 = time.perf_counter(), time.process_time()
                fn()
                cpu[name].append(time.process_time() - c0)
                wall[name].append(time.perf_counter() - t0)
        t_numba = float(np.median(cpu["numba grid (scan)"]))
        for name, ts in cpu.items():
            med, med_wall = float(np.median(ts)), float(np.median(wall[name]))
            r = results[name]
            dd = ok = ""
            if isinstance(r, ScanResult) and name != "numba grid (scan)":
                dd = f"{np.abs(r.distance - base.distance).max():.0e}"
                ok = f"{np.mean(r.hit_kind == base.hit_kind) * 100:.2f}%"
            print(
                f"{n:>7} {name:<22} {med * 1e3:>9.3f} {med_wall * 1e3:>9.3f} {med / n * 1e6:>9.3f} "
                f"{med / t_numba:>8.1f} {dd:>8} {ok:>8}"
            )
    print(f"load avg at end {os.getloadavg()[0]:.2f} (a shared machine inflates every system alike)")


if __name__ == "__main__":
    main()
