"""Step throughput of ``navigation``: agentsim (dict and array APIs) vs VMAS ``navigation`` vs mpe2 ``simple_spread``.

Every system runs random actions (a pool of 16 action sets drawn once, cycled) on one thread; at each size the
systems are timed interleaved (see ``common.measure_interleaved``) and the table reports medians of
agent-steps per CPU second. agentsim runs its defaults (kinematic motion, 32-ray 3D scan: 16 azimuths x 2
elevation rings, collisions on, no comms); every timed block starts from freshly reset episodes (untimed) and
lasts at most 300 steps, with ``max_steps`` beyond the block so that no time limit falls inside the timing.
Agents that collide are ended and only live agents are counted. VMAS runs ``navigation`` with 32 lidar rays
(2D) and a spawning area grown with N so that N agents and goals fit; mpe2 runs ``simple_spread`` with N
agents. APIs without batching (agentsim's dict API, mpe2) step B separate envs in a Python loop for B x N
rows. VMAS and mpe2 check every pair of entities every step, so their step time grows as N^2: a size whose
estimated step time (quadratic from the largest size measured) exceeds ``--max-step-s`` is skipped and the
estimate is shown. See ``benchmarks/README.md``.

Run: ``.venv/bin/python benchmarks/bench_step.py [--quick] [--sizes 1x4 1x64 ...] [--systems ...]``
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import argparse  # noqa: E402
import importlib.util  # noqa: E402
import itertools  # noqa: E402
import math  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass  # noqa: E402

import common  # noqa: E402  (pins thread pools before numpy / numba / torch load)
import numpy as np  # noqa: E402

SIZES = ("1x4", "1x64", "1x1000", "1x10000", "32x16", "512x4")
SYSTEMS = ("dict", "array", "vmas", "mpe2")
POOL = 16  # random action sets per case, cycled
PROBE_N = 64  # size at which a quadratic system is probed when nothing smaller was measured
LONG_EPISODE = 10**7  # max_steps / max_cycles: no time limit inside the timed window
# Every block starts from fresh episodes (reset untimed) and is at most this long, so agents that random
# actions steer into obstacles stay few (about 95 % of agents are still live after 300 steps).
MAX_BLOCK_STEPS = 300


@dataclass(frozen=True)
class Target:
    """A throughput target of one size: ``agent`` (agent-steps/s) or ``env`` (env-steps/s, B = 1)."""

    unit: str
    value: float

    def text(self) -> str:
        """Human form, e.g. '>= 100,000 agent-steps/s'."""
        return f">= {self.value:,.0f} {self.unit}-steps/s"

    def met(self, agent_rate: float, step_s: float) -> bool:
        """Whether a measurement meets the target."""
        return (agent_rate if self.unit == "agent" else 1.0 / step_s) >= self.value


TARGETS = {
    (1, 64): Target("agent", 100_000),
    (1, 1000): Target("env", 500),
    (1, 10000): Target("env", 40),
    (512, 4): Target("agent", 1_000_000),
}
RATIO_TARGET = 1.2  # step time may grow at most 1.2x faster than N (10k / 1k <= 12)
PYMUNK_TARGET = 2.0  # pymunk step <= 2x the kinematic step


def parse_size(text: str) -> tuple[int, int]:
    """'32x16' -> (32, 16)."""
    try:
        b, n = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like BxN (e.g. 1x64), got {text!r}") from None
    if b < 1 or n < 1:
        raise argparse.ArgumentTypeError(f"size must have B >= 1 and N >= 1, got {text!r}")
    return b, n


# ------------------------------------------------------------------------------------------------ systems
def _cycle(pool: list) -> Callable[[], object]:
    it = itertools.cycle(pool)
    return lambda: next(it)


def array_case(b: int, n: int, seed: int, **config: object) -> common.Case:
    """agentsim's batched array API (``BatchedEnv``); counts the agents alive at the start of each step."""
    from agentsim_env.env.vector import BatchedEnv

    env = BatchedEnv("navigation", b, n_agents=n, max_steps=LONG_EPISODE, **config)
    seeds = itertools.count(seed)
    rng = np.random.default_rng(seed)
    nxt = _cycle([rng.uniform(-1.0, 1.0, (b, n, env.act_dim)) for _ in range(POOL)])

    def prepare() -> None:
        env.reset(seed=next(seeds))

    def step() -> int:
        live = int(env.alive.sum())
        env.step(nxt())
        return live

    return common.Case(step, prepare)


def dict_case(b: int, n: int, seed: int) -> common.Case:
    """agentsim's PettingZoo ParallelEnv with Dict observations and actions; B envs stepped in a loop."""
    import agentsim_env

    envs = [agentsim_env.make("navigation", n_agents=n, max_steps=LONG_EPISODE) for _ in range(b)]
    rng = np.random.default_rng(seed)
    pools = []
    for env in envs:
        pools.append(
            _cycle(
                [
                    {a: {"motion": rng.uniform(-1, 1, 3).astype(np.float32)} for a in env.possible_agents}
                    for _ in range(POOL)
                ]
            )
        )
    seeds = itertools.count(seed * 1_000_003)

    def prepare() -> None:
        for env in envs:
            env.reset(seed=next(seeds))

    def step() -> int:
        done = 0
        for env, nxt in zip(envs, pools):
            live = env.agents
            if not live:
                continue
            acts = nxt()
            if len(live) != n:  # agents ended: act for the live ones only (rare; inside the timing)
                acts = {a: acts[a] for a in live}
            env.step(acts)
            done += len(live)
        return done

    return common.Case(step, prepare)


