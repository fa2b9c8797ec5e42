"""Make the README's screenshots of the 3D viewer and the hot-zone designer (headless Chromium, Playwright).

Run: ``.venv/bin/python docs/screenshots.py`` (writes ``docs/images/viewer_*.png`` and ``designer.png``).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import agentsim_env  # noqa: E402
from agentsim_env.policies.registry import make_policy  # noqa: E402
from agentsim_env.render.web.designer import designer_handlers, designer_hello  # noqa: E402
from agentsim_env.render.web.server import WebServer  # noqa: E402
from agentsim_env.render.web.viewer import WebViewer  # noqa: E402
from tests.browser import browser_page  # noqa: E402

OUT = ROOT / "docs" / "images"


def live(name: str, policy: str, steps: int, shot: str, select: int | None = None, query: str = "",
         settle: float = 1.5, **config: object) -> None:  # fmt: skip
    """Run ``steps`` steps of ``name`` with ``policy`` while the page watches; screenshot the last one."""
    env = agentsim_env.make(name, **config)
    pol = make_policy(name, env, policy)
    viewer = WebViewer(quiet=True, title=f"{name} | {policy}")
    url = viewer.attach(env.world, env.scenario)
    obs, _ = env.reset(seed=0)
    pol.reset(0)
    viewer.new_episode()
    with browser_page(1400, 860) as (page, errors):
        page.goto(url + query)
        page.wait_for_function("window.agentsim && window.agentsim.ready", timeout=60000)
        if select is not None:
            page.evaluate(f"window.agentsim.send({{cmd: 'select', slot: {select}}})")
        for _ in range(steps):
            if not env.agents:
                break
            obs, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
            time.sleep(0.01)
        time.sleep(settle)  # short: message lines fade within a second
        page.screenshot(path=str(OUT / shot))
        if errors:
            print("console errors:", errors)
    viewer.close()
    print("written", OUT / shot)


def designer() -> None:
    """The designer with the default zones."""
    srv = WebServer("designer.html", title="designer", handlers=designer_handlers(None),
                    on_connect=lambda: designer_hello(None))  # fmt: skip
    url = srv.start()
    with browser_page(1300, 800) as (page, _):
        page.goto(url)
        page.wait_for_function("window.designer && window.designer.ready && window.designer.lastPreview")
        time.sleep(1.0)
        page.screenshot(path=str(OUT / "designer.png"))
    srv.stop()
    print("written", OUT / "designer.png")


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    live("uav_release", "B5_cvt", 420, "viewer_uav_release.png")
    live("navigation", "go_to_goal", 60, "viewer_navigation.png", select=3, n_agents=24, map_size=70.0)
    live("relay", "flood", 40, "viewer_relay.png", settle=0.25)
    designer()
