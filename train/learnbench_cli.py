"""``agentsim benchmark-rl`` (also ``benchmarks/bench_learning.py``): the learning benchmark's command line.

See ``agentsim_env.train.learnbench`` for what runs and ``agentsim_env.train.learnbench_report`` for the files.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import Any

from agentsim_env.train.learnbench import (
    ALGORITHMS,
    DEFAULT_BENCHMARL_PYTHON,
    BenchOptions,
    bench_scenarios,
    run_benchmark,
)

__all__ = ["add_arguments", "add_benchmark_rl_command", "cmd_benchmark_rl", "main", "options_from_args"]

EPILOG = """\
examples:
  agentsim benchmark-rl --quick --out /tmp/bench_quick          # every scenario, ppo + mappo, 2 seeds, ~3 min
  agentsim benchmark-rl                                         # the full table (hours): every algorithm, 3 seeds
  agentsim benchmark-rl --scenarios navigation --algorithms ppo --seeds 3 --budget 500000"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the benchmark's options to ``p``."""
    p.add_argument("--scenarios", nargs="+", default=[], metavar="NAME", help=f"from {bench_scenarios()} (all)")
    p.add_argument(
        "--algorithms", nargs="+", default=[], metavar="NAME", help=f"from {list(ALGORITHMS)} (all; --quick: ppo mappo)"
    )
    p.add_argument("--seeds", type=int, default=None, help="training seeds per algorithm (3; --quick: 2)")
    p.add_argument("--budget", type=int, default=None, help="agent-steps per run (the bench configs')")
    p.add_argument("--eval-seeds", type=int, default=None, help="evaluation episodes per policy (the configs')")
    p.add_argument("--quick", action="store_true", help="small envs and tiny budgets: a check of the pipeline")
    p.add_argument("--out", type=Path, default=Path("outputs/bench_learning"), help="output folder")
    p.add_argument(
        "--benchmarl-python",
        type=Path,
        default=DEFAULT_BENCHMARL_PYTHON,
        metavar="PATH",
        help="the BenchMARL environment's Python (default: %(default)s)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def options_from_args(args: argparse.Namespace, command: str) -> BenchOptions:
    """The ``BenchOptions`` of parsed arguments (checked: a bad value raises ``ValueError`` naming it)."""
    return BenchOptions(
        scenarios=tuple(args.scenarios),
        algorithms=tuple(args.algorithms),
        seeds=args.seeds,
        budget=args.budget,
        eval_seeds=args.eval_seeds,
        quick=bool(args.quick),
        out=Path(args.out),
        benchmarl_python=Path(args.benchmarl_python),
        progress=not args.no_progress,
        command=command,
    )


def cmd_benchmark_rl(args: argparse.Namespace) -> int:
    """Run the benchmark and print the summary table."""
    command = getattr(args, "command_line", "") or "agentsim benchmark-rl " + shlex.join(sys.argv[2:])
    opts = options_from_args(args, command)
    run_benchmark(opts)
    print((opts.out / "summary.md").read_text(encoding="utf-8"))
    print(f"files in {opts.out}: runs.csv, curves.csv, baselines.csv, summary.md, <scenario>.png")
    return 0


def add_benchmark_rl_command(sub: Any) -> argparse.ArgumentParser:
    """Add ``benchmark-rl`` to the ``agentsim`` subcommands (``sub`` is the parser's subparsers object)."""
    p = sub.add_parser(
        "benchmark-rl",
        help="the learning benchmark: every scenario, PPO and BenchMARL algorithms, seeds, baselines",
        description="Train every algorithm on every scenario for a fixed agent-step budget and several seeds,\n"
        "evaluate on held-out seeds beside the scripted baselines, and write runs.csv, curves.csv, a PNG per\n"
        "scenario and summary.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=EPILOG,
    )
    add_arguments(p)
    p.set_defaults(func=cmd_benchmark_rl)
    return p


def main(argv: list[str] | None = None, prog: str = "bench_learning.py") -> int:
    """Entry point of ``benchmarks/bench_learning.py``: parse ``argv`` and run; a bad option exits 2 with one
    line naming it."""
    p = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0], epilog=EPILOG,
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    add_arguments(p)
    args = p.parse_args(argv)
    args.command_line = f"python benchmarks/{prog} " + shlex.join(sys.argv[1:] if argv is None else argv)
    try:
        return cmd_benchmark_rl(args)
    except ValueError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
