"""The live window of ``agentsim run --render``: how a run ends, and what happens without a display.

The end-to-end tests run the real command under Xvfb (skipped where Xvfb is not installed; ``make browser``
installs it): SIGTERM, Ctrl-C and a closed window each end the run cleanly, the store keeps what was recorded.
"""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from agentsim_env.cli import main

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------------ no display
@pytest.mark.parametrize(
    ("env", "named"),
    [
        ({"SDL_VIDEODRIVER": "dummy", "DISPLAY": ":0"}, "SDL_VIDEODRIVER=dummy"),
        ({"SDL_VIDEODRIVER": None, "DISPLAY": None, "WAYLAND_DISPLAY": None}, "DISPLAY"),
    ],
)
def test_render_without_display_is_one_error_line(
    env: dict[str, str | None],
    named: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    for key, value in env.items():
        if value is None:
            monkeypatch.delenv(key, raising=False)
        else:
            monkeypatch.setenv(key, value)
    out = tmp_path / "out"
    rc = main(
        [
            "run",
            "navigation",
            "--render",
            "--fps",
            "1000",
            "--episodes",
            "1",
            "--quiet",
            "--out",
            str(out),
            "--set",
            "n_agents=2",
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and err[0].startswith("agentsim: error: --render"), err
    assert named in err[0] and "agentsim view navigation" in err[0]
    assert not out.exists()  # refused before anything was made


@pytest.mark.parametrize("event", ["QUIT", "WINDOWCLOSE", "Esc"])
def test_closed_window_raises_and_closes(event: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    pg = pytest.importorskip("pygame")
    from agentsim_env.render.window import Window, WindowClosed

    win = Window("t", fps=1000)
    frame = np.zeros((20, 30, 3), dtype=np.uint8)
    win.show(frame)
    pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_a))  # other keys do not close it
    win.show(frame)
    posted = pg.event.Event(pg.KEYDOWN, key=pg.K_ESCAPE) if event == "Esc" else pg.event.Event(getattr(pg, event))
    pg.event.post(posted)
    with pytest.raises(WindowClosed, match="closed"):
        win.show(frame)
    assert not pg.display.get_init()  # the window is gone, not left open and unresponsive


# ------------------------------------------------------------------------------------- under Xvfb
@pytest.fixture(scope="module")
def xdisplay() -> Iterator[str]:
    """A private X server (``:N``) for the module's tests."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (make browser installs it)")
    pytest.importorskip("pygame")
    r, w = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(w), "-screen", "0", "800x700x24", "-nolisten", "tcp"],
        pass_fds=(w,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(w)
    with os.fdopen(r) as f:
        number = f.readline().strip()
    try:
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(10)


def _env(display: str | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("SDL_VIDEODRIVER", "WAYLAND_DISPLAY", "DISPLAY")}
    return {
        **env,
        **({"DISPLAY": display} if display else {}),
        "AGENTSIM_QUIET_COMPILE": "1",
        "NUMBA_NUM_THREADS": "1",
    }


def _start(display: str | None, args: list[str], code: str | None = None) -> subprocess.Popen[str]:
    """``agentsim ARGS`` in a subprocess (``code`` runs first, in the same process)."""
    prog = (code or "") + "\nimport sys\nfrom agentsim_env.cli import main\nsys.exit(main(sys.argv[1:]))"
    return subprocess.Popen(
        [sys.executable, "-c", prog, *args],
        cwd=ROOT,
        env=_env(display),
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def _count(db: Path, sql: str) -> int:
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5) as con:
            return int(con.execute(sql).fetchone()[0])
    except sqlite3.Error:
        return 0


def _wait_for_steps(
    proc: subprocess.Popen[str], db: Path, n: int, sql: str = "SELECT count(DISTINCT step) FROM steps"
) -> None:
    deadline = time.monotonic() + 60
    while _count(db, sql) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{sql} not at {n} within 60 s"
        time.sleep(0.1)


def _run_row(db: Path) -> tuple[str, int, int]:
    """(status, episodes, steps) of the store's one run."""
    with sqlite3.connect(db) as con:
        (status,) = con.execute("SELECT status FROM runs").fetchone()
        (episodes,) = con.execute("SELECT count(*) FROM episodes").fetchone()
        (steps,) = con.execute("SELECT count(*) FROM steps").fetchone()
    return status, episodes, steps


@pytest.mark.slow
@pytest.mark.parametrize(("sig", "code", "word"), [(signal.SIGTERM, 143, "SIGTERM"), (signal.SIGINT, 130, "Ctrl-C")])
def test_signal_ends_live_run_cleanly(xdisplay: str, tmp_path: Path, sig: int, code: int, word: str) -> None:
    db = tmp_path / "run.db"
    proc = _start(
        xdisplay,
        [
            "run",
            "navigation",
            "--render",
            "--episodes",
            "3",
            "--quiet",
            "--record",
            str(db),
            "--out",
            str(tmp_path / "out"),
            "--set",
            "n_agents=3",
        ],
    )
    try:
        _wait_for_steps(proc, db, 5)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == code, (out, err)
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"agentsim: stopped by {word}"), lines
    assert str(db) in lines[0]
    status, episodes, steps = _run_row(db)
    assert (status, episodes) == ("incomplete", 1) and steps >= 5 * 3


@pytest.mark.slow
@pytest.mark.parametrize(("sig", "code", "word"), [(signal.SIGTERM, 143, "SIGTERM"), (signal.SIGINT, 130, "Ctrl-C")])
def test_signal_ends_batch_run_cleanly(tmp_path: Path, sig: int, code: int, word: str) -> None:
    # without --render too: the run stops between steps (a Ctrl-C inside a kernel came out as a SystemError)
    db, out = tmp_path / "run.db", tmp_path / "out"
    proc = _start(
        None, ["run", "navigation", "--episodes", "100000", "--quiet", "--record", str(db), "--out", str(out)]
    )
    try:
        _wait_for_steps(proc, db, 3, "SELECT count(*) FROM episodes")
        proc.send_signal(sig)
        stdout, err = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == code, (stdout, err)
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"agentsim: stopped by {word} after "), lines
    assert "episodes x 4 agents" in stdout  # the summary of the episodes that ended
    assert len(list(out.glob("navigation_*.png"))) == 1
    assert _run_row(db)[0] == "incomplete"


