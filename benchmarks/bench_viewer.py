"""The web viewer's stream: page updates per second and the simulation's slowdown, with a real browser client.

``navigation`` (one world, N agents, collisions off so that every agent keeps flying, the dict API with fixed
random actions; every timed block starts from the same reset) steps as fast as it can in three
settings, interleaved over rounds: **alone** (no viewer), **page** (the viewer's step hook streaming to the 3D page
open in headless Chromium, from the system's package, driven by Playwright), and **slow page** (the same hook
with a WebSocket client in another process that takes 250 ms to acknowledge each frame: latest state wins, so
the simulation must not notice). Reported per N: env steps/s in each setting (wall clock: the page and the
server thread share the machine with the simulation, which is the cost a user sees), the slowdown, the page's
updates/s (frames the page received and applied per second, read from the page; it acknowledges each on
arrival), the frames it drew per second (software WebGL here: the browser's rendering, not the stream, limits
that), the frame size and the targets (>= 30 updates/s
at 1,000 agents, >= 5 at 10,000; slowdown <= 20 %).

Run: ``.venv/bin/python benchmarks/bench_viewer.py [--quick] [--sizes 1000 10000] [--seconds 4] [--rounds 3]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import common  # noqa: I001 - pins the thread pools before numpy loads
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TARGET_UPDATES = {1000: 30.0, 10000: 5.0}
MAX_SLOWDOWN = 0.20
SLOW_CLIENT = """
import asyncio, json, sys, time
from websockets.asyncio.client import connect
async def main(url):
    async with connect(url, max_size=None) as ws:
        end = time.time() + float(sys.argv[2])
        while time.time() < end:
            try:
                m = await asyncio.wait_for(ws.recv(), 0.5)
            except asyncio.TimeoutError:
                continue
            if isinstance(m, bytes):
                await asyncio.sleep(0.25)  # a slow page: a quarter of a second per frame
                seq = json.loads(m[8:8 + int.from_bytes(m[4:8], 'little')])['seq']
                await ws.send(json.dumps({'cmd': 'ack', 'seq': seq}))
