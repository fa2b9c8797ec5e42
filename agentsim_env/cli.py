"""The ``agentsim`` command.

Subcommands:
    run        roll out a scenario's scripted baseline (batch, or live with --render), print a summary table,
               draw the first episode's trajectories as PNG (named by scenario, policy, seed and --set values)
               (``cli_run``)
    scenarios  list the registered scenarios
    evaluate   batch evaluation of the UAV sensor-release strategies (zone files x strategies x seeds):
               sensors.csv, runs.csv, summary.md (ranking) and PNG plots
    warmup     compile and cache every simulation kernel the commands reach (``agentsim_env.warmup``);
               ``make install`` runs it
    view       the 3D web viewer: a live run with a policy, or a replay from the store (``cli_view``)
    zones      the hot-zone designer page, and a zone-file check (``cli_view``)

``--set KEY=VALUE`` values are parsed by the type of the config field they set (``agentsim_env.cli_set``).
Bad input (counts, folders, config values) ends with one ``agentsim: error: ...`` line and exit code 2, before
any rollout. Help texts that need the registries are built only when shown, so ``agentsim --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from collections.abc import Callable
from typing import Any

from agentsim_env.cli_kernels import COMPILE_NOTICE, WARM_MARKER, announce_compile, kernels_cold, mark_warm
from agentsim_env.cli_run import check_record, cmd_run, config_tag
from agentsim_env.cli_set import parse_set
from agentsim_env.outdirs import prepare_out, remove_created

__all__ = [
    "COMPILE_NOTICE",
    "WARM_MARKER",
    "announce_compile",
    "build_parser",
    "config_tag",
    "kernels_cold",
    "main",
    "mark_warm",
    "prepare_out",
]

SET_HELP = (
    "config values, parsed by each field's type: booleans true/false/1/0/yes/no, integers, numbers, "
    "lists as 12,20 or [12,20], none/null for optional fields, sub-configs as a JSON object or dotted keys "
    "(body.radius=1.0 comms.loss=0.1)"
)


# ----------------------------------------------------------------------------------------------- help
class _Formatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Epilogs kept as written; defaults appended to help texts (unless None/False or already named)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if default is None or default is False or default is argparse.SUPPRESS or "(default" in text:
            return text
        shown = " ".join(map(str, default)) if isinstance(default, (list, tuple)) else str(default)
        return f"{text} (default: {shown.replace('%', '%%')})"


class _LazyParser(argparse.ArgumentParser):
    """An ArgumentParser whose help texts that need imports are filled in only when help is shown."""

    def __init__(
        self, *args: Any, lazy: Callable[[argparse.ArgumentParser], None] | None = None, **kwargs: Any
    ) -> None:
        kwargs.setdefault("formatter_class", _Formatter)
        super().__init__(*args, **kwargs)
        self._lazy = lazy

    def format_help(self) -> str:
        """The help text (running the lazy filler first, once)."""
        if self._lazy is not None:
            fill, self._lazy = self._lazy, None
            fill(self)
        return super().format_help()


def _action(parser: argparse.ArgumentParser, dest: str) -> argparse.Action:
    return next(a for a in parser._actions if a.dest == dest)


def _wrap(label: str, names: list[str], width: int = 100) -> str:
    return textwrap.fill(", ".join(names), width, initial_indent=f"  {label:13s}", subsequent_indent=" " * 15)


def _fill_main(p: argparse.ArgumentParser) -> None:
    import agentsim_env

    p.epilog = f"scenarios: {', '.join(agentsim_env.list_scenarios())}\n\n" + (p.epilog or "")


def _fill_run(p: argparse.ArgumentParser) -> None:
    import agentsim_env
    from agentsim_env.policies.registry import BASELINES

    names = agentsim_env.list_scenarios()
    _action(p, "scenario").help = f"one of: {', '.join(names)}"
    lines = [
        _wrap(n, [f"{b} (default)" if i == 0 else b for i, b in enumerate(BASELINES.get(n, []))] or ["-"])
        for n in names
    ]
    p.epilog = "baselines per scenario (--policy):\n" + "\n".join(lines) + "\n\n" + (p.epilog or "")


def _fill_evaluate(p: argparse.ArgumentParser) -> None:
    from agentsim_env.uav.evaluation.runner import TELEPORT, available_strategies

    names = [n for n in available_strategies() if n != TELEPORT]
    listed = textwrap.fill(", ".join(names), 100, initial_indent="  ", subsequent_indent="  ")
    p.epilog = (
        f"release strategies (--strategies):\n{listed}\n  ({TELEPORT} is always added as the reference)\n\n"
        + (p.epilog or "")
    )


RUN_EPILOG = """\
The PNG of the first episode is OUT/SCENARIO_POLICY_seedSEED[_HASH].png, HASH being 6 hex digits of the --set
values (none without --set), so different configs do not overwrite each other.

