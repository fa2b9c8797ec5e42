"""``agentsim run``: roll out a scenario's baseline (or a trained model) over episodes, print the summary table
(steps, mean return, outcomes, env-steps/s and agent-steps/s) and draw the first episode's trajectories.

Episodes run through ``env.rollout`` (arrays; over ``--shards`` the policy runs inside the shards) unless a live
window (``--render``) or a store (``--record``) needs every step's dicts. SIGTERM and Ctrl-C end the run between
two steps with a report of the episodes that ended.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.cli_kernels import announce_compile, mark_warm
from agentsim_env.cli_set import canonical, parse_set
from agentsim_env.outdirs import prepare_out, remove_created


def check_count(option: str, value: int) -> None:
    """Raise unless ``value`` is an integer >= 1 (episodes, seeds)."""
    if value < 1:
        raise ValueError(f"{option} must be an integer >= 1, got {value}")


def config_tag(config: dict[str, Any]) -> str:
    """``""`` without config values, else ``"_"`` + 6 hex digits of their canonical text (for file names)."""
    if not config:
        return ""
    return "_" + hashlib.sha1(canonical(config).encode()).hexdigest()[:6]


def progress(it: Any, total: int, desc: str, enabled: bool) -> Any:
    """``it`` with a progress bar over episodes (tqdm), or ``it`` itself when not ``enabled``."""
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


def _rollout_row(env: Any, policy: Any, seed: int, recorder: Any, bar: Any, check: Callable[[], None] | None) -> tuple:
    """One episode through ``env.rollout`` (arrays, no per-step dicts): a row of the run's summary table."""

    def on_step(env: Any, step: int, view: Any) -> None:
        if recorder is not None:  # the trajectory PNG's positions and outcomes, from the step's arrays
            recorder.on_rollout(env, step, view)
        if bar is not None and step:  # step 0: the reset
            bar.update(1)
        if check is not None:  # a stop asked for by SIGTERM or Ctrl-C ends the run here, between steps
            check()

    res = env.rollout(policy, env.scenario.max_steps, seed=seed, on_step=on_step)
    return (
        seed,
        res.steps,
        float(np.mean(res.returns)),
        res.info_sums,
        res.steps_per_s,
        res.agent_steps_per_s,
    )


def check_record(path: str | None) -> None:
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
    check_count("--episodes", args.episodes)
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
    check_record(getattr(args, "record", None))
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
        print(
            f"{args.scenario}: {args.shards} shards ({env.coordinator.backend.address}), halo "
            f"{env.coordinator.strips.halo:.1f} m",
            flush=True,
        )
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
    bar = (
        _step_bar(args.episodes * env.scenario.max_steps, args.scenario)
        if (env.scenario.n_agents >= BIG_WORLD and not args.quiet)
        else None
    )
    episodes = (
        range(args.episodes)
        if bar is not None
        else progress(range(args.episodes), args.episodes, args.scenario, not args.quiet)
    )
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
                rows.append(
                    (
                        ep.seed,
                        ep.steps,
                        float(np.mean(list(ep.returns.values()))),
                        ep.info_sums,
                        ep.steps / wall,
                        counted.n / wall,
                    )
                )
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
