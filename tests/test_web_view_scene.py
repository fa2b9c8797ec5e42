"""What the live viewer sends about the scenario: markers (goals, targets, zones) asked of the scenario, why an
agent is no longer active (arrived, collided, offline), the log's message kinds with heartbeats and group
broadcasts hidden by default, replies to the controls carrying a steps/s number, and the wait for a first page."""

from __future__ import annotations

import ast
import inspect
import threading
import time

import numpy as np
import pytest

import agentsim_env
from agentsim_env.render.web import frames
from agentsim_env.render.web.frames import log_lines, scene_message, unpack_frame
from agentsim_env.render.web.viewer import WebViewer
from agentsim_env.uav.zones import DENSITY_SAMPLES
from tests.web_client import talk


def _markers(name: str, **cfg: object) -> tuple[object, dict]:
    env = agentsim_env.make(name, **cfg)
    env.reset(seed=1)
    return env, scene_message(env.world, env.scenario, 0)


def test_navigation_scene_marks_every_goal_where_the_env_keeps_it() -> None:
    env, scene = _markers("navigation", n_agents=5)
    goals = [m for m in scene["markers"] if m["kind"] == "goal"]
    assert [m["slot"] for m in goals] == list(range(5))
    want = env.world.task.goal[:5, :2]
    assert np.allclose([m["pos"][:2] for m in goals], want, atol=1e-3)
    assert all(m["radius"] == pytest.approx(env.scenario.config.goal_radius) for m in goals)


def test_relay_scene_marks_each_group_target_and_its_scout() -> None:
    env, scene = _markers("relay")
    sc = env.scenario
    targets = [m for m in scene["markers"] if m["kind"] == "target"]
    assert len(targets) == sc.n_groups
    t = env.world.task
    for m in targets:
        g = m["group"]
        scout = int(np.flatnonzero(t.scout[: sc.n_agents] & (np.arange(sc.n_agents) % sc.n_groups == g))[0])
        assert m["slot"] == scout  # the scout that sees this target
        assert np.allclose(m["pos"][:2], t.target[scout], atol=1e-3)


def test_uav_release_scene_marks_its_zones_with_density_profiles() -> None:
    env, scene = _markers("uav_release")
    zones = [m for m in scene["markers"] if m["kind"] == "zone"]
    zs = env.scenario.zones.zones
    assert len(zones) == len(zs) == len(scene["zones"])
    assert np.allclose([m["pos"][:2] for m in zones], [z.centre for z in zs])
    assert all(len(m["density"]) == DENSITY_SAMPLES for m in zones)


def test_frames_asks_the_scenario_and_never_checks_its_type() -> None:
    tree = ast.parse(inspect.getsource(frames))
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "isinstance"]
    imports = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert not calls, "frames.py checks types"
    assert not any("scenarios" in (m or "") for m in imports), imports


def test_status_says_why_an_agent_is_not_active() -> None:
    env = agentsim_env.make("navigation", n_agents=4, map_size=60.0, obstacle_density=0.0)
    env.reset(seed=0)
    v = WebViewer(quiet=True)
    v.attach(env.world, env.scenario)  # its step hook sees the scores (who ended and why)
    v.new_episode()
    st, t = env.world.state, env.world.task
    st.pos[1] = st.pos[0] + np.array([0.1, 0.0, 0.0])  # 0 and 1 collide
    st.pos[2] = t.goal[2]  # 2 arrives
    st.vel[2] = 0.0
    zero = {a: {k: np.zeros(s.shape, np.float32) for k, s in env.action_space(a).items()} for a in env.agents}
    try:
        env.step(zero)
        status = frames.state_arrays(env.world, 0, None, None, v._why)["status"]
    finally:
        v.close()
    names = [frames.STATUS_NAMES[int(s)] for s in status]
    assert names[:3] == ["collided", "collided", "arrived"] and names[3] == "active", names


def test_heartbeats_and_group_broadcasts_are_their_own_log_kinds_hidden_by_default() -> None:
    env = agentsim_env.make("uav_release")
    env.reset(seed=0)
    scene = scene_message(env.world, env.scenario, 0)
    assert {"heartbeat", "broadcast"} <= set(scene["log_kinds"])
    assert set(scene["log_hidden"]) == set(frames.LOG_HIDDEN) == {"heartbeat", "broadcast", "overlay"}
    from agentsim_env.policies.registry import make_policy

    pol = make_policy("uav_release", env, "B5_cvt")
    obs, _ = env.reset(seed=0)
    pol.reset(0)
    kinds: list[str] = []
    for _ in range(60):
        obs, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
        kinds += [ln["kind"] for ln in log_lines(env.world, env.scenario, env.world.last_events, 0, 0)]
    assert "broadcast" in kinds and "message" not in kinds  # the UAVs' GROUP traffic, not plain messages


