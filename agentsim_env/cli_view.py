"""``agentsim view``: the 3D web viewer, live or replaying a store.

``agentsim_env.cli.build_parser`` registers it with :func:`add_view_commands`. The viewer is
``agentsim_env.render.web``; replay is ``agentsim_env.recorder.web_replay``. It serves on 127.0.0.1 unless
``--host`` says otherwise (``render.web.bind``), prints the page's URL and runs until Ctrl-C (or ``--episodes`` /
``--steps``).
"""

from __future__ import annotations

import argparse
import sys
import threading
import webbrowser
from typing import Any

from agentsim_env.render.web.bind import check_network, network_options, warn_host

VIEW_EPILOG = """\
examples:
  agentsim view navigation --set n_agents=40
  agentsim view uav_release --policy B5_cvt
  agentsim view relay --speed 5                      (5 steps per second; 0 = as fast as it runs)
  agentsim view navigation --policy outputs/train/navigation
  agentsim view --replay runs.db --episode 0         (play / pause / step / speed / time slider)
  agentsim view --replay runs.db --episode 0 --out replay.mp4   (the 3D view as a video, headless Chromium)
open the printed URL in a browser; Ctrl-C stops. See docs/viewer.md."""


def cmd_view(args: argparse.Namespace) -> int:
    """Run a scenario with a policy and stream it to the page, or replay a store."""
    check_network(args)
    if args.speed is not None:
        from agentsim_env.render.web.viewer import SPEED_RANGE, speed_ok

        if not speed_ok(args.speed):
            raise ValueError(f"--speed must be {SPEED_RANGE}, got {args.speed}")
    export = [f"--{n}" for n in ("fps", "size", "every") if getattr(args, n) is not None]
    if (args.out is None or not args.replay) and (export or args.out is not None):
        raise ValueError(
            f"{' '.join(export or ['--out'])}: --out exports a replay to a video; give --replay RUN.db --out VIDEO.mp4"
        )
    if args.replay:
        if args.scenario or args.policy or args.set:
            raise ValueError("--replay plays a store: give no SCENARIO, --policy or --set with it")
        if args.out is not None:
            return _export(args)
        return _replay(args)
    if not args.scenario:
        raise ValueError("give a SCENARIO to run ('agentsim scenarios' lists them) or --replay RUN.db")
    for name in ("episodes", "steps"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise ValueError(f"--{name} must be an integer >= 1, got {v}")
    return _live(args)


def _replay(args: argparse.Namespace) -> int:
    from agentsim_env.recorder.web_replay import ReplayViewer

    viewer = ReplayViewer(
        args.replay,
        run=args.run,
        episode=args.episode or 0,
        world=args.world,
        host=args.host,
        port=args.port,
        speed=args.speed,
    )
    url = viewer.start()
    warn_host(args.host)
    if args.open:
        webbrowser.open(url)
    try:
        threading.Event().wait()  # until Ctrl-C
    except KeyboardInterrupt:
        pass
    finally:
        viewer.close()
    return 0


def _export(args: argparse.Namespace) -> int:
    from agentsim_env.recorder.web_video import DEFAULT_SIZE, export_replay_video

    if args.speed is not None:
        raise ValueError("--speed sets the pace of a live page; an exported video's rate is --fps")
    try:
        path, n = export_replay_video(
            args.replay,
            args.out,
            run=args.run,
            episode=args.episode or 0,
            world=args.world,
            fps=args.fps,
            size=DEFAULT_SIZE if args.size is None else args.size,
            every=1 if args.every is None else args.every,
            progress=True,
        )
    except KeyboardInterrupt:
        print("agentsim view: interrupted; no video written", file=sys.stderr)
        return 130
    print(f"written: {path} ({n} frames)")
    return 0


def _live(args: argparse.Namespace) -> int:
    import agentsim_env
    from agentsim_env.cli_set import parse_set
    from agentsim_env.policies.registry import make_policy, resolve_policy
    from agentsim_env.policies.rollout import run_episode
    from agentsim_env.render.web.viewer import WebViewer, clamp_speed
    from agentsim_env.scenarios.registry import scenario_class

    config = parse_set(scenario_class(args.scenario).config_cls, args.set or [])
    policy_name, config = resolve_policy(args.scenario, args.policy, config)
    args.announce()
    env = agentsim_env.make(args.scenario, **config)
    policy = make_policy(args.scenario, env, policy_name)
    speed = args.speed if args.speed is not None else clamp_speed(1.0 / env.world.config.dt)
    viewer = WebViewer(
        host=args.host,
        port=args.port,
        speed=speed,
        title=f"{args.scenario} | {policy_name}",
        quiet=True,
        wait=not args.no_wait,
    )
    url = viewer.attach(env.world, env.scenario)
    waits = "" if args.no_wait else "; it starts when the page opens"
    print(
        f"agentsim view: {args.scenario} with policy {policy_name} at {url}  (Ctrl-C stops{waits})",
        file=sys.stderr,
    )
    warn_host(args.host)
    if args.open:
        webbrowser.open(url)
    steps = 0

    def on_step(e: Any, infos: dict[str, Any]) -> None:
        nonlocal steps
        if not infos and e.world.step_count[0] == 0:
            viewer.new_episode()
        else:
            steps += 1
            if args.steps is not None and steps >= args.steps:
                raise KeyboardInterrupt

    try:
        k = 0
        while args.episodes is None or k < args.episodes:
            run_episode(env, policy, args.seed + k, on_step=on_step)
            k += 1
    except KeyboardInterrupt:
        pass
    finally:
        viewer.close()
        env.close()
    return 0


def add_view_commands(sub: Any, set_help: str, announce: Any) -> None:
    """Register ``agentsim view`` on the subparsers action ``sub``.

    Args:
        sub: The subparsers action of the ``agentsim`` parser.
        set_help: Help text of ``--set``.
        announce: Prints the one-line notice when kernels are about to be compiled (called before a live run).
    """
    v = sub.add_parser(
        "view",
        help="the 3D web viewer: a live simulation, or a replay from the store",
        description="Run SCENARIO with a policy and show it in 3D in the browser (log stream, pause,\n"
        "step, speed, click an agent), or replay a recorded episode with --replay.",
        epilog=VIEW_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    v.add_argument("scenario", nargs="?", metavar="SCENARIO", help="a registered scenario ('agentsim scenarios')")
    v.add_argument("--policy", default=None, help="baseline name (default: the scenario's first) or a trained model")
    v.add_argument("--set", nargs="*", metavar="KEY=VALUE", help=set_help)
    v.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    v.add_argument(
        "--speed",
        type=float,
        default=None,
        help="steps per second, 0.1..10000 (default: real time; 0: as fast as it runs)",
    )
    v.add_argument("--episodes", type=int, default=None, help="stop after this many episodes (default: run on)")
    v.add_argument("--steps", type=int, default=None, help="stop after this many steps (default: run on)")
    v.add_argument(
        "--no-wait",
        action="store_true",
        help="start the simulation at once (default: wait for the "
        "first page, so that it shows the episode from step 0)",
    )
    v.add_argument("--replay", default=None, metavar="RUN.db", help="replay an episode of this store instead")
    v.add_argument("--run", type=int, default=None, help="replay: run id (default: the last)")
    v.add_argument("--episode", type=int, default=None, help="replay: episode of the run (default: 0)")
    v.add_argument("--world", type=int, default=0, help="replay: world of a batched run")
    v.add_argument(
        "--out",
        default=None,
        metavar="VIDEO",
        help="replay: write the 3D view to VIDEO (.mp4 or .gif) through headless Chromium instead of serving it",
    )
    v.add_argument("--fps", type=float, default=None, help="--out: frames per second (default: real time)")
    v.add_argument("--size", type=int, default=None, help="--out: video width in pixels, 160..1920 (16:9; 960)")
    v.add_argument("--every", type=int, default=None, help="--out: draw every K-th recorded step (and the last)")
    network_options(v)
    v.set_defaults(func=cmd_view, announce=announce)


__all__ = ["add_view_commands", "cmd_view"]
