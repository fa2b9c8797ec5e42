"""The ``agentsim`` command.

Subcommands:
    run        roll out a scenario's scripted baseline (batch, or live with --render), print a summary table,
               draw the first episode's trajectories as PNG (named by scenario, policy, seed and --set values)
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
import hashlib
import os
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env import _compile_notice
from agentsim_env.cli_set import canonical, parse_set
from agentsim_env.outdirs import prepare_out, remove_created

#: File in the numba cache directory whose content (versions) says the kernels were compiled and cached.
WARM_MARKER = ".agentsim-kernels-warm"
COMPILE_NOTICE = "agentsim: compiling simulation kernels (first run only, ~30 s)..."
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

    def __init__(self, *args: Any, lazy: Callable[[argparse.ArgumentParser], None] | None = None,
                 **kwargs: Any) -> None:  # fmt: skip
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
    lines = [_wrap(n, [f"{b} (default)" if i == 0 else b for i, b in enumerate(BASELINES.get(n, []))] or ["-"])
             for n in names]  # fmt: skip
    p.epilog = "baselines per scenario (--policy):\n" + "\n".join(lines) + "\n\n" + (p.epilog or "")


def _fill_evaluate(p: argparse.ArgumentParser) -> None:
    from agentsim_env.evaluation.runner import TELEPORT, available_strategies

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


# -------------------------------------------------------------------------------------------- checks

def _check_count(option: str, value: int) -> None:
    """Raise unless ``value`` is an integer >= 1 (episodes, seeds)."""
    if value < 1:
        raise ValueError(f"{option} must be an integer >= 1, got {value}")


def config_tag(config: dict[str, Any]) -> str:
    """``""`` without config values, else ``"_"`` + 6 hex digits of their canonical text (for file names)."""
    if not config:
        return ""
    return "_" + hashlib.sha1(canonical(config).encode()).hexdigest()[:6]


# ------------------------------------------------------------------------------------- kernel cache
def _kernel_cache_dir() -> Path | None:
    """The directory numba caches the package's kernels in (None: no writable one is known)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if chosen:
        return Path(chosen)
    from agentsim_env._numba_cache import PACKAGE_DIR, in_tree_writable

    if in_tree_writable():
        return Path(PACKAGE_DIR) / "__pycache__"
    try:
        from numba.misc.appdirs import AppDirs
    except ImportError:
        return None
    return Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)


def _stamp() -> str:
    """What the warm marker records: the versions that decide whether numba's cache is reused."""
    from importlib.metadata import PackageNotFoundError, version

    import agentsim_env

    try:
        numba_version = version("numba")
    except PackageNotFoundError:
        numba_version = "?"
    py = ".".join(map(str, sys.version_info[:2]))
    return f"agentsim_env {agentsim_env.__version__} numba {numba_version} python {py}\n"


def kernels_cold() -> bool:
    """Whether the numba kernel cache looks cold (no warm marker with the current versions)."""
    d = _kernel_cache_dir()
    if d is None:
        return True
    try:
        return (d / WARM_MARKER).read_text(encoding="utf-8") != _stamp()
    except OSError:
        return True


def announce_compile() -> bool:
    """Print the one-line compile notice to stderr when the kernel cache is cold; return whether it was."""
    cold = kernels_cold()
    if cold and not _compile_notice.quiet():  # AGENTSIM_QUIET_COMPILE=1 silences both notices
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)
        _compile_notice.mark_shown()  # the library's own notice (on an actual compilation) would repeat it
    return cold


def mark_warm() -> None:
    """Record that the kernels are compiled and cached (silently skipped where the cache is not writable)."""
    d = _kernel_cache_dir()
    if d is None:
        return
    try:
        d.mkdir(parents=True, exist_ok=True)
        (d / WARM_MARKER).write_text(_stamp(), encoding="utf-8")
    except OSError:
        pass


# ------------------------------------------------------------------------------------------ commands
def _progress(it: Any, total: int, desc: str, enabled: bool) -> Any:
    if not enabled:
        return it
    from tqdm.auto import tqdm

    return tqdm(it, total=total, desc=desc, unit="ep")


BIG_WORLD = 10_000
"""Agents from which ``agentsim run`` shows its progress in steps rather than episodes."""


def _step_bar(total: int, desc: str) -> Any:
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="step")