@pytest.mark.slow
def test_closing_the_window_ends_the_run(xdisplay: str, tmp_path: Path) -> None:
    # the window's close button arrives as a QUIT event: post one while the second episode is shown
    code = """
import pygame
from agentsim_env.render import window
shown, show = [0], window.Window.show
def counted(self, frame):
    shown[0] += 1
    if shown[0] == 35:  # the first episode is 30 steps (31 frames)
        pygame.event.post(pygame.event.Event(pygame.QUIT))
    show(self, frame)
window.Window.show = counted
"""
    db, out = tmp_path / "run.db", tmp_path / "out"
    proc = _start(
        xdisplay,
        [
            "run",
            "navigation",
            "--render",
            "--episodes",
            "3",
            "--fps",
            "1000",
            "--quiet",
            "--record",
            str(db),
            "--out",
            str(out),
            "--set",
            "n_agents=2",
            "max_steps=30",
        ],
        code,
    )
    try:
        stdout, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, (stdout, err)
    assert "Traceback" not in err
    assert "agentsim: window closed after 1 of 3 episodes" in err
    assert "navigation: 1 episodes" in stdout  # the summary of the episode that ended
    assert len(list(out.glob("navigation_*.png"))) == 1
    status, episodes, _ = _run_row(db)
    assert (status, episodes) == ("incomplete", 2)


@pytest.mark.slow
def test_render_plays_one_episode_by_default(xdisplay: str, tmp_path: Path) -> None:
    proc = _start(
        xdisplay,
        ["run", "navigation", "--render", "--fps", "1000", "--quiet", "--out", "", "--set", "n_agents=2"],
    )
    try:
        stdout, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, (stdout, err)
    assert "navigation: 1 episodes" in stdout
