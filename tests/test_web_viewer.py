"""The 3D viewer page in a real browser (headless Chromium from the system's packages, driven by Playwright).

Marked slow. Each test serves a simulation (or a store) on 127.0.0.1, opens the page with the fixed top-down
camera (``?camera=top``) and checks what a person would see: agents and obstacles drawn where their projected
positions are (pixels compared with an empty scene), the log stream showing a collision the env reported and
holding new lines while paused, the replay showing the recorded positions at a chosen step, and a click on an
agent showing its state.
"""

from __future__ import annotations

import io
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.core.scene import Scene
from agentsim_env.render.web.viewer import WebViewer
from tests.browser import browser_page

pytestmark = pytest.mark.slow


def _image(page: Any) -> np.ndarray:
    """The page's screenshot as an (H, W, 3) float array in [0, 1]."""
    import matplotlib.pyplot as plt

    return plt.imread(io.BytesIO(page.screenshot()), format="png")[..., :3]


def _patch(img: np.ndarray, xy: tuple[float, float], r: int = 2) -> np.ndarray:
    x, y = int(round(xy[0])), int(round(xy[1]))
    return img[max(y - r, 0) : y + r + 1, max(x - r, 0) : x + r + 1]


def _differs(a: np.ndarray, b: np.ndarray, xy: tuple[float, float]) -> bool:
    return float(np.abs(_patch(a, xy) - _patch(b, xy)).max()) > 0.08


def _open(page: Any, url: str) -> None:
    page.goto(url + "?camera=top")
    page.wait_for_function("window.agentsim && window.agentsim.ready", timeout=30000)


def _wait_step(page: Any, step: int, timeout: float = 15.0) -> None:
    page.wait_for_function(f"window.agentsim.lastStep === {step}", timeout=timeout * 1000)
    time.sleep(0.2)  # one more animation frame drawn


def _project(page: Any, p: np.ndarray) -> tuple[float, float]:
    return tuple(page.evaluate("(p) => window.agentsim.project(p)", [float(v) for v in p]))  # type: ignore[return-value]


def _nav(n: int = 6, **cfg: Any) -> tuple[Any, WebViewer, str]:
    """A navigation env reset with seed 3, streamed by a viewer: (env, viewer, url)."""
    env = agentsim_env.make("navigation", n_agents=n, **cfg)
    env.reset(seed=3)
    viewer = WebViewer(quiet=True)
    url = viewer.attach(env.world, env.scenario)
    viewer.new_episode()
    return env, viewer, url


def test_page_draws_agents_and_obstacles_where_they_are_with_no_console_errors() -> None:
    env, viewer, url = _nav(6, map_size=60.0, obstacle_density=1.0 / 300.0)
    try:
        with browser_page() as (page, errors):
            _open(page, url)
            _wait_step(page, 0)
            full = _image(page)
            st, sc = env.world.state, env.world.scene
            agents = [_project(page, st.pos[i]) for i in range(6)]
            objects = [
                _project(page, np.r_[sc.centre[o, :2], sc.centre[o, 2] + sc.half[o, 2]]) for o in range(sc.n_objects)
            ]
            # the empty scene: the same map, no objects, the agents moved far off the map
            env.world.scene = Scene()
            st.pos[:6] = [1e4, 1e4, 1.0]
            viewer.new_episode()
            page.wait_for_function("window.agentsim.episode === 1")
            _wait_step(page, 0)
            empty = _image(page)
            assert not errors, errors
    finally:
        viewer.close()
    h, w, _ = full.shape
    inside = [(x, y) for x, y in agents if 3 <= x < w - 3 and 3 <= y < h - 3]
    assert len(inside) == 6, agents
    assert all(_differs(full, empty, xy) for xy in agents), "an agent is not drawn at its projected position"
    assert len(objects) >= 3
    assert sum(_differs(full, empty, xy) for xy in objects) >= len(objects) - 1  # one may hide under an agent
    # the ground far from every agent and object looks the same in both
    far = [
        (x, y)
        for x, y in [(w * 0.02, h * 0.5), (w * 0.5, h * 0.98)]
        if min(np.hypot(x - a, y - b) for a, b in agents + objects) > 30
    ]
    assert all(not _differs(full, empty, xy) for xy in far)