def _observers(recorder: Any, bar: Any, check: Callable[[], None] | None = None) -> Any:
    """One ``run_episode`` observer: the trajectory recorder, a step bar and a stop check (each may be None)."""
    if bar is None and check is None:
        return recorder

    def on_step(env: Any, infos: dict[str, Any]) -> None:
        if recorder is not None:
            recorder(env, infos)
        if bar is not None and int(env.world.step_count[0]):  # not the call right after the reset
            bar.update(1)
        if check is not None:  # a live run stops here, between steps, when SIGTERM or Ctrl-C asked it to
            check()

    return on_step


class _AgentSteps:
    """A ``run_episode`` observer counting agent-steps (the agents that acted in each step), then passing on."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.n = 0

    def __call__(self, env: Any, infos: dict[str, Any]) -> None:
        self.n += len(infos)
        if self.inner is not None:
            self.inner(env, infos)


def _rollout_row(
    env: Any, policy: Any, seed: int, recorder: Any, bar: Any, check: Callable[[], None] | None
) -> tuple:
    """One episode through ``env.rollout`` (arrays, no per-step dicts): a row of the run's summary table."""

    def on_step(env: Any, step: int, view: Any) -> None:
        if recorder is not None:  # the trajectory PNG's positions and outcomes, from the step's arrays
            recorder.on_rollout(env, step, view)
        if bar is not None and step:  # step 0: the reset
            bar.update(1)
        if check is not None:  # a stop asked for by SIGTERM or Ctrl-C ends the run here, between steps
            check()

    res = env.rollout(policy, env.scenario.max_steps, seed=seed, on_step=on_step)
    return (seed, res.steps, float(np.mean(res.returns)), res.info_sums, res.steps_per_s, res.agent_steps_per_s)


def _check_record(path: str | None) -> None:
    """Fail before any rollout when ``--record PATH`` cannot be recorded to (``recorder.schema.check_store_path``)."""
    if not path:
        return
    from agentsim_env.recorder.schema import StoreError, check_store_path

    try:
        check_store_path(path)
    except StoreError as exc:
        raise ValueError(f"--record {exc}") from None


def cmd_run(args: argparse.Namespace) -> int:
    """Roll out the baseline over seeds; print success and return statistics; draw the first episode."""
    if args.episodes is None:  # a live window plays in real time: one episode unless more are asked for
        args.episodes = 1 if args.render else 5
    _check_count("--episodes", args.episodes)
    if args.seed < 0:
        raise ValueError(f"--seed must be an integer >= 0, got {args.seed}")
    if args.fps is not None and args.fps <= 0:
        raise ValueError(f"--fps must be an integer > 0, got {args.fps}")
    shards = getattr(args, "shards", None)
    if shards is not None and shards < 1:
        raise ValueError(f"--shards must be an integer >= 1, got {shards}")
    threads = getattr(args, "threads", 1)
    if threads < 1 or threads > 256:
        raise ValueError(f"--threads must be an integer in [1, 256], got {threads}")
    if threads != 1 and shards is not None:
        raise ValueError("--threads applies to one process; with --shards each shard runs one thread")
    if getattr(args, "ray_address", None) is not None and shards is None:
        raise ValueError("--ray-address needs --shards K (the number of shard processes)")
    from agentsim_env.scenarios.registry import scenario_class

    config = parse_set(scenario_class(args.scenario).config_cls, args.set or [])
    from agentsim_env.policies.registry import resolve_policy

    policy_name, config = resolve_policy(args.scenario, args.policy, config)
    if args.render:
        from agentsim_env.cli_live import check_display

        check_display(args.scenario)
    _check_record(getattr(args, "record", None))
    created = prepare_out(args.out) if args.out else []
    try:
        return _run(args, config, policy_name)
    except KeyboardInterrupt:  # before the first step: one line, not a traceback
        remove_created(created)
        print("agentsim: stopped by Ctrl-C", file=sys.stderr)
        return 130
    except BaseException:
        remove_created(created)
        raise


