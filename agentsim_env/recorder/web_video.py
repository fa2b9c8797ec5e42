"""A recorded episode's 3D replay view written as an MP4 or GIF (``agentsim view --replay RUN.db --out x.mp4``).

The replay is served as for ``agentsim view --replay`` (``recorder.web_replay``) and opened in headless Chromium,
driven by Playwright; the side panel, header and replay bar are hidden so the 3D view fills the frame. Playback is
driven step by step rather than in real time: the replay is paused, then for each frame the page asks for one
recorded step (``seek``), Playwright waits until the page's test hooks (``window.agentsim.lastStep`` and
``lastSeq``) say that frame is drawn, and the page is screenshot and fed to the encoder (``render.video``). A video
thus has exactly one frame per chosen step, however slowly this machine draws.

Needs the ``viewer`` extra (websockets and Playwright), the ``video`` extra (imageio-ffmpeg) and a Chromium; the
system's Chromium is used (``AGENTSIM_CHROMIUM`` names another), nothing is downloaded. The video is written to a
temporary file beside ``out`` and renamed into place when complete, so an interrupted export leaves nothing behind.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "CHROMIUM_FLAGS",
    "DEFAULT_SIZE",
    "MAX_FRAMES",
    "SIZE_RANGE",
    "check_export",
    "export_replay_video",
    "find_chromium",
    "frame_size",
]

#: Longest side of the video in pixels (the width; frames are 16:9), allowed and default.
SIZE_RANGE: tuple[int, int] = (160, 1920)
DEFAULT_SIZE = 960
#: Most frames one export draws: a software-rendered page draws a few frames a second, so longer exports take
#: hours; ``every`` brings a long episode under it.
MAX_FRAMES = 5000
#: Seconds the page may take to draw one frame (software WebGL on a busy machine is slow, but not this slow).
FRAME_TIMEOUT_S = 60.0

#: Chromium without network, sync or GPU (software WebGL), as the browser tests launch it.
CHROMIUM_FLAGS: list[str] = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-default-apps",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]

PLAYWRIGHT_HINT = 'exporting the 3D view needs Playwright: pip install "agentsim-env[viewer]"'
CHROMIUM_HINT = (
    "exporting the 3D view needs Chromium (none found): install it (Debian/Ubuntu: apt install "
    "chromium) or set AGENTSIM_CHROMIUM to its executable"
)

# Only the 3D view and its legend: the panel, header, replay bar, error banner and the view's own buttons are
# hidden; a label names the replay and the step (the page's own status line is in the hidden panel). Below
# LEGEND_MIN_WIDTH the legend's lines would take a third of the frame, so it is hidden too.
LEGEND_MIN_WIDTH = 480
_PAGE_CSS = """
#header, #side, #replay-bar, #error-banner, #view-options { display: none !important; }
#export-label { position: fixed; left: 8px; top: 6px; z-index: 5; padding: 2px 6px; border-radius: 3px;
  font: 13px/1.3 system-ui, sans-serif; color: #222; background: rgba(255, 255, 255, .8); pointer-events: none; }
"""
_ADD_LABEL = "() => { const d = document.createElement('div'); d.id = 'export-label'; document.body.append(d); }"
_SEEK = (
    "([step, text]) => { document.getElementById('export-label').textContent = text; "
    "window.agentsim.send({cmd: 'seek', step: step}); }"
)
_DRAWN = "([step, seq]) => window.agentsim.lastStep === step && window.agentsim.lastSeq > seq"


def frame_size(size: int) -> tuple[int, int]:
    """The ``(width, height)`` of the video's frames for a longest side of ``size`` pixels (16:9, both even)."""
    w = size - size % 2
    h = round(size * 9 / 16)
    return w, h - h % 2