def vmas_case(b: int, n: int, seed: int) -> common.Case:
    """VMAS ``navigation`` on CPU, continuous actions, 32 lidar rays, spawning area grown with N."""
    import torch
    import vmas

    side = max(1.0, 0.25 * math.sqrt(n))  # the default 2 x 2 m area cannot fit many agents and goals
    env = vmas.make_env(
        "navigation",
        num_envs=b,
        device="cpu",
        continuous_actions=True,
        seed=seed,
        n_agents=n,
        n_lidar_rays=32,
        world_spawning_x=side,
        world_spawning_y=side,
    )
    env.reset()
    g = torch.Generator().manual_seed(seed)
    nxt = _cycle([[torch.rand(b, 2, generator=g) * 2 - 1 for _ in range(n)] for _ in range(POOL)])

    def step() -> int:
        env.step(nxt())
        return b * n

    return common.Case(step)


def mpe2_case(b: int, n: int, seed: int) -> common.Case:
    """mpe2 ``simple_spread`` ParallelEnv with N agents, continuous actions; B envs stepped in a loop."""
    from mpe2 import simple_spread_v3

    envs = [simple_spread_v3.parallel_env(N=n, max_cycles=LONG_EPISODE, continuous_actions=True) for _ in range(b)]
    rng = np.random.default_rng(seed)
    pools = []
    for i, env in enumerate(envs):
        env.reset(seed=seed + i)
        pools.append(_cycle([{a: rng.uniform(0, 1, 5).astype(np.float32) for a in env.agents} for _ in range(POOL)]))

    def step() -> int:
        for env, nxt in zip(envs, pools):
            env.step(nxt())
        return b * n

    return common.Case(step)


FACTORIES = {"dict": dict_case, "array": array_case, "vmas": vmas_case, "mpe2": mpe2_case}
QUADRATIC = ("vmas", "mpe2")
MODULE = {"vmas": "vmas", "mpe2": "mpe2"}


class Planner:
    """Decides which quadratic systems to skip, from the largest size measured so far (or a small probe)."""

    def __init__(self, max_step_s: float, seed: int) -> None:
        self.max_step_s = max_step_s
        self.seed = seed
        self.known: dict[tuple[str, int], tuple[int, float]] = {}

    def record(self, system: str, b: int, n: int, step_s: float) -> None:
        """Remember a measured step time (the largest N per system and B wins)."""
        if system in QUADRATIC and n >= self.known.get((system, b), (0, 0.0))[0]:
            self.known[(system, b)] = (n, step_s)

    def skip_reason(self, system: str, b: int, n: int) -> str | None:
        """None to run, else why the cell is skipped."""
        mod = MODULE.get(system)
        if mod and importlib.util.find_spec(mod) is None:
            return f"skipped ({mod} not installed)"
        if system not in QUADRATIC:
            return None
        if (system, b) not in self.known and n > PROBE_N:
            case = FACTORIES[system](b, PROBE_N, self.seed)
            stats = common.measure_interleaved({system: case}, rounds=1, block_s=0.0, warmup=1)
            self.record(system, b, PROBE_N, stats[system].step_s)
        n0, t0 = self.known.get((system, b), (n, 0.0))
        est = t0 * (n / n0) ** 2
        if n > n0 and est > self.max_step_s:
            return f"skipped (est. {est:.3g} s/step)"
        return None


# ------------------------------------------------------------------------------------------------ report
def _cell(stats: dict[str, common.Stats], skipped: dict[str, str], name: str) -> str:
    if name in skipped:
        return skipped[name]
    return common.fmt_num(stats[name].agent_steps_per_s)


def _ratio(stats: dict[str, common.Stats], a: str, b: str) -> str:
    if a in stats and b in stats:
        return f"{stats[a].agent_steps_per_s / stats[b].agent_steps_per_s:.3g}"
    return "skipped"


def _pass(target: Target | None, stats: dict[str, common.Stats], skipped: dict[str, str], name: str) -> str:
    if target is None:
        return "-"
    if name in skipped or name not in stats:
        return "skipped"
    s = stats[name]
    return "PASS" if target.met(s.agent_steps_per_s, s.step_s) else "FAIL"