examples:
  agentsim run navigation --episodes 20
  agentsim run navigation --policy random --set n_agents=8 collisions=false body.max_speed=8
  agentsim run relay --set gap=12,20 comms.loss=0.1 --out outputs/relay
  agentsim run uav_release --set zones=tiny n_uavs=2 --episodes 1 --render"""
EVALUATE_EPILOG = """\
examples:
  agentsim evaluate --zones default --strategies all --seeds 3
  agentsim evaluate --zones tiny my_zones.json --strategies B2_rings B5_cvt --seeds 0,4,9 \\
      --set n_uavs=2 payload=10 wind.mean_speed=3 --out outputs/eval_tiny"""
MAIN_EPILOG = """\
examples:
  agentsim scenarios
  agentsim run navigation --episodes 20 --set n_agents=8
  agentsim evaluate --zones default --strategies all --seeds 3
  agentsim train navigation
  agentsim warmup
Run 'agentsim COMMAND --help' for a command's options."""


# ------------------------------------------------------------------------------------------ commands
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
        if min(values) < 0:
            raise ValueError(f"--seeds must be integers >= 0, got {min(values)}")
        return list(dict.fromkeys(values))
    if values[0] < 1:
        raise ValueError(f"--seeds N must be >= 1 (or give a list such as 0,4,9), got {values[0]}")
    return list(range(values[0]))


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Fly every strategy over every zone file and seed; write CSVs, plots and the Markdown ranking.

    Nothing is written unless every run succeeds (see ``agentsim_env.uav.evaluation.report``); the output folder
    is created and probed before the first run, and removed again (when still empty) if a run fails.
    """
    from agentsim_env.scenarios.registry import scenario_class
    from agentsim_env.uav.evaluation.report import ranking_table, write_outputs
    from agentsim_env.uav.evaluation.runner import resolve_strategies, resolve_zones, run_grid
    from agentsim_env.uav.evaluation.scoring import rank_strategies, run_rows

    # validate the cheap inputs before the first (slow) run
    seeds = _parse_seeds(args.seeds)
    overrides = parse_set(scenario_class("uav_release").config_cls, args.set or [])
    resolve_zones(args.zones)
    resolve_strategies(args.strategies)
    store = getattr(args, "record", None) or None
    check_record(store)
    created = prepare_out(args.out)
    try:
        announce_compile()
        if store is None:
            grid = run_grid(args.zones, args.strategies, seeds, overrides, progress=not args.quiet)
            paths, _ = write_outputs(grid, args.out, plots=not args.no_plots)
        else:  # every mission recorded; sensors.csv and runs.csv read back from the store
            from agentsim_env.recorder import record
            from agentsim_env.recorder.read import open_store

            def record_env(env: Any, label: str) -> Any:
                return record(env, store, label=label)

            grid = run_grid(
                args.zones, args.strategies, seeds, overrides, progress=not args.quiet, record_env=record_env
            )
            with open_store(store) as st:
                paths, _ = write_outputs(grid, args.out, plots=not args.no_plots, store=st.con)
    except BaseException:
        remove_created(created)
        raise
    mark_warm()
    rows = run_rows(grid.runs)
    for src in grid.sources:
        print(f"\nRanking, zone file {src.label!r} ({len(seeds)} seed(s)):\n")
        print(ranking_table(rank_strategies(rows, src.label)))
    print("\nwritten:")
    for p in paths:
        print(f"  {p}")
    if store:
        flown = [r.store_run for r in grid.runs if r.store_run is not None]
        print(f"  {store} ({len(flown)} missions recorded, runs {min(flown)}-{max(flown)})")
    return 0


def cmd_warmup(args: argparse.Namespace) -> int:
    """Compile and cache every kernel the commands reach (``agentsim_env.warmup``), then mark the cache warm."""
    from agentsim_env.warmup import warm_up

    announce_compile()
    warm_up(None if args.quiet else lambda name, s: print(f"  {name:14s} ready ({s:.1f} s)", flush=True))
    mark_warm()
    if not args.quiet:
        print("agentsim: simulation kernels compiled and cached")
    return 0


# -------------------------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``agentsim``."""
    p = _LazyParser(
        prog="agentsim", description="agentsim-env command line", epilog=MAIN_EPILOG, lazy=_fill_main
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    r = sub.add_parser(
        "run",
        help="roll out a scenario's scripted baseline",
        description="Roll out a scenario's scripted baseline over --episodes seeds, print a summary table\n"
        "and draw the first episode's trajectories.",
        epilog=RUN_EPILOG,
        lazy=_fill_run,
    )
    r.add_argument("scenario", metavar="SCENARIO", help="a registered scenario ('agentsim scenarios')")
    r.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="episodes (seeds SEED, SEED+1, ...), >= 1 (default: 5; 1 with --render)",
    )
    r.add_argument("--seed", type=int, default=0, help="seed of the first episode, >= 0")
    r.add_argument(
        "--policy",
        default=None,
        help="baseline name (default: the scenario's first; see below) or "
        "a trained model (a folder from 'agentsim train', or its .zip)",
    )
    r.add_argument("--set", nargs="*", metavar="KEY=VALUE", help=SET_HELP)
    r.add_argument(
        "--render",
        action="store_true",
        help="show a live window, in real time unless --fps is "
        "given (needs a display); closing it, Esc, SIGTERM or Ctrl-C end the run",
    )
    r.add_argument(
        "--fps", type=int, default=None, help="frames per second of the live window, > 0 (default: real time)"
    )
    r.add_argument("--out", default="outputs", help="folder for the trajectory PNG ('' for none)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument(
        "--record",
        default=None,
        metavar="PATH",
        help="record every episode to this SQLite store (one run; created when missing; see 'agentsim runs')",
    )
    r.add_argument(
        "--shards",
        type=int,
        default=None,
        metavar="K",
        help="run the simulation over K shard processes on Ray (navigation, relay; see docs/distributed.md)",
    )
    r.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="with --shards: a Ray cluster's host:port (default: a local cluster on 127.0.0.1)",
    )
    r.add_argument(
        "--threads",
        type=int,
        default=1,
        metavar="N",
        help="threads for the per-agent kernels "
        "(scan, collisions, motion; worth it from tens of thousands of agents; same results)",
    )
    r.set_defaults(func=cmd_run)
    s = sub.add_parser("scenarios", help="list the registered scenarios")
    s.set_defaults(func=cmd_scenarios)
    e = sub.add_parser(
        "evaluate",
        help="batch evaluation of the UAV sensor-release strategies",
        description="Fly every release strategy over every zone file and seed (scenario uav_release);\n"
        "write sensors.csv, runs.csv, summary.md and PNG plots.",
        epilog=EVALUATE_EPILOG,
        lazy=_fill_evaluate,
    )
    e.add_argument(
        "--zones",
        nargs="+",
        default=["default"],
        metavar="ZONES",
        help="zone files: 'default', 'tiny' or JSON paths (several allowed)",
    )
    e.add_argument(
        "--strategies",
        nargs="+",
        default=["all"],
        metavar="NAME",
        help="release strategies (see below), or 'all'",
    )
    e.add_argument(
        "--seeds",
        nargs="+",
        default=["3"],
        metavar="SEED",
        help="a count N >= 1 (seeds 0..N-1) or a list: 0,4,9 or 0 4 9 (one seed: 7,)",
    )
    e.add_argument(
        "--set", nargs="*", metavar="KEY=VALUE", help="uav_release " + SET_HELP + "; for every run"
    )
    e.add_argument("--out", default="outputs/evaluation", help="output folder")
    e.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.add_argument(
        "--record",
        default=None,
        metavar="PATH",
        help="record every mission to this SQLite store "
        "(a run each, labelled zones= strategy= seed=); sensors.csv and runs.csv are then read "
        "back from it",
    )
    e.set_defaults(func=cmd_evaluate)
    w = sub.add_parser(
        "warmup",
        help="compile and cache the simulation kernels (done once; make install runs it)",
        description="Run every scenario with every scripted baseline, its variants (comms, pymunk), the\n"
        "batched and sharded envs, on small configs and for a few steps: this compiles every numba kernel\n"
        "the commands reach into the on-disk cache, so later runs start at once.",
    )
    w.add_argument("--quiet", action="store_true", help="print only the compile notice")
    w.set_defaults(func=cmd_warmup)
    from agentsim_env.train.cli import add_train_command

    add_train_command(sub)
    from agentsim_env.cli_replay import add_replay_command

    add_replay_command(sub)
    from agentsim_env.cli_store import add_store_commands

    add_store_commands(sub)
    from agentsim_env.cli_view import add_view_commands

    add_view_commands(sub, SET_HELP, announce_compile)
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
