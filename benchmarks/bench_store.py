"""Cost of recording to the SQLite store: rows written per second and the step time with the recorder attached.

``navigation`` with 1 world x 1,000 agents (``--agents``) through the dict API (``agentsim_env.make``), random
actions from a pool of 16 action sets drawn once and cycled (as in ``bench_step.py``), timed interleaved (see
``common.measure_interleaved``) in the same run:

- ``plain``: the env without a recorder;
- ``recorded``: the same env recorded with ``record(env, path, commit_every=1)`` (every step a transaction:
  durable once ``step`` returns); ``--commit-every 1 10`` adds a row per value.

Each timed block starts from a freshly reset episode (the reset, and the step-0 rows the recorder writes for
it, are not timed) and lasts at most 300 steps, with ``max_steps`` beyond the block. The recorder's stage-10
hook is timed on its own (CPU time around each call, commit included): **rows/s** is the ``steps`` rows it
wrote (one per agent that acted) per CPU second spent in the hook, the messages, events and sensors of the
step included (navigation without comms writes none). The store lives in a temporary folder (``--dir``) and
grows through the run, so the cost of a growing file and index, and of WAL checkpoints, is in the timing.

Targets: rows/s >= 500,000 at 1x1000 with commit_every=1; recorded / plain step time <= 2.

Run: ``.venv/bin/python benchmarks/bench_store.py [--quick] [--agents 1000] [--commit-every 1 10]``
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import argparse  # noqa: E402
import itertools  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import common  # noqa: E402  (pins thread pools before numpy / numba / torch load)
import numpy as np  # noqa: E402

POOL = 16  # random action sets, cycled
LONG_EPISODE = 10**7  # max_steps: no time limit inside the timed window
MAX_BLOCK_STEPS = 300  # as bench_step.py: few agents end inside a block
ROWS_TARGET = 500_000  # steps rows per CPU second of the hook, 1x1000, commit_every=1
RATIO_TARGET = 2.0  # recorded / plain step time


@dataclass
class HookClock:
    """CPU time spent in the recorder's hook and the ``steps`` rows it wrote, per timed block."""

    cpu: float = 0.0
    rows: int = 0
    steps: int = 0
    blocks: list[tuple[int, float, int]] = field(default_factory=list)

    def start_block(self) -> None:
        """Forget what was counted since the last block ended (the reset's step-0 rows)."""
        self.cpu, self.rows, self.steps = 0.0, 0, 0

    def close_block(self) -> None:
        """End the current block (called when the next one starts, and once at the end)."""
        self.blocks.append((self.rows, self.cpu, self.steps))
        self.start_block()

    def rates(self, rounds: int) -> list[float]:
        """Rows per hook CPU second of the last ``rounds`` blocks (the earlier ones are warm-up and sizing)."""
        return [rows / max(cpu, 1e-9) for rows, cpu, _ in self.blocks[-rounds:]]

    def hook_s(self, rounds: int) -> float:
        """Median hook CPU seconds per step over the last ``rounds`` blocks."""
        return float(np.median([cpu / max(steps, 1) for _, cpu, steps in self.blocks[-rounds:]]))


def dict_case(n: int, seed: int, path: Path | None = None, commit_every: int = 1) -> tuple[common.Case, Any]:
    """The dict API at 1 x ``n``; recorded to ``path`` when given. Returns the case and its hook clock (or None)."""
    import agentsim_env
    from agentsim_env.recorder import record

    env = agentsim_env.make("navigation", n_agents=n, max_steps=LONG_EPISODE)
    clock = None
    if path is not None:
        env = record(env, path, commit_every=commit_every)
        clock = HookClock()
        rec, world = env.recorder, env.world
        hook = rec.hook

        def timed(w: Any, events: Any) -> None:
            sc = events.scores
            acting = int(np.count_nonzero(sc.acting)) if sc is not None else int(w.state.online.sum())
            c0 = time.process_time()
            hook(w, events)
            clock.cpu += time.process_time() - c0
            clock.rows += acting
            clock.steps += 1

        world.hooks[world.hooks.index(hook)] = timed  # the same hook, timed
    rng = np.random.default_rng(seed)
    pool = [{a: {"motion": rng.uniform(-1, 1, 3).astype(np.float32)} for a in env.possible_agents} for _ in range(POOL)]
    nxt: Callable[[], dict] = itertools.cycle(pool).__next__
    seeds = itertools.count(seed * 1_000_003)
    first = [True]

    def prepare() -> None:
        if clock is not None and not first[0]:
            clock.close_block()
        first[0] = False
        env.reset(seed=next(seeds))
        if clock is not None:  # the reset's step-0 rows are not part of the timing
            clock.start_block()

    def step() -> int:
        live = env.agents
        if not live:
            return 0
        acts = nxt()
        if len(live) != n:  # agents ended: act for the live ones only
            acts = {a: acts[a] for a in live}
        env.step(acts)
        return len(live)

    return common.Case(step, prepare), (env, clock)