def main(argv: list[str] | None = None) -> dict:
    """Measure every size, print the tables, and return the raw results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few short rounds (a smoke test; numbers are rough)")
    ap.add_argument("--sizes", type=parse_size, nargs="+", default=[parse_size(s) for s in SIZES])
    ap.add_argument("--systems", nargs="+", choices=SYSTEMS, default=list(SYSTEMS))
    ap.add_argument("--rounds", type=int, default=None, help="timed rounds per size (default 15, quick 3)")
    ap.add_argument("--block-s", type=float, default=None, help="seconds per timed block (default 0.15)")
    ap.add_argument("--max-step-s", type=float, default=None, help="skip a quadratic system above this")
    ap.add_argument("--pymunk-size", type=parse_size, default=(1, 64), help="size of the pymunk-vs-kinematic check")
    ap.add_argument(
        "--ratio-sizes",
        type=parse_size,
        nargs=2,
        default=[(1, 1000), (1, 10000)],
        help="two B=1 sizes whose step-time ratio is checked",
    )
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rounds = args.rounds or (3 if args.quick else 15)
    block_s = args.block_s if args.block_s is not None else (0.02 if args.quick else 0.15)
    max_step_s = args.max_step_s if args.max_step_s is not None else (0.25 if args.quick else 2.0)
    if "vmas" in args.systems:
        common.torch_single_thread()
    planner = Planner(max_step_s, args.seed)
    print(f"machine: {common.machine_description()}")
    print(
        f"mode: {'quick' if args.quick else 'full'}; {rounds} interleaved rounds of ~{block_s} s blocks per "
        f"system; medians of agent-steps per CPU second"
    )
    results: dict = {"sizes": {}, "checks": []}
    rows = []
    for b, n in args.sizes:
        cases: dict[str, common.Case] = {}
        skipped: dict[str, str] = {}
        for name in args.systems:
            reason = planner.skip_reason(name, b, n)
            if reason:
                skipped[name] = reason
            else:
                cases[name] = FACTORIES[name](b, n, args.seed)
        if "array" in args.systems and (b, n) == tuple(args.pymunk_size):
            cases["array pymunk"] = array_case(b, n, args.seed, physics="pymunk")
        stats = common.measure_interleaved(cases, rounds, block_s, max_block_steps=MAX_BLOCK_STEPS)
        for name, s in stats.items():
            planner.record(name, b, n, s.step_s)
        for name in SYSTEMS:
            if name not in stats and name not in skipped:
                skipped[name] = "skipped (not run)" if name in args.systems else "skipped (not selected)"
        results["sizes"][(b, n)] = {"stats": stats, "skipped": skipped}
        target = TARGETS.get((b, n))
        array_ms = common.fmt_num(stats["array"].step_s * 1e3) if "array" in stats else "skipped (not run)"
        rows.append(
            [
                f"{b}x{n}",
                _cell(stats, skipped, "dict"),
                _cell(stats, skipped, "array"),
                array_ms,
                _cell(stats, skipped, "vmas"),
                _cell(stats, skipped, "mpe2"),
                _ratio(stats, "array", "vmas"),
                _ratio(stats, "array", "mpe2"),
                target.text() if target else "-",
                _pass(target, stats, skipped, "array"),
                _pass(target if b == 1 else None, stats, skipped, "dict"),
            ]
        )
        print(f"  measured {b}x{n}", flush=True)
    headers = [
        "size BxN",
        "dict API ag-st/s",
        "array API ag-st/s",
        "array ms/step",
        "VMAS ag-st/s",
        "mpe2 ag-st/s",
        "array/VMAS",
        "array/mpe2",
        "target",
        "array",
        "dict",
    ]
    print()
    print(common.markdown_table(headers, rows))
    print()
    print("ag-st/s = agent-steps per second (live agents only); dict API and mpe2 step B envs in a loop when B > 1.")
    checks = []
    res = results["sizes"]
    small, big = (tuple(s) for s in args.ratio_sizes)
    limit = RATIO_TARGET * big[1] / small[1]
    if small in res and big in res and "array" in res[small]["stats"] and "array" in res[big]["stats"]:
        r = res[big]["stats"]["array"].step_s / res[small]["stats"]["array"].step_s
        checks.append(
            [
                f"step time {big[0]}x{big[1]} / {small[0]}x{small[1]} (array API)",
                f"{r:.3g}",
                f"<= {limit:.3g}",
                "PASS" if r <= limit else "FAIL",
            ]
        )
    else:
        checks.append(
            [
                f"step time {big[0]}x{big[1]} / {small[0]}x{small[1]} (array API)",
                "skipped (sizes not measured)",
                f"<= {limit:.3g}",
                "skipped",
            ]
        )
    ps = tuple(args.pymunk_size)
    label = f"pymunk / kinematic step time {ps[0]}x{ps[1]} (array API)"
    if ps in res and "array pymunk" in res[ps]["stats"]:
        st = res[ps]["stats"]
        r = st["array pymunk"].step_s / st["array"].step_s
        checks.append([label, f"{r:.3g}", f"<= {PYMUNK_TARGET:.3g}", "PASS" if r <= PYMUNK_TARGET else "FAIL"])
    else:
        checks.append([label, "skipped (size not measured)", f"<= {PYMUNK_TARGET:.3g}", "skipped"])
    results["checks"] = checks
    print()
    print(common.markdown_table(["check", "value", "target", "result"], checks))
    return results


if __name__ == "__main__":
    main()