def test_log_stream_shows_the_collision_and_its_pause_holds_lines_while_steps_go_on() -> None:
    env, viewer, url = _nav(4, map_size=60.0, obstacle_density=0.0)
    acts = {a: {k: np.zeros(s.shape, np.float32) for k, s in env.action_space(a).items()} for a in env.agents}
    try:
        with browser_page() as (page, errors):
            _open(page, url)
            st = env.world.state
            st.pos[1] = st.pos[0] + np.array([0.1, 0.0, 0.0])  # agents 0 and 1 overlap: a collision this step
            _, _, term, _, infos = env.step({a: acts[a] for a in env.agents})
            assert env.world.last_events.collisions.agent.size > 0  # the env reported it
            page.wait_for_function("window.agentsim.logLines().some(l => l.includes('collided'))", timeout=15000)
            line = next(ln for ln in page.evaluate("window.agentsim.logLines()") if "collided" in ln)
            assert "agent_0" in line and "agent_1" in line
            page.click("#log-pause")
            held = page.evaluate("window.agentsim.logLines().length")
            step0 = page.evaluate("window.agentsim.lastStep")
            for _ in range(3):  # more events: collisions in new episodes
                env.reset()
                viewer.new_episode()
                st.pos[3] = st.pos[2]
                for _ in range(5):
                    env.step({a: acts[a] for a in env.agents})
            page.wait_for_function(
                "window.agentsim.episode > 0 && window.agentsim.lastStep >= 1 && window.agentsim.framesDrawn > 2",
                timeout=15000,
            )
            time.sleep(0.5)
            assert page.evaluate("window.agentsim.logLines().length") == held  # paused: no new lines
            assert page.evaluate("window.agentsim.episode") == 4 or page.evaluate("window.agentsim.lastStep") != step0
            page.click("#log-pause")  # resume: the held lines appear
            page.wait_for_function(f"window.agentsim.logLines().length > {held}", timeout=10000)
            assert not errors, errors
    finally:
        viewer.close()


def test_clicking_an_agent_shows_its_state() -> None:
    env, viewer, url = _nav(3, map_size=40.0, obstacle_density=0.0)
    try:
        with browser_page() as (page, errors):
            _open(page, url)
            _wait_step(page, 0)
            x, y = _project(page, env.world.state.pos[2])
            page.mouse.click(x, y)
            page.wait_for_function("window.agentsim.selected === 2", timeout=10000)
            page.wait_for_function(
                "document.querySelector('#agent-panel').textContent.includes('agent_2')", timeout=10000
            )
            assert not errors, errors
    finally:
        viewer.close()


def test_replay_shows_the_recorded_positions_at_the_chosen_step(tmp_path: Path) -> None:
    from agentsim_env.cli import main
    from agentsim_env.recorder.read import open_store
    from agentsim_env.recorder.web_replay import ReplayViewer

    db = tmp_path / "run.db"
    assert (
        main(
            [
                "run",
                "navigation",
                "--episodes",
                "1",
                "--set",
                "n_agents=4",
                "map_size=60",
                "--record",
                str(db),
                "--out",
                "",
                "--quiet",
            ]
        )
        == 0
    )
    steps = open_store(db).table("steps")
    viewer = ReplayViewer(db, episode=0, quiet=True)
    url = viewer.start()
    try:
        with browser_page() as (page, errors):
            _open(page, url)
            page.evaluate("window.agentsim.send({cmd: 'pause'})")
            shots = {}
            for k in (0, 30):
                page.evaluate(f"window.agentsim.send({{cmd: 'seek', step: {k}}})")
                _wait_step(page, k)
                shots[k] = _image(page)
            assert not errors, errors
            pos = {k: steps[steps.step == k].sort_values("agent")[["x", "y", "z"]].to_numpy() for k in (0, 30)}
            px = {k: [_project(page, p) for p in pos[k]] for k in (0, 30)}
    finally:
        viewer.close()
    moved = [i for i in range(4) if np.hypot(*np.subtract(px[0][i], px[30][i])) > 12]
    assert len(moved) >= 2
    # at step 30 each moved agent is drawn where the store puts it, and was not there at step 0
    assert all(_differs(shots[30], shots[0], px[30][i]) for i in moved)
    assert all(_differs(shots[30], shots[0], px[0][i]) for i in moved)


def test_agentsim_view_shows_uavs_releasing_sensors(tmp_path: Path) -> None:
    import re
    import subprocess
    import sys

    cmd = [
        sys.executable,
        "-m",
        "agentsim_env.cli",
        "view",
        "uav_release",
        "--policy",
        "B5_cvt",
        "--set",
        "zones=tiny",
        "--speed",
        "100",
    ]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    try:
        url = None
        assert proc.stderr is not None
        for line in proc.stderr:
            m = re.search(r"(http://127\.0\.0\.1:\d+/)", line)
            if m:
                url = m.group(1)
                break
        assert url, "agentsim view printed no URL"
        with browser_page() as (page, errors):
            page.goto(url)
            page.wait_for_function("window.agentsim && window.agentsim.ready", timeout=30000)
            page.wait_for_function(
                "window.agentsim.logLines().some(l => l.includes('released')) && "
                "window.agentsim.logLines().some(l => l.includes('landed'))",
                timeout=60000,
            )
            assert not errors, errors
    finally:
        proc.terminate()
        proc.wait(timeout=20)