def check_export(out: str | os.PathLike[str], fps: float | None, size: int, every: int) -> str:
    """Check the export's arguments before anything is loaded or started.

    Args:
        out: The video file: ``*.mp4`` or ``*.gif``.
        fps: Frames per second, > 0 (None: real time).
        size: Longest side of the video in pixels, within :data:`SIZE_RANGE`.
        every: Draw every ``every``-th recorded step, >= 1.

    Returns:
        The video format, ``"mp4"`` or ``"gif"``.

    Raises:
        ValueError: Naming the argument and what it may be.
    """
    from agentsim_env.recorder.replay_load import _check_int
    from agentsim_env.render.video import VIDEO_FORMATS, video_format

    fmt = video_format(out)
    if fmt is None:
        suffix = Path(out).suffix or "no suffix"
        raise ValueError(
            f"--out {str(out)!r}: the 3D view is exported as {', '.join('.' + f for f in VIDEO_FORMATS)} (got {suffix})"
        )
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float)) or not fps > 0):
        raise ValueError(f"--fps must be > 0, got {fps!r}")
    lo, hi = SIZE_RANGE
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not lo <= size <= hi:
        raise ValueError(f"--size must be an integer in {lo}..{hi} (the video's width in pixels), got {size!r}")
    _check_int("--every", every, 1)
    return fmt


def find_chromium() -> str | None:
    """The Chromium to drive: ``AGENTSIM_CHROMIUM``, else ``chromium`` / ``chromium-browser`` on the PATH."""
    return os.environ.get("AGENTSIM_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


def _playwright() -> Any:
    """``playwright.sync_api``, or a ValueError naming the extra."""
    try:
        from playwright import sync_api
    except ImportError:
        raise ValueError(PLAYWRIGHT_HINT) from None
    return sync_api


def _launch(pw: Any) -> Any:
    """Headless Chromium: the system's, else one Playwright installed itself; a ValueError when there is none."""
    path = find_chromium()
    if path and not (os.path.isfile(path) and os.access(path, os.X_OK)):
        raise ValueError(f"AGENTSIM_CHROMIUM={path!r} is not an executable file; {CHROMIUM_HINT.split(': ', 1)[1]}")
    try:
        return pw.chromium.launch(executable_path=path, headless=True, args=CHROMIUM_FLAGS)
    except Exception as exc:  # noqa: BLE001 - Playwright's Error: no browser, or one that does not start
        if path is None:
            raise ValueError(CHROMIUM_HINT) from None
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"Chromium ({path}) did not start: {first}") from None


def _rgb(png: bytes) -> np.ndarray:
    from agentsim_env.render.video import png_rgb

    return png_rgb(png)


def export_replay_video(
    store: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    run: int | None = None,
    episode: int = 0,
    world: int = 0,
    fps: float | None = None,
    size: int = DEFAULT_SIZE,
    every: int = 1,
    progress: bool = False,
) -> tuple[Path, int]:
    """Write the 3D replay view of a recorded episode to a video, one frame per chosen recorded step.

    Args:
        store: The store (SQLite) written by the recorder.
        out: ``*.mp4`` (H.264) or ``*.gif``; its folder is created. Written only when complete (temp + rename).
        run: The run (None: the last one).
        episode: The episode of the run.
        world: The world of a batched run.
        fps: Frames per second (None: real time, ``1 / (dt * every)`` from the run's config).
        size: The video's width in pixels (frames are 16:9), within :data:`SIZE_RANGE`.
        every: Draw every ``every``-th recorded step (the last step is always drawn), >= 1.
        progress: Show a progress bar (tqdm, on stderr).

    Returns:
        The video's path and its number of frames.

    Raises:
        ValueError: A bad argument, a store or episode that is not there (naming what is), more than
            :data:`MAX_FRAMES` frames, a missing package or Chromium (naming what to install), a page that does not
            draw, or an ``out`` that cannot be written.
    """
    from agentsim_env.recorder.replay import replay_info
    from agentsim_env.render.video import VideoWriter, check_video_support

    fmt = check_export(out, fps, size, every)
    try:
        check_video_support(fmt)
    except ImportError as exc:
        raise ValueError(str(exc)) from None
    info = replay_info(store, run, episode, world)
    steps = [int(s) for s in info.frame_steps(every)]
    if len(steps) > MAX_FRAMES:
        need = -(-len(info.steps) // MAX_FRAMES)
        while len(info.frame_steps(need)) > MAX_FRAMES:  # the last step is drawn too: at most one more
            need += 1
        raise ValueError(
            f"the export would draw {len(steps)} frames, at most {MAX_FRAMES}: pass --every {need} or more"
        )
    target = Path(out)
    if target.is_dir():
        raise ValueError(f"--out {str(target)!r} is a folder; give a file name ending in .{fmt}")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"{str(target.parent)!r} cannot be created: {exc.strerror or exc}") from None
    sync_api = _playwright()
    tmp = target.with_name(f".{target.stem}.{os.getpid()}.part.{fmt}")
    writer = VideoWriter(tmp, fps or info.fps(every))
    try:
        _draw(sync_api, info, steps, writer, size, progress)
        writer.close()
        os.replace(tmp, target)
    except OSError as exc:
        raise ValueError(f"{str(target)!r} cannot be written: {exc.strerror or exc}") from None
    except ImportError as exc:  # Pillow, to read the screenshots (the video extra)
        raise ValueError(str(exc)) from None
    finally:
        writer.abort()  # nothing left after close(); else drops a partial file
        tmp.unlink(missing_ok=True)
    return target, len(steps)


