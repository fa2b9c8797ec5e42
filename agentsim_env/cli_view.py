"""``agentsim view`` (the 3D web viewer, live or replaying a store) and ``agentsim zones`` (design, check).

``agentsim_env.cli.build_parser`` registers both with :func:`add_view_commands`. The viewer and the designer are
``agentsim_env.render.web``; replay is ``agentsim_env.recorder.web_replay``. Both serve on 127.0.0.1 unless
``--host`` says otherwise, print the page's URL and run until Ctrl-C (or ``--episodes`` / ``--steps``).
"""

from __future__ import annotations

import argparse
import sys
import threading
import webbrowser
from typing import Any

VIEW_EPILOG = """\
examples:
  agentsim view navigation --set n_agents=40
  agentsim view uav_release --policy B5_cvt
  agentsim view relay --speed 5                      (5 steps per second; 0 = as fast as it runs)
  agentsim view navigation --policy outputs/train/navigation
  agentsim view --replay runs.db --episode 0         (play / pause / step / speed / time slider)
  agentsim view --replay runs.db --episode 0 --out replay.mp4   (the 3D view as a video, headless Chromium)
open the printed URL in a browser; Ctrl-C stops. See docs/viewer.md."""

ZONES_EPILOG = """\
examples:
  agentsim zones design my_zones.json    draw zones on the map; Save writes my_zones.json (only that file)
  agentsim zones design                  start from the default zones; nothing is written (Download instead)
  agentsim zones check my_zones.json     validate a zone file, list its zones, check the default fleet carries them
  agentsim zones check my_zones.json --set n_uavs=6    ... for another fleet
then: agentsim evaluate --zones my_zones.json --strategies B5_cvt"""


def _check_network(args: argparse.Namespace) -> None:
    if not isinstance(args.port, int) or not 0 <= args.port <= 65535:
        raise ValueError(f"--port must be an integer in 0..65535 (0: a free port), got {args.port}")
    if not args.host:
        raise ValueError("--host must be an address such as 127.0.0.1 (this machine only) or 0.0.0.0")


def cmd_view(args: argparse.Namespace) -> int:
    """Run a scenario with a policy and stream it to the page, or replay a store."""
    _check_network(args)
    if args.speed is not None:
        from agentsim_env.render.web.viewer import SPEED_RANGE, speed_ok

        if not speed_ok(args.speed):
            raise ValueError(f"--speed must be {SPEED_RANGE}, got {args.speed}")
    export = [f"--{n}" for n in ("fps", "size", "every") if getattr(args, n) is not None]
    if (args.out is None or not args.replay) and (export or args.out is not None):
        raise ValueError(
            f"{' '.join(export or ['--out'])}: --out exports a replay to a video; give --replay RUN.db "
            "--out VIDEO.mp4"
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
    _warn_host(args.host)
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


def _warn_host(host: str, what: str = "watch and control the simulation") -> None:
    if host not in ("127.0.0.1", "localhost", "::1"):
        print(
            f"agentsim: WARNING: serving on {host}: any machine that reaches it can {what} (there is no "
            "authentication)",
            file=sys.stderr,
        )


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
    _warn_host(args.host)
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


def cmd_zones_design(args: argparse.Namespace) -> int:
    """Serve the hot-zone designer until Ctrl-C."""
    _check_network(args)
    from agentsim_env.uav.designer import run_designer

    _warn_host(args.host, "edit and save the zones")
    run_designer(args.file, host=args.host, port=args.port, open_browser=args.open)
    return 0


def cmd_zones_check(args: argparse.Namespace) -> int:
    """Validate a zone file; print its zones and whether the fleet carries their sensors.

    The fleet is the ``uav_release`` default, or the ``--set`` values (checked as ``agentsim run`` checks them,
    with these zones); a fleet that cannot carry every sensor ends the check with one error line (exit 2).
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


def _network_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind; anything but 127.0.0.1 is reachable "
        "from other machines (a warning is printed)",
    )
    p.add_argument("--port", type=int, default=0, help="port (0: a free one)")
    p.add_argument("--open", action="store_true", help="open the page in the default browser")


def add_view_commands(sub: Any, set_help: str, announce: Any) -> None:
    """Register ``agentsim view`` and ``agentsim zones`` on the subparsers action ``sub``.

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
    v.add_argument(
        "scenario", nargs="?", metavar="SCENARIO", help="a registered scenario ('agentsim scenarios')"
    )
    v.add_argument(
        "--policy", default=None, help="baseline name (default: the scenario's first) or a trained model"
    )
    v.add_argument("--set", nargs="*", metavar="KEY=VALUE", help=set_help)
    v.add_argument("--seed", type=int, default=0, help="seed of the first episode")
    v.add_argument(
        "--speed",
        type=float,
        default=None,
        help="steps per second, 0.1..10000 (default: real time; 0: as fast as it runs)",
    )
    v.add_argument(
        "--episodes", type=int, default=None, help="stop after this many episodes (default: run on)"
    )
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
        help="replay: write the 3D view to VIDEO (.mp4 or .gif) "
        "through headless Chromium instead of serving it",
    )
    v.add_argument("--fps", type=float, default=None, help="--out: frames per second (default: real time)")
    v.add_argument(
        "--size", type=int, default=None, help="--out: video width in pixels, 160..1920 (16:9; 960)"
    )
    v.add_argument(
        "--every", type=int, default=None, help="--out: draw every K-th recorded step (and the last)"
    )
    _network_options(v)
    v.set_defaults(func=cmd_view, announce=announce)
    z = sub.add_parser(
        "zones",
        help="hot-zone files: the designer page, or a check",
        description="Design hot zones in the browser, or check a zone file (docs/zones.md).",
        epilog=ZONES_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    zsub = z.add_subparsers(dest="zones_command", required=True, metavar="ACTION")
    d = zsub.add_parser("design", help="the hot-zone designer page (saves only to FILE)")
    d.add_argument(
        "file", nargs="?", default=None, metavar="FILE", help="zone file to edit (created on Save)"
    )
    _network_options(d)
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


__all__ = ["add_view_commands", "cmd_view", "cmd_zones_check", "cmd_zones_design"]
