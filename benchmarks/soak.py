"""Soak test: does the resident memory (RSS) of a long run stay flat once warmed up?

Not part of ``make bench`` (``run_all.py`` runs ``bench_*.py`` only) and not run in CI: the full run takes about
ten minutes on one core while the step time stays flat. Two phases, one process:

1. **Steps.** ``--steps`` (1,000,000) steps of ``navigation`` with comms on (default comms plus heartbeats every
   5 steps) and ``--agents`` (100) agents, through the array API (``BatchedEnv`` with one world; worlds reset
   inside ``step`` when every agent is done, so the run spans thousands of episodes). Actions are uniform random
   in [-1, 1], the ``comm`` part included (every channel is used). RSS is sampled every ``--sample-every``
   steps (default: 200 samples over the run).
2. **Missions.** ``--missions`` (200) ``uav_release`` missions on ``--zones`` (``tiny``) flown by the shipped
   default baseline (``agentsim_env.policies.registry.make_policy``, strategy B5_cvt) through
   ``agentsim_env.uav.evaluation.mission.fly_mission``, seeds 0, 1, 2, ...; one env and one policy serve every
   mission (each mission resets both), or a fresh pair per mission with ``--fresh-env``. RSS is sampled after
   each mission.

Per phase: RSS after warm-up (the sample at ``--warmup`` = 10 % of the run), final RSS, the largest sample,
the growth from warm-up to the end in percent, the least-squares slope of the samples after warm-up, and PASS
when the growth is at most ``--max-growth`` (5 %). RSS comes from psutil when installed, else from
``/proc/self/statm``. The exit status is 1 when a phase fails.

Run: ``.venv/bin/python benchmarks/soak.py [--quick] [--steps N] [--missions M] [--plot rss.png]``
(``--quick``: 20,000 steps and 10 missions, about half a minute).
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402, I001  (before numpy: it pins the thread pools)

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

STEPS, MISSIONS = 1_000_000, 200
QUICK_STEPS, QUICK_MISSIONS = 20_000, 10
COMMS = {"heartbeat_period": 5}
"""``navigation``'s comms: the defaults of ``CommsConfig`` plus heartbeats every 5 steps."""
HEADERS = [
    "phase",
    "work",
    "samples",
    "RSS warm-up MB",
    "RSS final MB",
    "RSS max MB",
    "growth %",
    "slope MB/10%",
    "wall s",
    "result",
]


# -------------------------------------------------------------------------------------------------- RSS
def _rss_reader() -> tuple[str, Callable[[], int]]:
    """The RSS source (its name, and a function returning the process's resident bytes now)."""
    try:
        import psutil

        proc = psutil.Process()
        return "psutil", lambda: int(proc.memory_info().rss)
    except ImportError:
        pass
    statm = Path("/proc/self/statm")
    if statm.exists():
        page = os.sysconf("SC_PAGE_SIZE")
        return "/proc/self/statm", lambda: int(statm.read_text().split()[1]) * page
    import resource  # neither: the peak RSS is the best there is (kilobytes on Linux, bytes on macOS)

    scale = 1 if sys.platform == "darwin" else 1024
    return "getrusage peak", lambda: int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * scale


RSS_SOURCE, rss_bytes = _rss_reader()


@dataclass
class Trace:
    """RSS samples of one phase: ``at`` (steps or missions done) and ``rss`` (bytes)."""

    phase: str
    unit: str
    total: int
    warmup: float
    at: list[int] = field(default_factory=list)
    rss: list[int] = field(default_factory=list)
    wall_s: float = 0.0

    def sample(self, done: int) -> None:
        self.at.append(done)
        self.rss.append(rss_bytes())

    def summary(self, max_growth: float) -> dict[str, float | str | int]:
        """Warm-up, final and max RSS (MB), growth after warm-up (%), slope after warm-up (MB per 10 % of the
        run) and PASS / FAIL."""
        at, rss = np.asarray(self.at, dtype=float), np.asarray(self.rss, dtype=float) / 2**20
        w = int(np.searchsorted(at, self.warmup * self.total))  # first sample at or after the warm-up point
        w = min(w, len(at) - 1)
        warm, final = rss[w], rss[-1]
        growth = (final - warm) / warm * 100.0
        post_at, post = at[w:], rss[w:]
        slope = float(np.polyfit(post_at, post, 1)[0]) * 0.1 * self.total if len(post) >= 3 else 0.0
        return {
            "warm": warm,
            "final": final,
            "max": float(rss.max()),
            "growth": growth,
            "slope": slope,
            "samples": len(rss),
            "result": "PASS" if growth <= max_growth else "FAIL",
        }


# ----------------------------------------------------------------------------------------------- phases
def run_steps(steps: int, agents: int, every: int, seed: int, warmup: float, progress: bool) -> Trace:
    """Phase 1: ``steps`` random steps of ``navigation`` with comms, array API, one world."""
    from agentsim_env.env.vector import BatchedEnv

    env = BatchedEnv("navigation", 1, n_agents=agents, comms=dict(COMMS))
    rng = np.random.default_rng(seed)
    trace = Trace("navigation + comms", "steps", steps, warmup)
    t0 = time.perf_counter()
    env.reset(seed=seed)
    trace.sample(0)
    shape = (1, agents, env.act_dim)
    bar = tqdm(total=steps, desc="steps", unit="step", unit_scale=True, mininterval=2.0, disable=not progress)
    done = 0
    while done < steps:
        n = min(every, steps - done)
        for _ in range(n):
            env.step(rng.uniform(-1.0, 1.0, shape))
        done += n
        bar.update(n)
        trace.sample(done)
    bar.close()
    trace.wall_s = time.perf_counter() - t0
    return trace