asyncio.run(main(sys.argv[1]))
"""


class Sim:
    """``navigation`` with N agents stepped with fixed random actions (reset when the episode ends)."""

    def __init__(self, n: int) -> None:
        import agentsim_env

        self.env = agentsim_env.make("navigation", n_agents=n, max_steps=100000, collisions=False)
        self.env.reset(seed=0)
        rng = np.random.default_rng(0)
        space = self.env.action_space(self.env.possible_agents[0])
        self.actions = {
            a: {k: rng.uniform(-0.3, 0.3, s.shape).astype(np.float32) for k, s in space.items()}
            for a in self.env.possible_agents
        }

    def run(self, seconds: float) -> float:
        """Step for ``seconds`` of wall time; return env steps per second."""
        env = self.env
        env.reset(seed=0)
        n = 0
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            if not env.agents:
                env.reset()
            acts = self.actions if len(env.agents) == len(self.actions) else {a: self.actions[a] for a in env.agents}
            env.step(acts)
            n += 1
        return n / (time.perf_counter() - t0)


def _browser() -> tuple[object, object, object]:
    sys.path.insert(0, str(ROOT))
    from playwright.sync_api import sync_playwright

    from tests.browser import CHROMIUM_FLAGS, chromium_path

    pw = sync_playwright().start()
    browser = pw.chromium.launch(executable_path=chromium_path(), headless=True, args=CHROMIUM_FLAGS)
    page = browser.new_page(viewport={"width": 1000, "height": 700})
    return pw, browser, page


def measure(n: int, seconds: float, rounds: int, page: object) -> dict[str, float]:
    """Interleaved rounds of alone / page / slow page for N agents; medians."""
    from agentsim_env.render.web.frames import pack_frame, state_arrays
    from agentsim_env.render.web.viewer import WebViewer

    sim = Sim(n)
    sim.run(0.5)  # warm-up (kernels, caches)
    viewer = WebViewer(quiet=True, title=f"bench {n}")
    url = viewer.attach(sim.env.world, sim.env.scenario)
    viewer.new_episode()
    world = sim.env.world
    frame_bytes = len(pack_frame(1, 0, 0, state_arrays(world, 0, None, None)))
    res: dict[str, list[float]] = {
        "alone": [],
        "page": [],
        "slow": [],
        "updates": [],
        "drawn": [],
        "slow_updates": [],
    }
    try:
        for _ in range(rounds):
            world.hooks = [h for h in world.hooks if h != viewer.hook]
            page.goto("about:blank")  # type: ignore[attr-defined]
            res["alone"].append(sim.run(seconds))
            world.add_hook(viewer.hook)
            page.goto(url + "?camera=top")  # type: ignore[attr-defined]
            page.wait_for_function("window.agentsim && window.agentsim.ready", timeout=60000)  # type: ignore[attr-defined]
            sim.run(0.5)
            counts = "[window.agentsim.framesReceived, window.agentsim.framesDrawn]"
            r0, d0 = page.evaluate(counts)  # type: ignore[attr-defined]
            t0 = time.perf_counter()
            res["page"].append(sim.run(seconds))
            dt = time.perf_counter() - t0
            r1, d1 = page.evaluate(counts)  # type: ignore[attr-defined]
            res["updates"].append((r1 - r0) / dt)
            res["drawn"].append((d1 - d0) / dt)
            page.goto("about:blank")  # type: ignore[attr-defined]
            client = subprocess.Popen(
                [sys.executable, "-c", SLOW_CLIENT, url.replace("http", "ws") + "ws", str(seconds + 2.0)]
            )
            deadline = time.time() + 10
            while viewer.server.n_pages == 0 and time.time() < deadline:
                time.sleep(0.05)
            sent0 = viewer.server.frames_sent
            t0 = time.perf_counter()
            res["slow"].append(sim.run(seconds))
            res["slow_updates"].append((viewer.server.frames_sent - sent0) / (time.perf_counter() - t0))
            client.wait(timeout=30)
    finally:
        viewer.close()
        sim.env.close()
    out = {k: float(np.median(v)) for k, v in res.items()}
    out["frame_bytes"] = float(frame_bytes)
    return out


def main(argv: list[str] | None = None) -> int:
    """Measure and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10000], help="agents in the world")
    ap.add_argument("--seconds", type=float, default=4.0, help="seconds per timed block")
    ap.add_argument("--rounds", type=int, default=3, help="interleaved rounds (medians are reported)")
    ap.add_argument("--quick", action="store_true", help="tiny run: 100 agents, 1 s blocks, 1 round")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.seconds, args.rounds = [100], 1.0, 1
    print(f"machine: {common.machine_description()}")
    print(f"date: {time.strftime('%Y-%m-%d')}; browser: headless Chromium (system package, software WebGL)")
    pw, browser, page = _browser()
    rows = []
    try:
        for n in args.sizes:
            r = measure(n, args.seconds, args.rounds, page)
            slow = 1.0 - r["page"] / r["alone"]
            slow_slow = 1.0 - r["slow"] / r["alone"]
            target = TARGET_UPDATES.get(n)
            ok = (target is None or r["updates"] >= target) and slow <= MAX_SLOWDOWN and slow_slow <= MAX_SLOWDOWN
            rows.append(
                [
                    f"{n:,}",
                    f"{r['frame_bytes'] / 1024:,.1f}",
                    common.fmt_num(r["alone"]),
                    common.fmt_num(r["page"]),
                    f"{100 * slow:+.1f} %",
                    common.fmt_num(r["updates"]),
                    f">= {target:g}" if target else "-",
                    common.fmt_num(r["drawn"]),
                    common.fmt_num(r["slow"]),
                    f"{100 * slow_slow:+.1f} %",
                    common.fmt_num(r["slow_updates"]),
                    "PASS" if ok else "FAIL",
                ]
            )
    finally:
        browser.close()  # type: ignore[attr-defined]
        pw.stop()  # type: ignore[attr-defined]
    print()
    print(
        common.markdown_table(
            [
                "agents",
                "frame KiB",
                "env steps/s alone",
                "with page",
                "slowdown",
                "page updates/s",
                "target",
                "page draws/s",
                "slow page: steps/s",
                "slowdown",
                "frames/s sent",
                "result",
            ],
            rows,
        )
    )
    print(f"\nslowdown target: <= {MAX_SLOWDOWN:.0%} (positive = slower); {os.cpu_count()} logical CPUs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