def test_overlay_hop_summaries_are_their_own_log_kind_hidden_by_default() -> None:
    env = agentsim_env.make("relay")
    obs, _ = env.reset(seed=0)
    from agentsim_env.policies.registry import make_policy

    pol = make_policy("relay", env, "flood")
    pol.reset(0)
    lines: list[dict] = []
    for _ in range(40):
        obs, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
        lines += log_lines(env.world, env.scenario, env.world.last_events, 0, 0)
    overlay = [ln for ln in lines if ln["text"].startswith("OVERLAY:")]
    assert overlay and {ln["kind"] for ln in overlay} == {"overlay"}  # one summary a step, not a plain message
    assert "overlay" in frames.LOG_HIDDEN


def test_replies_to_the_controls_carry_a_steps_per_second_number() -> None:
    env = agentsim_env.make("navigation", n_agents=2)
    v = WebViewer(quiet=True, wait=False)
    url = v.attach(env.world, env.scenario)
    env.reset(seed=0)
    v.new_episode()
    try:
        texts, _ = talk(url, [{"cmd": "pause"}, {"cmd": "speed", "value": 5}, {"cmd": "resume"}], seconds=0.5)
    finally:
        v.close()
    statuses = [t for t in texts if t["type"] == "status"]
    assert len(statuses) >= 4
    assert all(isinstance(s.get("steps_per_s"), (int, float)) for s in statuses), statuses


def test_the_live_view_waits_for_its_first_page_then_starts_at_step_0() -> None:
    env = agentsim_env.make("navigation", n_agents=2)
    v = WebViewer(quiet=True, wait=True)
    url = v.attach(env.world, env.scenario)
    env.reset(seed=0)
    started = threading.Event()

    def first_episode() -> None:
        v.new_episode()
        started.set()

    t = threading.Thread(target=first_episode, daemon=True)
    t.start()
    try:
        time.sleep(0.5)
        assert not started.is_set()  # no page yet: the episode does not start
        texts, got = talk(url, [], seconds=0.5)
        assert started.wait(5.0)
        assert any(t["type"] == "scene" for t in texts)
        assert got and unpack_frame(got[0])[0]["step"] == 0
    finally:
        v.close()
        t.join(5.0)


def test_no_wait_starts_at_once_and_close_releases_a_waiting_viewer() -> None:
    env = agentsim_env.make("navigation", n_agents=2)
    v = WebViewer(quiet=True, wait=False)
    v.attach(env.world, env.scenario)
    env.reset(seed=0)
    t0 = time.perf_counter()
    v.new_episode()
    assert time.perf_counter() - t0 < 1.0
    v.close()
    w = WebViewer(quiet=True, wait=True)
    w.attach(env.world, env.scenario)
    threading.Timer(0.3, w.close).start()
    t0 = time.perf_counter()
    w.new_episode()  # returns once closed, without a page
    assert time.perf_counter() - t0 < 3.0


def test_render_mode_web_does_not_wait() -> None:
    env = agentsim_env.make("navigation", n_agents=2, render_mode="web")
    t0 = time.perf_counter()
    try:
        env.reset(seed=0)
        assert time.perf_counter() - t0 < 5.0
        assert env.viewer.wait_for_page is not None  # the documented way to hold until a page opens
    finally:
        env.close()


def test_replay_keeps_one_status_per_agent_and_its_replies_carry_steps_per_second(tmp_path) -> None:
    from agentsim_env.recorder import record
    from agentsim_env.recorder.web_replay import ReplayViewer

    env = record(
        agentsim_env.make("navigation", n_agents=3, max_steps=4, map_size=60.0, obstacle_density=0.0),
        tmp_path / "r.db",
    )
    env.reset(seed=0)
    st = env.unwrapped.world.state if hasattr(env, "unwrapped") else env.world.state
    st.pos[1] = st.pos[0] + np.array([0.1, 0.0, 0.0])  # 0 and 1 collide at the first step
    st.pos[2] = env.world.task.goal[2]  # 2 arrives
    zero = {a: {k: np.zeros(s.shape, np.float32) for k, s in env.action_space(a).items()} for a in env.agents}
    while env.agents:
        env.step({a: zero[a] for a in env.agents})
    env.close()
    v = ReplayViewer(tmp_path / "r.db", quiet=True)
    try:
        names = [frames.STATUS_NAMES[int(s)] for s in v.data.status[-1]]
        assert names == ["collided", "collided", "arrived"], names
        assert v.data.status[0].tolist() == [0, 0, 0]
        url = v.start()
        texts, _ = talk(url, [{"cmd": "pause"}, {"cmd": "speed", "value": 5}], seconds=0.4)
    finally:
        v.close()
    statuses = [t for t in texts if t["type"] == "status"]
    assert statuses and all(isinstance(s.get("steps_per_s"), (int, float)) for s in statuses), statuses


@pytest.mark.parametrize(("flags", "waits"), [([], True), (["--no-wait"], False)])
def test_agentsim_view_waits_for_a_page_unless_no_wait(
    monkeypatch: pytest.MonkeyPatch, flags: list[str], waits: bool
) -> None:
    from agentsim_env.cli import main

    calls: list[int] = []
    monkeypatch.setattr(WebViewer, "wait_for_page", lambda self, timeout=None: calls.append(1) or True)
    assert main(["view", "navigation", "--set", "n_agents=2", "--steps", "2", "--speed", "0", *flags]) == 0
    assert calls == ([1] if waits else [])
