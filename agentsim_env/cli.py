"""The ``agentsim`` command.

Subcommands:
    run        roll out a scenario's scripted baseline (batch, or live with --render), print a summary table,
               draw the first episode's trajectories as PNG (named by scenario, policy, seed and --set values)
               (``cli_run``)
    scenarios  list the registered scenarios
    warmup     compile and cache every simulation kernel the commands reach (``agentsim_env.warmup``);
               ``make install`` runs it
    view       the 3D web viewer: a live run with a policy, or a replay from the store (``cli_view``)
    train, replay, export, runs   (``agentsim_env.train.cli``, ``cli_replay``, ``cli_store``)
    benchmark-rl  the learning benchmark: scenarios x algorithms x seeds beside the baselines
               (``agentsim_env.train.learnbench_cli``)
    evaluate   batch evaluation of the UAV sensor-release strategies (zone files x strategies x seeds):
               sensors.csv, runs.csv, summary.md (ranking) and PNG plots (``agentsim_env.uav.cli``)
    zones      the hot-zone designer page, and a zone-file check (``agentsim_env.uav.cli``)

The UAV case study's subcommands come from ``SUBCOMMAND_PROVIDERS`` (``"module:function"`` strings), so this
module names no UAV function.

``--set KEY=VALUE`` values are parsed by the type of the config field they set (``agentsim_env.cli_set``).
Bad input (counts, folders, config values) ends with one ``agentsim: error: ...`` line and exit code 2, before
any rollout. Help texts that need the registries are built only when shown, so ``agentsim --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import textwrap
from collections.abc import Callable
from typing import Any

from agentsim_env.cli_kernels import COMPILE_NOTICE, WARM_MARKER, announce_compile, kernels_cold, mark_warm
from agentsim_env.cli_run import cmd_run, config_tag
from agentsim_env.outdirs import prepare_out

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
    from agentsim_env.policies.registry import scenario_policies

    names = agentsim_env.list_scenarios()
    _action(p, "scenario").help = f"one of: {', '.join(names)}"
    lines = [
        _wrap(n, [f"{b} (default)" if i == 0 else b for i, b in enumerate(scenario_policies(n))] or ["-"])
        for n in names
    ]
    p.epilog = "baselines per scenario (--policy):\n" + "\n".join(lines) + "\n\n" + (p.epilog or "")


RUN_EPILOG = """\
The PNG of the first episode is OUT/SCENARIO_POLICY_seedSEED[_HASH].png, HASH being 6 hex digits of the --set
values (none without --set), so different configs do not overwrite each other.

examples:
  agentsim run navigation --episodes 20
  agentsim run navigation --policy random --set n_agents=8 collisions=false body.max_speed=8
  agentsim run relay --set gap=12,20 comms.loss=0.1 --out outputs/relay
  agentsim run uav_release --set zones=tiny n_uavs=2 --episodes 1 --render"""
MAIN_EPILOG = """\
examples:
  agentsim scenarios
  agentsim run navigation --episodes 20 --set n_agents=8
  agentsim evaluate --zones default --strategies all --seeds 3
  agentsim train navigation
  agentsim warmup
Run 'agentsim COMMAND --help' for a command's options."""


#: The packages that add their own subcommands: ``"module:function"`` of a function ``(sub, set_help) -> None``
#: registering them on the subparsers action ``sub`` (whose parsers take ``lazy=``, a filler of help texts run
#: only when the help is shown). Named by strings, so the generic command line imports none of them until the
#: parser is built; the module must import nothing heavy at its top (``agentsim --help`` stays fast).
SUBCOMMAND_PROVIDERS: tuple[str, ...] = ("agentsim_env.uav.cli:add_commands",)


def _provider(spec: str) -> Callable[[Any, str], None]:
    """The function a ``"module:function"`` entry of ``SUBCOMMAND_PROVIDERS`` names."""
    module, sep, attr = spec.partition(":")
    if not sep or not module or not attr:
        raise ValueError(f"subcommand provider {spec!r}: expected 'module:function'")
    fn: Callable[[Any, str], None] = getattr(importlib.import_module(module), attr)
    return fn


# ------------------------------------------------------------------------------------------ commands
def cmd_scenarios(args: argparse.Namespace) -> int:
    """Print the registered scenarios with the first line of their documentation."""
    from agentsim_env.scenarios.registry import scenario_class, usable_scenarios

    for name in usable_scenarios():  # a plug-in that does not load is left out (with a warning)
        mod = sys.modules[scenario_class(name).__module__]
        print(f"{name:14s} {(mod.__doc__ or '').strip().splitlines()[0]}")
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
    p = _LazyParser(prog="agentsim", description="agentsim-env command line", epilog=MAIN_EPILOG, lazy=_fill_main)
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
    from agentsim_env.train.learnbench_cli import add_benchmark_rl_command

    add_benchmark_rl_command(sub)
    from agentsim_env.cli_replay import add_replay_command

    add_replay_command(sub)
    from agentsim_env.cli_store import add_store_commands

    add_store_commands(sub)
    from agentsim_env.cli_view import add_view_commands

    add_view_commands(sub, SET_HELP, announce_compile)
    for spec in SUBCOMMAND_PROVIDERS:
        _provider(spec)(sub, SET_HELP)
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