def _run(args: argparse.Namespace, config: dict[str, Any], policy_name: str) -> int:
    import agentsim_env
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.policies.rollout import run_episode
    from agentsim_env.render.trajectories import TrajectoryRecorder, plot_trajectories

    announce_compile()
    mode = "human" if args.render else None
    if getattr(args, "shards", None) is not None:
        from agentsim_env.distributed import make as make_sharded

        env = make_sharded(args.scenario, shards=args.shards, ray_address=args.ray_address, render_mode=mode, **config)
        print(f"{args.scenario}: {args.shards} shards ({env.coordinator.backend.address}), halo "
              f"{env.coordinator.strips.halo:.1f} m", flush=True)  # fmt: skip
    else:
        env = agentsim_env.make(args.scenario, render_mode=mode, num_threads=getattr(args, "threads", 1), **config)
    if args.fps is not None:
        env.metadata["render_fps"] = args.fps  # the live window paces itself with this rate
    store = getattr(args, "record", None)
    if store:  # every episode of the rollout, in one run of the store
        from agentsim_env.recorder import record

        label = f"agentsim run {args.scenario} --policy {policy_name} --seed {args.seed} --episodes {args.episodes}"
        env = record(env, store, label=label + (" --set " + " ".join(args.set) if args.set else ""))
        store_run = env.recorder.run
    policy = make_policy(args.scenario, env, policy_name)
    rows = []
    traj = None
    # large worlds: a bar over steps (an episode of 100,000 agents takes minutes), else over episodes
    bar = _step_bar(args.episodes * env.scenario.max_steps, args.scenario) if (
        env.scenario.n_agents >= BIG_WORLD and not args.quiet) else None  # fmt: skip
    episodes = range(args.episodes) if bar is not None else _progress(range(args.episodes), args.episodes,
                                                                      args.scenario, not args.quiet)  # fmt: skip
    from agentsim_env.cli_live import LiveStop, StopRun, as_stop, is_stop, stop_line

    halt: StopRun | None = None
    try:
        with LiveStop() as live:  # SIGTERM and Ctrl-C end the run between two steps (a second one at once)
            for k in episodes:
                recorder = TrajectoryRecorder() if k == 0 and args.out else None
                if not args.render and not store:  # nothing needs per-step dicts
                    # over shards each shard builds the policy by its name (no object crosses to them)
                    who = policy_name if getattr(args, "shards", None) is not None else policy
                    rows.append(_rollout_row(env, who, args.seed + k, recorder, bar, live.check))
                    if recorder is not None:
                        traj = recorder.result(env)
                    continue
                counted = _AgentSteps(_observers(recorder, bar, live.check))
                t0 = time.perf_counter()
                ep = run_episode(env, policy, args.seed + k, on_step=counted)
                wall = time.perf_counter() - t0
                if recorder is not None:
                    traj = recorder.result(env)
                rows.append((ep.seed, ep.steps, float(np.mean(list(ep.returns.values()))), ep.info_sums,
                             ep.steps / wall, counted.n / wall))  # fmt: skip
    except BaseException as exc:
        if store:
            env.recorder.finish("incomplete")
        if not is_stop(exc):
            raise
        halt = as_stop(exc)  # the window closed, SIGTERM or Ctrl-C: report the episodes that ended
    if bar is not None:
        bar.total = bar.n
        bar.close()
    mark_warm()
    n = env.scenario.n_agents
    keys = sorted({k for r in rows for k in r[3] if k in ("arrived", "collided", "released", "landed")})
    if rows:  # none when a live run was stopped during its first episode
        print(f"\n{args.scenario}: {len(rows)} episodes x {n} agents, policy={policy_name}")
        print("| metric | mean | std |")
        print("|---|---|---|")
        print(f"| steps | {np.mean([r[1] for r in rows]):.1f} | {np.std([r[1] for r in rows]):.1f} |")
        print(f"| mean return | {np.mean([r[2] for r in rows]):.2f} | {np.std([r[2] for r in rows]):.2f} |")
        for key in keys:
            frac = np.array([r[3].get(key, 0.0) / n for r in rows])
            print(f"| {key} per agent | {frac.mean():.3f} | {frac.std():.3f} |")
        print(f"| env-steps/s | {np.mean([r[4] for r in rows]):.1f} | {np.std([r[4] for r in rows]):.1f} |")
        print(f"| agent-steps/s | {np.mean([r[5] for r in rows]):.0f} | {np.std([r[5] for r in rows]):.0f} |")
    if traj is not None:
        shown = Path(policy_name).name.removesuffix(".zip") or "model"  # a model path: its folder's name
        # HASH names the --set values only: a trained model's own env config is named by the model's folder
        from agentsim_env.scenarios.registry import scenario_class

        given = parse_set(scenario_class(args.scenario).config_cls, args.set or [])
        name = f"{args.scenario}_{shown}_seed{args.seed}{config_tag(given)}.png"
        title = f"{args.scenario} | policy {policy_name} | seed {args.seed} | {traj.steps} steps"
        if args.set:
            title += "\n" + textwrap.shorten(" ".join(args.set), 110, placeholder=" ...")
        path = plot_trajectories(traj, Path(args.out) / name, title)
        print(f"trajectories written to {path}")
    env.close()
    if store:
        failed = env.recorder.error
        stopped = f"; recording stopped early: {failed}" if failed else ""
        print(f"recorded to {store} (run {store_run}){stopped}")
    if halt is not None:
        print(stop_line(halt, len(rows), args.episodes, store, store_run if store else None), file=sys.stderr)
        return halt.code
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
        if min(values) < 0:
            raise ValueError(f"--seeds must be integers >= 0, got {min(values)}")
        return list(dict.fromkeys(values))
    if values[0] < 1:
        raise ValueError(f"--seeds N must be >= 1 (or give a list such as 0,4,9), got {values[0]}")
    return list(range(values[0]))


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Fly every strategy over every zone file and seed; write CSVs, plots and the Markdown ranking.

    Nothing is written unless every run succeeds (see ``agentsim_env.evaluation.report``); the output folder
    is created and probed before the first run, and removed again (when still empty) if a run fails.
    """
    from agentsim_env.evaluation.report import ranking_table, write_outputs
    from agentsim_env.evaluation.runner import resolve_strategies, resolve_zones, run_grid
    from agentsim_env.evaluation.scoring import rank_strategies, run_rows
    from agentsim_env.scenarios.registry import scenario_class

    # validate the cheap inputs before the first (slow) run
    seeds = _parse_seeds(args.seeds)
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

            grid = run_grid(args.zones, args.strategies, seeds, overrides, progress=not args.quiet,
                            record_env=record_env)  # fmt: skip
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
    r.add_argument("--episodes", type=int, default=None, help="episodes (seeds SEED, SEED+1, ...), >= 1 "
                   "(default: 5; 1 with --render)")  # fmt: skip
    r.add_argument("--seed", type=int, default=0, help="seed of the first episode, >= 0")
    r.add_argument("--policy", default=None, help="baseline name (default: the scenario's first; see below) or "
                   "a trained model (a folder from 'agentsim train', or its .zip)")  # fmt: skip
    r.add_argument("--set", nargs="*", metavar="KEY=VALUE", help=SET_HELP)
    r.add_argument("--render", action="store_true", help="show a live window, in real time unless --fps is "
                   "given (needs a display); closing it, Esc, SIGTERM or Ctrl-C end the run")  # fmt: skip
    r.add_argument("--fps", type=int, default=None, help="frames per second of the live window, > 0 "
                   "(default: real time)")  # fmt: skip
    r.add_argument("--out", default="outputs", help="folder for the trajectory PNG ('' for none)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--record", default=None, metavar="PATH", help="record every episode to this SQLite store "
                   "(one run; created when missing; see 'agentsim runs')")  # fmt: skip
    r.add_argument("--shards", type=int, default=None, metavar="K", help="run the simulation over K shard "
                   "processes on Ray (navigation, relay; see docs/distributed.md)")  # fmt: skip
    r.add_argument("--ray-address", default=None, metavar="ADDR", help="with --shards: a Ray cluster's "
                   "host:port (default: a local cluster on 127.0.0.1)")  # fmt: skip
    r.add_argument("--threads", type=int, default=1, metavar="N", help="threads for the per-agent kernels "
                   "(scan, collisions, motion; worth it from tens of thousands of agents; same results)")  # fmt: skip
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
    e.add_argument("--zones", nargs="+", default=["default"], metavar="ZONES",
                   help="zone files: 'default', 'tiny' or JSON paths (several allowed)")  # fmt: skip
    e.add_argument("--strategies", nargs="+", default=["all"], metavar="NAME",
                   help="release strategies (see below), or 'all'")  # fmt: skip
    e.add_argument("--seeds", nargs="+", default=["3"], metavar="SEED",
                   help="a count N >= 1 (seeds 0..N-1) or a list: 0,4,9 or 0 4 9 (one seed: 7,)")  # fmt: skip
    e.add_argument(
        "--set", nargs="*", metavar="KEY=VALUE", help="uav_release " + SET_HELP + "; for every run"
    )
    e.add_argument("--out", default="outputs/evaluation", help="output folder")
    e.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.add_argument("--record", default=None, metavar="PATH", help="record every mission to this SQLite store "
                   "(a run each, labelled zones= strategy= seed=); sensors.csv and runs.csv are then read "
                   "back from it")  # fmt: skip
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