def run_missions(missions: int, zones: str, fresh: bool, warmup: float, progress: bool) -> Trace:
    """Phase 2: ``missions`` ``uav_release`` missions flown by the default baseline."""
    import agentsim_env
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.uav.evaluation.mission import fly_mission

    def build() -> tuple[object, object]:
        env = agentsim_env.make("uav_release", zones=zones)
        return env, make_policy("uav_release", env)

    trace = Trace("uav_release missions", "missions", missions, warmup)
    t0 = time.perf_counter()
    env, policy = build()
    trace.sample(0)
    incomplete = 0
    for m in tqdm(range(missions), desc="missions", unit="mission", mininterval=2.0, disable=not progress):
        if fresh and m:
            env.close()  # type: ignore[attr-defined]
            env, policy = build()
        incomplete += fly_mission(env, policy, seed=m)["completed"] < 1.0
        trace.sample(m + 1)
    env.close()  # type: ignore[attr-defined]
    trace.wall_s = time.perf_counter() - t0
    if incomplete:
        print(f"note: {incomplete} of {missions} missions hit max_steps before completing")
    return trace


# ------------------------------------------------------------------------------------------------ output
def table(traces: list[Trace], max_growth: float) -> str:
    rows = []
    for t in traces:
        s = t.summary(max_growth)
        rows.append(
            [
                t.phase,
                f"{t.total:,} {t.unit}",
                str(s["samples"]),
                common.fmt_num(float(s["warm"])),
                common.fmt_num(float(s["final"])),
                common.fmt_num(float(s["max"])),
                f"{float(s['growth']):+.2f}",
                f"{float(s['slope']):+.2f}",
                common.fmt_num(t.wall_s),
                str(s["result"]),
            ]
        )
    return common.markdown_table(HEADERS, rows)


def plot(traces: list[Trace], path: str) -> None:
    """RSS over the run, one panel per phase, the warm-up point marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(traces), figsize=(6 * len(traces), 4), squeeze=False)
    for ax, t in zip(axes[0], traces):
        ax.plot(t.at, np.asarray(t.rss) / 2**20, lw=1.2)
        ax.axvline(t.warmup * t.total, color="grey", ls="--", lw=1, label="end of warm-up")
        ax.set(title=t.phase, xlabel=t.unit, ylabel="RSS (MB)")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"plot: {path}")


def main(argv: list[str] | None = None) -> int:
    """Run the phases, print the machine line and the table; 0 when every phase passes, else 1."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_STEPS:,} steps and {QUICK_MISSIONS} missions")
    ap.add_argument("--steps", type=int, default=None, help=f"navigation steps (default {STEPS:,}; 0 skips)")
    ap.add_argument("--missions", type=int, default=None, help=f"uav_release missions (default {MISSIONS}; 0 skips)")
    ap.add_argument("--agents", type=int, default=100, help="navigation agents (default 100)")
    ap.add_argument("--sample-every", type=int, default=None, help="steps between RSS samples (default steps/200)")
    ap.add_argument("--zones", default="tiny", help="uav_release zones (default 'tiny')")
    ap.add_argument("--fresh-env", action="store_true", help="a new uav_release env and policy per mission")
    ap.add_argument("--warmup", type=float, default=0.1, help="warm-up fraction of each phase (default 0.1)")
    ap.add_argument("--max-growth", type=float, default=5.0, help="PASS threshold on RSS growth, %% (default 5)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--plot", metavar="PATH", default=None, help="write a PNG of RSS over time")
    ap.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = ap.parse_args(argv)
    steps = args.steps if args.steps is not None else (QUICK_STEPS if args.quick else STEPS)
    missions = args.missions if args.missions is not None else (QUICK_MISSIONS if args.quick else MISSIONS)
    if steps < 0 or missions < 0 or (steps == 0 and missions == 0):
        ap.error("give a positive --steps or --missions")
    if not 0.0 <= args.warmup < 1.0:
        ap.error("--warmup must be in [0, 1)")
    every = args.sample_every or max(1, steps // 200)
    progress = not args.no_progress
    print(f"machine: {common.machine_description()}")
    print(
        f"mode: {'quick' if args.quick else 'full'}; RSS from {RSS_SOURCE}; warm-up {args.warmup:.0%} of each "
        f"phase; PASS: growth after warm-up <= {args.max_growth:g} %"
    )
    traces = []
    if steps:
        print(
            f"phase 1: navigation, {args.agents} agents, comms {COMMS} (CommsConfig defaults otherwise), "
            f"BatchedEnv with 1 world (array API), random actions, RSS every {every:,} steps",
            flush=True,
        )
        traces.append(run_steps(steps, args.agents, every, args.seed, args.warmup, progress))
    gc.collect()
    if missions:
        print(
            f"phase 2: uav_release on zones={args.zones!r}, default baseline (B5_cvt) via fly_mission, "
            f"{'a fresh env per mission' if args.fresh_env else 'one env for every mission'}, "
            f"RSS after each mission",
            flush=True,
        )
        traces.append(run_missions(missions, args.zones, args.fresh_env, args.warmup, progress))
    print()
    print(table(traces, args.max_growth))
    if args.plot:
        plot(traces, args.plot)
    return int(any(t.summary(args.max_growth)["result"] == "FAIL" for t in traces))


if __name__ == "__main__":
    sys.exit(main())
