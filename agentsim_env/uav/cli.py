"""The case study's subcommands: ``agentsim evaluate`` (every release strategy over zone files and seeds) and
``agentsim zones`` (the designer page, and a zone-file check).

``agentsim_env.cli`` adds them through its list of subcommand providers (``"agentsim_env.uav.cli:add_commands"``),
so the generic command line names no UAV function. Everything heavy is imported inside the commands:
registering them keeps ``agentsim --help`` fast.
"""

from __future__ import annotations

import argparse
import textwrap
from typing import Any

from agentsim_env.render.web.bind import check_network, network_options, warn_host

__all__ = [
    "EVALUATE_EPILOG",
    "ZONES_EPILOG",
    "add_commands",
    "cmd_evaluate",
    "cmd_zones_check",
    "cmd_zones_design",
    "parse_seeds",
]

EVALUATE_EPILOG = """\
examples:
  agentsim evaluate --zones default --strategies all --seeds 3
  agentsim evaluate --zones tiny my_zones.json --strategies B2_rings B5_cvt --seeds 0,4,9 \\
      --set n_uavs=2 payload=10 wind.mean_speed=3 --out outputs/eval_tiny"""

ZONES_EPILOG = """\
examples:
  agentsim zones design my_zones.json    draw zones on the map; Save writes my_zones.json (only that file)
  agentsim zones design                  start from the default zones; nothing is written (Download instead)
  agentsim zones check my_zones.json     validate a zone file, list its zones, check the default fleet carries them
  agentsim zones check my_zones.json --set n_uavs=6    ... for another fleet
then: agentsim evaluate --zones my_zones.json --strategies B5_cvt"""


# ------------------------------------------------------------------------------------------ evaluate
def _fill_evaluate(p: argparse.ArgumentParser) -> None:
    """The epilog listing the release strategies (filled when help is shown: it imports the registry)."""
    from agentsim_env.uav.evaluation.runner import TELEPORT, available_strategies

    listed = textwrap.fill(", ".join(available_strategies()), 100, initial_indent="  ", subsequent_indent="  ")
    p.epilog = (
        f"release strategies (--strategies):\n{listed}\n  (the {TELEPORT} reference, placed without flying, is "
        f"always added;\n  the flown {TELEPORT} strategy is labelled {TELEPORT}_flown)\n\n" + (p.epilog or "")
    )


def parse_seeds(tokens: list[str]) -> list[int]:
    """The seeds of ``--seeds``: ``N`` (one number: seeds 0..N-1) or an explicit list.

    Args:
        tokens: The option's words: ``["3"]``, ``["0,4,9"]``, ``["0", "4", "9"]`` or ``["7,"]`` (one seed).

    Returns:
        The seeds, duplicates dropped, in the order given.

    Raises:
        ValueError: If a word is not an integer, nothing is given, a listed seed is negative or ``N < 1``.
    """
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


