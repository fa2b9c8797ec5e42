"""``agentsim replay``: draw a recorded episode from a store as PNG frames, an MP4 or a GIF (no simulation).

``agentsim_env.cli.build_parser`` registers it with :func:`add_replay_command`. The drawing is
``agentsim_env.recorder.replay``; videos need the ``video`` extra (``pip install "agentsim-env[video]"``).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

REPLAY_EPILOG = """\
examples:
  agentsim replay run.db --episode 0 --out outputs/replay.mp4
  agentsim replay run.db --run 2 --episode 3 --world 1 --every 2 --fps 20 --out outputs/replay.gif
  agentsim replay run.db --episode 0 --out outputs/frames/        (frame_00000.png, frame_00001.png, ...)"""


def check_out(out: str) -> None:
    """Refuse an ``--out`` whose extension is neither a video format nor a folder's.

    A name such as ``x.avi`` would otherwise become a folder of PNG frames called ``x.avi``. A name ending in
    a path separator, or an existing folder, is a folder whatever its dots.

    Args:
        out: The ``--out`` value.

    Raises:
        ValueError: For an extension other than the supported video ones (the message lists them).
    """
    from agentsim_env.render.video import VIDEO_FORMATS

    path = Path(out)
    suffix = path.suffix.lower().lstrip(".")
    if not suffix or suffix in VIDEO_FORMATS or out.endswith(("/", os.sep)) or path.is_dir():
        return
    shown = ", ".join(f".{f}" for f in VIDEO_FORMATS)
    raise ValueError(
        f"--out {out!r}: unknown extension '.{suffix}'; supported: {shown} (a video), or a folder for PNG "
        f"frames (a name without an extension, or ending in '/')"
    )


def cmd_replay(args: argparse.Namespace) -> int:
    """Write the replay; print what was written.

    Missing packages for a video (an ``ImportError``) are reported as a ``ValueError`` with the same message, so
    the command ends with one ``agentsim: error:`` line and exit code 2.
    """
    from agentsim_env.recorder.replay import write_replay

    if args.fps is not None and not args.fps > 0:
        raise ValueError(f"--fps must be > 0, got {args.fps}")
    check_out(args.out)
    try:
        paths = write_replay(
            args.store,
            args.out,
            run=args.run,
            episode=args.episode,
            world=args.world,
            every=args.every,
            size=args.size,
            fps=args.fps,
        )
    except ImportError as exc:
        raise ValueError(str(exc)) from None
    if len(paths) == 1:
        print(f"written: {paths[0]}")
    else:
        print(f"written: {len(paths)} frames, {paths[0]} ... {paths[-1]}")
    return 0


def add_replay_command(sub: Any) -> argparse.ArgumentParser:
    """Register ``agentsim replay`` on the subparsers action ``sub`` of the ``agentsim`` parser."""
    p: argparse.ArgumentParser = sub.add_parser(
        "replay",
        help="draw a recorded episode from a store (PNG frames, MP4 or GIF)",
        description="Draw one recorded episode of a store (agentsim_env.recorder) from the store alone: agents,\n"
        "their trails, offline agents, collisions and released sensors, step by step.",
        epilog=REPLAY_EPILOG,
    )
    p.add_argument("store", metavar="RUN.db", help="the SQLite store written by the recorder")
    p.add_argument("--run", type=int, default=None, help="run id (default: the last run in the store)")
    p.add_argument("--episode", type=int, required=True, help="episode of the run (0: the first)")
    p.add_argument("--world", type=int, default=0, help="world of a batched run")
    p.add_argument("--every", type=int, default=1, help="draw every K-th step (the last step is always drawn)")
    p.add_argument("--fps", type=float, default=None, help="video frames per second (default: real time)")
    p.add_argument("--size", type=int, default=512, help="longest side of the map in pixels")
    p.add_argument(
        "--out",
        required=True,
        help="video.mp4, video.gif, or a folder for PNG frames (a name "
        "without an extension, or ending in '/'); another extension is an error",
    )
    p.set_defaults(func=cmd_replay)
    return p


__all__ = ["add_replay_command", "check_out", "cmd_replay"]