def _draw(sync_api: Any, info: Any, steps: list[int], writer: Any, size: int, progress: bool) -> None:
    """Serve the replay, open it in headless Chromium and append one screenshot per step in ``steps``."""
    from agentsim_env.recorder.web_replay import ReplayViewer

    width, height = frame_size(size)
    try:
        viewer = ReplayViewer(info.path, run=info.run, episode=info.episode, world=info.world, quiet=True)
    except ImportError as exc:  # websockets (the viewer extra)
        raise ValueError(str(exc)) from None
    viewer.controls.paused = True  # the page's frames come from the seeks below only
    bar = None
    try:
        url = viewer.start()
        with sync_api.sync_playwright() as pw:
            browser = _launch(pw)
            try:
                page = browser.new_page(viewport={"width": width, "height": height}, device_scale_factor=1)
                errors: list[str] = []
                page.on("pageerror", lambda e: errors.append(str(e)))
                page.goto(url)
                hide_legend = "" if width >= LEGEND_MIN_WIDTH else "#legend { display: none !important; }"
                page.add_style_tag(content=_PAGE_CSS + hide_legend)
                page.evaluate(_ADD_LABEL)
                _wait(
                    page,
                    sync_api,
                    "window.agentsim && window.agentsim.ready",
                    None,
                    "the page to open",
                    errors,
                )
                if progress:
                    from tqdm.auto import tqdm

                    bar = tqdm(total=len(steps), desc="export", unit="frame")
                title = f"{info.scenario} | run {info.run}, episode {info.episode}"
                for step in steps:
                    seq = page.evaluate("window.agentsim.lastSeq")
                    page.evaluate(_SEEK, [step, f"{title} | step {step}"])
                    _wait(page, sync_api, _DRAWN, [step, seq], f"step {step} to be drawn", errors)
                    writer.append(_rgb(page.screenshot(type="png")))
                    if bar is not None:
                        bar.update(1)
            finally:
                browser.close()
    finally:
        if bar is not None:
            bar.close()
        viewer.close()


def _wait(page: Any, sync_api: Any, expression: str, arg: Any, what: str, errors: list[str]) -> None:
    """Wait for ``expression`` to hold in the page; a ValueError saying what never came (and the page's errors)."""
    try:
        page.wait_for_function(expression, arg=arg, timeout=FRAME_TIMEOUT_S * 1000)
    except sync_api.TimeoutError:
        seen = f"; page errors: {' | '.join(errors[:3])}" if errors else ""
        raise ValueError(f"the viewer page did not draw: waited {FRAME_TIMEOUT_S:g} s for {what}{seen}") from None