def _check_record(path: str | None) -> None:
    """Fail before the first run when ``--record PATH`` cannot be recorded to."""
    if not path:
        return
    from agentsim_env.recorder.schema import StoreError, check_store_path

    try:
        check_store_path(path)
    except StoreError as exc:
        raise ValueError(f"--record {exc}") from None


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Fly every strategy over every zone file and seed; write CSVs, plots and the Markdown ranking.

    Nothing is written unless every run succeeds (see ``agentsim_env.uav.evaluation.report``); the output folder
    is created and probed before the first run, and removed again (when still empty) if a run fails.

    Args:
        args: The parsed ``agentsim evaluate`` arguments.

    Returns:
        The exit code, 0.
    """
    from agentsim_env.cli_kernels import announce_compile, mark_warm
    from agentsim_env.cli_set import parse_set
    from agentsim_env.outdirs import prepare_out, remove_created
    from agentsim_env.scenarios.registry import scenario_class
    from agentsim_env.uav.evaluation.report import ranking_table, write_outputs
    from agentsim_env.uav.evaluation.runner import resolve_strategies, resolve_zones, run_grid
    from agentsim_env.uav.evaluation.scoring import rank_strategies, run_rows

    # validate the cheap inputs before the first (slow) run
    seeds = parse_seeds(args.seeds)
    overrides = parse_set(scenario_class("uav_release").config_cls, args.set or [])
    resolve_zones(args.zones)
    resolve_strategies(args.strategies)
    store = getattr(args, "record", None) or None
    _check_record(store)
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


# --------------------------------------------------------------------------------------------- zones
def cmd_zones_design(args: argparse.Namespace) -> int:
    """Serve the hot-zone designer until Ctrl-C.

    Args:
        args: The parsed ``agentsim zones design`` arguments.

    Returns:
        The exit code, 0.
    """
    check_network(args)
    from agentsim_env.uav.designer import run_designer

    warn_host(args.host, "edit and save the zones")
    run_designer(args.file, host=args.host, port=args.port, open_browser=args.open)
    return 0


def cmd_zones_check(args: argparse.Namespace) -> int:
    """Validate a zone file; print its zones and whether the fleet carries their sensors.

    The fleet is the ``uav_release`` default, or the ``--set`` values (checked as ``agentsim run`` checks them,
    with these zones); a fleet that cannot carry every sensor ends the check with one error line (exit 2).

    Args:
        args: The parsed ``agentsim zones check`` arguments.

    Returns:
        The exit code, 0.

    Raises:
        ValueError: If the file cannot be read or is invalid, ``--set`` is invalid or names the zones, or the
            fleet cannot carry every sensor.
    """
    from agentsim_env.cli_set import parse_set
    from agentsim_env.uav.capacity import capacity_text, default_fleet, fleet_capacity
    from agentsim_env.uav.config import UavReleaseConfig
    from agentsim_env.uav.zones import load_zones, overlaps

    overrides = parse_set(UavReleaseConfig, getattr(args, "set", None) or [])
    if "zones" in overrides:
        raise ValueError("--set zones=... is not allowed here: the zones are FILE's")
    try:
        zs = load_zones(args.file)
    except OSError as exc:
        raise ValueError(f"{args.file}: {exc.strerror or exc}") from None
    w, h = zs.map_size
    print(f"{args.file}: valid; map {w:g} x {h:g} m, {len(zs.zones)} zones, {zs.n_sensors} sensors")
    print("| # | name | centre | radius | sensors | profile | weight |")
    print("|---|---|---|---|---|---|---|")
    for i, z in enumerate(zs.zones):
        print(
            f"| {i} | {z.name or ''} | ({z.centre[0]:g}, {z.centre[1]:g}) | {z.radius:g} | {z.n_sensors} | "
            f"{z.profile} | {z.weight:g} |"
        )
    for i, j in overlaps(zs):
        print(f"note: zones {i} and {j} overlap")
    n_uavs, payload = default_fleet()
    cap = fleet_capacity(zs, overrides.get("n_agents", n_uavs), overrides.get("payload", payload))
    text = capacity_text(cap, "fleet (--set)" if overrides else "default fleet")
    if not cap["carried"]:
        raise ValueError(text)
    print(text)
    if overrides:  # the other values must build with these zones too
        UavReleaseConfig(**{**overrides, "zones": zs})
    return 0


# ---------------------------------------------------------------------------------------------- hook
def add_commands(sub: Any, set_help: str) -> None:
    """Register ``agentsim evaluate`` and ``agentsim zones`` (a subcommand provider of ``agentsim_env.cli``).

    Args:
        sub: The subparsers action of the ``agentsim`` parser; its parsers take ``lazy=`` (a function that fills
            help texts needing imports, run only when the help is shown).
        set_help: Help text of ``--set`` (how values are parsed).
    """
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
    e.add_argument("--set", nargs="*", metavar="KEY=VALUE", help="uav_release " + set_help + "; for every run")
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
    z = sub.add_parser(
        "zones",
        help="hot-zone files: the designer page, or a check",
        description="Design hot zones in the browser, or check a zone file (docs/zones.md).",
        epilog=ZONES_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    zsub = z.add_subparsers(dest="zones_command", required=True, metavar="ACTION")
    d = zsub.add_parser("design", help="the hot-zone designer page (saves only to FILE)")
    d.add_argument("file", nargs="?", default=None, metavar="FILE", help="zone file to edit (created on Save)")
    network_options(d)
    d.set_defaults(func=cmd_zones_design)
    c = zsub.add_parser("check", help="validate a zone file, list its zones and check the fleet carries them")
    c.add_argument("file", metavar="FILE", help="a zone file (JSON)")
    c.add_argument(
        "--set",
        nargs="*",
        metavar="KEY=VALUE",
        help="uav_release config values for the fleet "
        "(n_uavs=6 payload=50 ...; default: the scenario's defaults), checked with these zones",
    )
    c.set_defaults(func=cmd_zones_check)
