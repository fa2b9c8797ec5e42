"""The 3D view at the camera a newcomer gets (headless Chromium): agents big enough to read, the scenario's goals
drawn where the env keeps them, and the legend telling arrived, collided and offline agents apart. Marked slow."""

from __future__ import annotations

import io
import time
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.render.web.viewer import WebViewer
from tests.browser import browser_page

pytestmark = pytest.mark.slow

MIN_AGENT_PIXELS = 60  # an agent (cone and its drop line) covers at least this many pixels on screen


def _image(page: Any) -> np.ndarray:
    import matplotlib.pyplot as plt

    return plt.imread(io.BytesIO(page.screenshot()), format="png")[..., :3]


def _project(page: Any, p: Any) -> tuple[float, float]:
    return tuple(page.evaluate("(p) => window.agentsim.project(p)", [float(v) for v in p]))  # type: ignore[return-value]


def _changed(a: np.ndarray, b: np.ndarray, xy: tuple[float, float], r: int) -> int:
    """Pixels within ``r`` of ``xy`` that differ between two screenshots."""
    x, y = int(round(xy[0])), int(round(xy[1]))
    pa, pb = (
        a[max(y - r, 0) : y + r + 1, max(x - r, 0) : x + r + 1],
        b[max(y - r, 0) : y + r + 1, max(x - r, 0) : x + r + 1],
    )
    return int((np.abs(pa - pb).max(axis=2) > 0.08).sum())


def test_default_navigation_view_draws_readable_agents_and_the_goals_where_the_env_says() -> None:
    env = agentsim_env.make("navigation")  # the default config: `agentsim view navigation`
    env.reset(seed=0)
    viewer = WebViewer(quiet=True)
    url = viewer.attach(env.world, env.scenario)
    viewer.new_episode()
    n = env.scenario.n_agents
    st, t = env.world.state, env.world.task
    try:
        with browser_page(1200, 800) as (page, errors):
            page.goto(url)  # the default (orbit) camera, framed by the page itself
            page.wait_for_function(
                "window.agentsim && window.agentsim.ready && window.agentsim.lastStep === 0", timeout=60000
            )
            time.sleep(0.5)
            full = _image(page)
            agents = [_project(page, st.pos[i]) for i in range(n)]
            goals = [_project(page, [*t.goal[i, :2], 0.0]) for i in range(n)]
            drawn = page.evaluate("window.agentsim.markers()")
            legend = page.inner_text("#legend")
            # the same camera with the agents and goals moved off the map: what is left is the map
            st.pos[:n] = [1e4, 1e4, 1.0]
            t.goal[:n] = [1e4, 1e4, 0.0]
            viewer.new_episode()
            page.wait_for_function("window.agentsim.episode === 1 && window.agentsim.lastStep === 0")
            time.sleep(0.5)
            empty = _image(page)
            assert not errors, errors
    finally:
        viewer.close()
    h, w, _ = full.shape
    assert all(20 <= x < w - 20 and 20 <= y < h - 20 for x, y in agents), agents
    sizes = [_changed(full, empty, xy, 30) for xy in agents]
    assert min(sizes) >= MIN_AGENT_PIXELS, f"agents cover {sizes} pixels; want >= {MIN_AGENT_PIXELS} each"
    # the page draws a goal per agent, each at the screen point of the env's goal
    got = sorted((m["slot"], m["x"], m["y"]) for m in drawn if m["kind"] == "goal")
    assert [g[0] for g in got] == list(range(n))
    assert np.allclose([g[1:] for g in got], goals, atol=1.0)
    assert all(_changed(full, empty, xy, 2) >= 4 for xy in goals), "a goal is not drawn at its projected position"
    for word in ("arrived", "collided", "offline", "goal"):
        assert word in legend, legend


def test_follow_keeps_the_selected_agent_centred_and_the_view_options_work() -> None:
    env = agentsim_env.make("navigation")
    env.reset(seed=0)
    viewer = WebViewer(quiet=True)
    url = viewer.attach(env.world, env.scenario)
    viewer.new_episode()
    st = env.world.state
    zero = {a: {k: np.zeros(s.shape, np.float32) for k, s in env.action_space(a).items()} for a in env.agents}
    try:
        with browser_page(1000, 700) as (page, errors):
            page.goto(url)
            page.wait_for_function(
                "window.agentsim && window.agentsim.ready && window.agentsim.lastStep === 0", timeout=60000
            )
            box = page.eval_on_selector(
                "#canvas",
                "c => { const r = c.getBoundingClientRect(); return [r.left + r.width / 2, r.top + r.height / 2]; }",
            )
            far = np.hypot(*np.subtract(_project(page, st.pos[2]), box))
            page.evaluate("window.agentsim.send({cmd: 'select', slot: 2})")
            page.check("#opt-follow")
            st.pos[2, :2] += 3.0  # the agent moves; the next frame carries it
            env.step({a: zero[a] for a in env.agents})
            page.wait_for_function("window.agentsim.lastStep === 1")
            time.sleep(0.3)
            near = np.hypot(*np.subtract(_project(page, st.pos[2]), box))
            page.uncheck("#opt-trails")
            page.click("#opt-frame")
            time.sleep(0.3)
            assert not errors, errors
    finally:
        viewer.close()
    assert far > 20 and near < 3, (far, near)
