"""The ``agentsim`` command.

Subcommands:
    run        roll out a scenario's scripted baseline (batch, or live with --render), print a summary table,
               write the last frame as PNG
    scenarios  list the registered scenarios
    evaluate   batch evaluation of the UAV sensor-release strategies (zone files x strategies x seeds):
               sensors.csv, runs.csv, summary.md (ranking) and PNG plots
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np


def _parse_config(pairs: list[str]) -> dict[str, Any]:
    """``key=value`` pairs; values are parsed as JSON when possible (numbers, lists, booleans)."""
    out: dict[str, Any] = {}
    for p in pairs:
        if "=" not in p:
            raise SystemExit(f"--set expects key=value, got {p!r}")
        k, v = p.split("=", 1)
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
        if isinstance(out[k], list):
            out[k] = tuple(out[k])
    return out


def _progress(it: Any, total: int, desc: str, enabled: bool) -> Any:
    if not enabled:
        return it
    from tqdm.auto import tqdm

    return tqdm(it, total=total, desc=desc, unit="ep")


def cmd_run(args: argparse.Namespace) -> int:
    """Roll out the baseline over seeds; print success and return statistics; save the last frame."""
    import agentsim_env
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.policies.rollout import run_episode
    from agentsim_env.render.topdown import save_png

    config = _parse_config(args.set or [])
    env = agentsim_env.make(args.scenario, render_mode="human" if args.render else "rgb_array", **config)
    if args.fps is not None:
        if args.fps <= 0:
            raise ValueError(f"--fps must be > 0, got {args.fps}")
        env.metadata["render_fps"] = args.fps  # the live window paces itself with this rate
    policy = make_policy(args.scenario, env, args.policy)
    rows = []
    frame = None
    for k in _progress(range(args.episodes), args.episodes, args.scenario, not args.quiet):
        ep = run_episode(env, policy, args.seed + k, render_every=0 if args.render else (1 if k == 0 else 0))
        if ep.frames:
            frame = ep.frames[-1]
        rows.append((ep.seed, ep.steps, float(np.mean(list(ep.returns.values()))), ep.info_sums))
    n = env.scenario.n_agents
    keys = sorted({k for *_, s in rows for k in s if k in ("arrived", "collided", "released", "landed")})
    print(f"\n{args.scenario}: {args.episodes} episodes x {n} agents, policy={args.policy or 'default'}")
    print("| metric | mean | std |")
    print("|---|---|---|")
    print(f"| steps | {np.mean([r[1] for r in rows]):.1f} | {np.std([r[1] for r in rows]):.1f} |")
    print(f"| mean return | {np.mean([r[2] for r in rows]):.2f} | {np.std([r[2] for r in rows]):.2f} |")
    for key in keys:
        frac = np.array([r[3].get(key, 0.0) / n for r in rows])
        print(f"| {key} per agent | {frac.mean():.3f} | {frac.std():.3f} |")
    if frame is not None and args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        save_png(frame, str(out / f"{args.scenario}_seed{args.seed}.png"))
        print(f"frame written to {out / f'{args.scenario}_seed{args.seed}.png'}")
    env.close()
    return 0


def cmd_scenarios(args: argparse.Namespace) -> int:
    """Print the registered scenarios with the first line of their documentation."""
    import agentsim_env
    from agentsim_env.scenarios.registry import scenario_class

    for name in agentsim_env.list_scenarios():
        mod = sys.modules[scenario_class(name).__module__]
        print(f"{name:14s} {(mod.__doc__ or '').strip().splitlines()[0]}")
    return 0


def _parse_seeds(tokens: list[str]) -> list[int]:
    """``N`` (one number: seeds 0..N-1) or an explicit list (``0,4,9``, ``0 4 9``, or ``7,`` for one seed)."""
    explicit = len(tokens) > 1 or any("," in t for t in tokens)
    parts = [p for t in tokens for p in t.split(",") if p.strip()]
    try:
        values = [int(p) for p in parts]
    except ValueError:
        raise ValueError(
            f"--seeds must be a count N or a list of integers (e.g. 0,4,9), got {' '.join(tokens)!r}"
        ) from None
    if not values:
        raise ValueError("--seeds must be a count N >= 1 or a list of integers, got nothing")
    if explicit:
        return list(dict.fromkeys(values))
    if values[0] < 1:
        raise ValueError(f"--seeds N must be >= 1 (or give a list such as 0,4,9), got {values[0]}")
    return list(range(values[0]))


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Fly every strategy over every zone file and seed; write CSVs, plots and the Markdown ranking.

    Nothing is written unless every run succeeds (see ``agentsim_env.evaluation.report``).
    """
    from agentsim_env.evaluation.report import ranking_table, write_outputs
    from agentsim_env.evaluation.runner import resolve_strategies, resolve_zones, run_grid
    from agentsim_env.evaluation.scoring import rank_strategies, run_rows

    overrides = _parse_config(args.set or [])
    seeds = _parse_seeds(args.seeds)
    # validate the cheap inputs before the first (slow) run
    resolve_zones(args.zones)
    resolve_strategies(args.strategies)
    grid = run_grid(args.zones, args.strategies, seeds, overrides, progress=not args.quiet)
    paths, _ = write_outputs(grid, args.out, plots=not args.no_plots)
    rows = run_rows(grid.runs)
    for src in grid.sources:
        print(f"\nRanking, zone file {src.label!r} ({len(seeds)} seed(s)):\n")
        print(ranking_table(rank_strategies(rows, src.label)))
    print("\nwritten:")
    for p in paths:
        print(f"  {p}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``agentsim``."""
    p = argparse.ArgumentParser(prog="agentsim", description="agentsim-env command line")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="roll out a scenario's scripted baseline")
    r.add_argument("scenario")
    r.add_argument("--episodes", type=int, default=5)
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--policy", default=None, help="baseline name (default: the scenario's first)")
    r.add_argument("--set", nargs="*", metavar="KEY=VALUE", help="scenario config values")
    r.add_argument("--render", action="store_true", help="show a live window (graphical mode)")
    r.add_argument("--fps", type=int, default=None, help="frames per second of the live window (default: real time)")
    r.add_argument("--out", default="outputs", help="folder for the PNG frame")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=cmd_run)
    s = sub.add_parser("scenarios", help="list the registered scenarios")
    s.set_defaults(func=cmd_scenarios)
    e = sub.add_parser("evaluate", help="batch evaluation of the UAV sensor-release strategies")
    e.add_argument(
        "--zones",
        nargs="+",
        default=["default"],
        metavar="ZONES",
        help="zone files: 'default', 'tiny' or JSON paths (several allowed; default: default)",
    )
    e.add_argument(
        "--strategies",
        nargs="+",
        default=["all"],
        metavar="NAME",
        help="release strategies, or 'all' (default); the B8 teleport reference is always added",
    )
    e.add_argument(
        "--seeds",
        nargs="+",
        default=["3"],
        metavar="SEED",
        help="a count N (seeds 0..N-1; default 3) or a list: 0,4,9 or 0 4 9 (one seed: 7,)",
    )
    e.add_argument("--set", nargs="*", metavar="KEY=VALUE", help="uav_release config values for every run")
    e.add_argument("--out", default="outputs/evaluation", help="output folder (default: outputs/evaluation)")
    e.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.set_defaults(func=cmd_evaluate)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``agentsim`` command."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except ValueError as exc:  # bad config or input: one clear line, no traceback
        print(f"agentsim: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
