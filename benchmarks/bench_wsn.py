"""Time ``evaluate_deployment`` (all WSN metrics, lifetime included) for growing sensor counts.

Three hot zones (gauss with a 10 % floor, 1/r power law, linear cone; radii 100 / 80 / 120 m), sensors split
evenly, landing scatter 2 m, defaults of ``WsnConfig`` (r_s = 10 m, r_c = 25 m, 1 m coverage lattice, one sink
per zone centroid). Prints the median of several runs of the whole evaluation and of its parts. The coverage
lattice is cached across calls with the same zones (as in a batch evaluation); its one-off build is shown
separately.

Usage: ``python benchmarks/bench_wsn.py [--repeats 5] [--sizes 500 1000 2000 5000]``
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one BLAS thread: 2 threads on a shared 2-core box is noisy
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from agentsim_env.uav.wsn import (  # noqa: E402
    RadialProfile,
    WsnConfig,
    ZoneGrid,
    connectivity,
    cover_pairs,
    evaluate_deployment,
    fidelity_per_zone,
    simulate_lifetime,
    zone_grid,
)
from agentsim_env.uav.wsn.coverage import _cached_grid  # noqa: E402

CENTRES = np.array([[0.0, 0.0], [250.0, 0.0], [120.0, 200.0]])
RADII = np.array([100.0, 80.0, 120.0])
PROFILES = [
    RadialProfile("gauss", 100.0, floor=0.1),
    RadialProfile("power", 80.0, alpha=1.0),
    RadialProfile("linear", 120.0),
]


def deployment(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Landing points, intended zones and intended points for ``n`` sensors."""
    per = np.full(3, n // 3)
    per[: n - per.sum()] += 1
    targets = np.vstack([CENTRES[k] + PROFILES[k].sample(int(per[k]), rng) for k in range(3)])
    zone = np.repeat(np.arange(3), per)
    return targets + rng.normal(0.0, 2.0, targets.shape), zone, targets


def median_time(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in milliseconds."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def bench_row(n: int, cfg: WsnConfig, grid: ZoneGrid, rng: np.random.Generator, repeats: int) -> tuple:
    """Timings (ms) of the whole evaluation and of its parts for one deployment of ``n`` sensors."""
    land, zone, targets = deployment(n, rng)
    total = median_time(lambda: evaluate_deployment(land, zone, CENTRES, RADII, PROFILES, cfg, targets), repeats)
    cov = median_time(lambda: cover_pairs(grid, land, cfg.r_s), repeats)
    con = median_time(lambda: connectivity(land, cfg.r_c, CENTRES, cfg.fiedler_max_n), repeats)
    life = median_time(lambda: simulate_lifetime(land, CENTRES, cfg.r_c, cfg.radio), repeats)
    fid = median_time(lambda: fidelity_per_zone(land, zone, CENTRES, RADII, PROFILES, targets, cfg.knn_k), repeats)
    res = simulate_lifetime(land, CENTRES, cfg.r_c, cfg.radio)
    return (
        n,
        f"{total:.1f}",
        f"{cov:.1f}",
        f"{con:.1f}",
        f"{life:.1f}",
        f"{fid:.1f}",
        res.n_events,
        res.n_reroutes,
    )


def main() -> None:
    """Print the timing table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 1000, 2000, 5000])
    args = parser.parse_args()
    cfg = WsnConfig()
    rng = np.random.default_rng(0)

    warm = deployment(60, rng)
    # First call compiles (or loads) the numba kernels.
    evaluate_deployment(warm[0], warm[1], CENTRES, RADII, PROFILES, cfg, warm[2])
    _cached_grid.cache_clear()
    t0 = time.perf_counter()
    grid = zone_grid(CENTRES, RADII, cfg.coverage_resolution)
    build_ms = 1e3 * (time.perf_counter() - t0)
    points = grid.points.shape[0]
    print(f"coverage lattice: {points} points, one-off build {build_ms:.1f} ms (cached afterwards)")
    print(f"median of {args.repeats} runs, ms\n")
    header = ("sensors", "evaluate", "coverage", "connect.", "lifetime", "fidelity", "events", "reroutes")
    print("| " + " | ".join(header) + " |")
    print("|" + "|".join("---:" for _ in header) + "|")
    for n in args.sizes:
        print("| " + " | ".join(str(x) for x in bench_row(n, cfg, grid, rng, args.repeats)) + " |")


if __name__ == "__main__":
    main()