def main(argv: list[str] | None = None) -> dict:
    """Measure, print the tables, and return the raw results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few short rounds (a smoke test; numbers are rough)")
    ap.add_argument("--agents", type=int, default=1000, help="agents in the one world")
    ap.add_argument("--commit-every", type=int, nargs="+", default=[1], help="recorded cases, one per value")
    ap.add_argument("--rounds", type=int, default=None, help="timed rounds (default 15, quick 3)")
    ap.add_argument("--block-s", type=float, default=None, help="seconds per timed block (default 0.15)")
    ap.add_argument("--dir", default=None, help="folder for the temporary store (default: the system's temp)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rounds = args.rounds or (3 if args.quick else 15)
    block_s = args.block_s if args.block_s is not None else (0.02 if args.quick else 0.15)
    n = args.agents
    print(f"machine: {common.machine_description()}")
    print(
        f"mode: {'quick' if args.quick else 'full'}; navigation 1x{n}, dict API; {rounds} interleaved rounds of "
        f"~{block_s} s blocks per case; medians over rounds, CPU time"
    )
    results: dict = {"stats": {}, "rows_per_s": {}, "checks": []}
    with tempfile.TemporaryDirectory(prefix="bench_store_", dir=args.dir) as tmp:
        cases: dict[str, common.Case] = {}
        clocks: dict[str, HookClock] = {}
        envs = []
        cases["plain"], (env, _) = dict_case(n, args.seed)
        envs.append(env)
        for k in args.commit_every:
            name = f"recorded, commit_every={k}"
            cases[name], (env, clock) = dict_case(n, args.seed, Path(tmp) / f"store_{k}.db", k)
            clocks[name] = clock
            envs.append(env)
        stats = common.measure_interleaved(cases, rounds, block_s, max_block_steps=MAX_BLOCK_STEPS)
        for clock in clocks.values():
            clock.close_block()
        sizes = {}  # the file and its write-ahead log, before closing (which checkpoints the log into the file)
        for name, k in zip(clocks, args.commit_every):
            files = [Path(tmp) / f"store_{k}.db{suffix}" for suffix in ("", "-wal")]
            sizes[name] = sum(f.stat().st_size for f in files if f.exists())
        for env in envs:
            env.close()
    plain = stats["plain"]
    rows = []
    for name, s in stats.items():
        clock = clocks.get(name)
        rate = float(np.median(clock.rates(rounds))) if clock else float("nan")
        results["stats"][name] = s
        results["rows_per_s"][name] = rate
        rows.append(
            [
                name,
                common.fmt_num(s.step_s * 1e3),
                common.fmt_num(s.wall_step_s * 1e3),
                common.fmt_num(s.agent_steps_per_s),
                common.fmt_num(clock.hook_s(rounds) * 1e3) if clock else "-",
                common.fmt_num(rate) if clock else "-",
                f"{s.step_s / plain.step_s:.3g}",
                common.fmt_num(sizes[name] / 2**20) if clock else "-",
            ]
        )
    headers = [
        "case",
        "ms/step (CPU)",
        "ms/step (wall)",
        "agent-steps/s",
        "hook ms/step",
        "rows/s written",
        "x plain",
        "store MiB",
    ]
    print()
    print(common.markdown_table(headers, rows))
    print()
    print(
        "hook ms/step: CPU time in the recorder's stage-10 hook per step (commit included); "
        "rows/s written: steps rows per CPU second in the hook; x plain: step time over the plain env's."
    )
    first = f"recorded, commit_every={args.commit_every[0]}"
    checks = []
    if args.commit_every[0] == 1:
        rate = results["rows_per_s"][first]
        checks.append(
            [
                f"steps rows/s written, 1x{n}, commit_every=1",
                common.fmt_num(rate),
                f">= {ROWS_TARGET:,}",
                "PASS" if rate >= ROWS_TARGET else "FAIL",
            ]
        )
    ratio = stats[first].step_s / plain.step_s
    checks.append(
        [
            f"step time recorded / plain, 1x{n}, dict API ({first.split(', ')[1]})",
            f"{ratio:.3g}",
            f"<= {RATIO_TARGET:g}",
            "PASS" if ratio <= RATIO_TARGET else "FAIL",
        ]
    )
    results["checks"] = checks
    print()
    print(common.markdown_table(["check", "value", "target", "result"], checks))
    return results


if __name__ == "__main__":
    main()
