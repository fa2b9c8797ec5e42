"""Make the README's screenshots of the 3D viewer and the hot-zone designer (headless Chromium, Playwright).

Run: ``.venv/bin/python docs/screenshots.py [navigation relay uav_release replay designer]`` (writes
``docs/images/viewer_*.png`` and ``designer.png``). Each view is what ``agentsim view SCENARIO`` shows a newcomer:
the scenario's default config and the default camera.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import agentsim_env  # noqa: E402
from agentsim_env.policies.registry import make_policy  # noqa: E402
from agentsim_env.render.web.server import WebServer  # noqa: E402
from agentsim_env.render.web.viewer import WebViewer  # noqa: E402
from agentsim_env.uav.designer import STATIC_DIR as DESIGNER_STATIC  # noqa: E402
from agentsim_env.uav.designer import designer_handlers, designer_hello  # noqa: E402
from tests.browser import browser_page  # noqa: E402

OUT = ROOT / "docs" / "images"


def live(
    name: str,
    policy: str,
    steps: int,
    shot: str,
    select: int | None = None,
    query: str = "",
    settle: float = 1.5,
    **config: object,
) -> None:
    """Run ``steps`` steps of ``name`` with ``policy`` while the page watches; screenshot the last one."""
    from agentsim_env.policies.registry import resolve_policy

    policy, config = resolve_policy(name, policy, dict(config))  # as `agentsim view NAME --policy POLICY` does
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
    srv = WebServer(
        "designer.html",
        title="designer",
        handlers=designer_handlers(None),
        on_connect=lambda: designer_hello(None),
        static_dir=DESIGNER_STATIC,
    )
    url = srv.start()
    with browser_page(1300, 800) as (page, _):
        page.goto(url)
        page.wait_for_function("window.designer && window.designer.ready && window.designer.lastPreview")
        time.sleep(1.0)
        page.screenshot(path=str(OUT / "designer.png"))
    srv.stop()
    print("written", OUT / "designer.png")


def replay(shot: str = "viewer_replay.png") -> None:
    """Record one default ``navigation`` episode with its first baseline, replay it, screenshot a late step."""
    import tempfile

    from agentsim_env.policies.registry import resolve_policy
    from agentsim_env.recorder import record
    from agentsim_env.recorder.web_replay import ReplayViewer

    with tempfile.TemporaryDirectory() as tmp:
        name, cfg = resolve_policy("navigation", None, {})
        env = record(agentsim_env.make("navigation", **cfg), Path(tmp) / "runs.db")
        pol = make_policy("navigation", env, name)
        obs, _ = env.reset(seed=0)
        pol.reset(0)
        while env.agents:
            obs, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
        env.close()
        viewer = ReplayViewer(Path(tmp) / "runs.db", quiet=True)
        url = viewer.start()
        with browser_page(1400, 860) as (page, errors):
            page.goto(url)
            page.wait_for_function("window.agentsim && window.agentsim.ready", timeout=60000)
            page.wait_for_function("window.agentsim.lastStep >= 45", timeout=120000)
            page.evaluate("window.agentsim.send({cmd: 'pause'})")
            time.sleep(1.0)
            page.screenshot(path=str(OUT / shot))
            if errors:
                print("console errors:", errors)
        viewer.close()
    print("written", OUT / shot)


SHOTS = {
    "navigation": lambda: live("navigation", "go_to_goal", 30, "viewer_navigation.png", select=0),
    "relay": lambda: live("relay", "flood", 120, "viewer_relay.png", settle=0.3),
    "uav_release": lambda: live("uav_release", "B5_cvt", 420, "viewer_uav_release.png"),
    "replay": replay,
    "designer": designer,
}

if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    for key in sys.argv[1:] or list(SHOTS):  # default: every shot; or name some (navigation relay ...)
        SHOTS[key]()
