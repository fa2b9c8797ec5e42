"""The web viewer's server side without a browser: frames, static files, commands, latest state wins, replay.

A plain WebSocket client (``websockets``) stands in for the page; the browser tests are tests/test_web_viewer.py.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
import urllib.error
import urllib.request
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import agentsim_env
from agentsim_env.cli import main
from agentsim_env.render.web.frames import pack_frame, scene_message, state_arrays, unpack_frame
from agentsim_env.render.web.server import WebServer, static_files
from agentsim_env.render.web.viewer import WebViewer

pytest.importorskip("websockets")
from websockets.asyncio.client import connect  # noqa: E402

from tests.web_client import talk  # noqa: E402


def _get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, b""


@given(n=st.integers(0, 50), m=st.integers(0, 7), seq=st.integers(0, 10**9), step=st.integers(0, 10**6))
def test_frame_round_trip_keeps_every_array_aligned(n: int, m: int, seq: int, step: int) -> None:
    rng = np.random.default_rng(n + m)
    arrays = {
        "pos": rng.normal(size=(n, 3)).astype(np.float32),
        "group": rng.integers(-1, 5, n).astype(np.int16),
        "online": rng.integers(0, 2, n).astype(np.uint8),
        "msg": rng.integers(-1, n + 1, (m, 2)).astype(np.int32),
    }
    frame = pack_frame(seq, step, 3, arrays)
    header, back = unpack_frame(frame)
    assert (header["seq"], header["step"], header["episode"]) == (seq, step, 3)
    for name, a in arrays.items():
        assert header["arrays"][name]["offset"] % 8 == 0
        np.testing.assert_array_equal(back[name], a)


def test_pack_frame_refuses_other_dtypes() -> None:
    with pytest.raises(TypeError, match="float64"):
        pack_frame(1, 0, 0, {"pos": np.zeros((2, 3))})


def test_state_arrays_and_scene_describe_the_world() -> None:
    env = agentsim_env.make("navigation", n_agents=5)
    env.reset(seed=1)
    w = env.world
    a = state_arrays(w, 0, None, selected=2)
    np.testing.assert_allclose(a["pos"], w.state.pos[:5], atol=1e-5)
    assert a["rays"].shape == (32, 3) and a["ray_hit"].shape == (32,)
    # an unhit ray ends at the sensor range from the agent
    miss = a["ray_hit"] == 0
    d = np.linalg.norm(a["rays"][miss] - w.state.pos[2], axis=1)
    np.testing.assert_allclose(d, w.state.sensor_range[2], rtol=1e-4)
    scene = scene_message(w, env.scenario, 0)
    assert scene["n_agents"] == 5 and len(scene["objects"]["kind"]) == int((w.scene.world == 0).sum())
    uav = agentsim_env.make("uav_release")
    uav.reset(seed=0)
    zones = scene_message(uav.world, uav.scenario, 0)["zones"]
    assert len(zones) == len(uav.scenario.zones.zones) >= 2
    json.dumps(scene_message(uav.world, uav.scenario, 0), allow_nan=False)  # no NaN or inf reaches the page
    assert all(z["density"][0] == 1.0 and min(z["density"]) >= 0.0 for z in zones)


def test_static_files_only_by_exact_name(tmp_path: Any) -> None:
    srv = WebServer("viewer.html")
    url = srv.start()
    try:
        assert srv.host == "127.0.0.1" and url.startswith("http://127.0.0.1:")
        status, body = _get(url)
        assert status == 200 and b"<html" in body.lower()
        for path in static_files():
            assert _get(url.rstrip("/") + path)[0] == 200, path
        for bad in [
            "/static/../server.py",
            "/static/%2e%2e/server.py",
            "/static/..%2fserver.py",
            "/../pyproject.toml",
            "/etc/passwd",
            "/static/vendor/../../frames.py",
            "/static//etc/passwd",
            "/static/",
            "/favicon.ico",
            "/static/%2Fetc%2Fpasswd",
            "//etc/passwd",
        ]:
            assert _get(url.rstrip("/") + bad)[0] == 404, bad
    finally:
        srv.stop()


def test_a_page_from_another_origin_cannot_connect() -> None:
    from websockets.exceptions import InvalidStatus

    srv = WebServer("viewer.html")
    url = srv.start()
    try:

        async def attempt(origin: str) -> None:
            async with connect(url.replace("http", "ws") + "ws", origin=origin):  # type: ignore[arg-type]
                pass

        with pytest.raises(InvalidStatus, match="403"):
            asyncio.run(attempt("http://evil.example"))
        asyncio.run(attempt(url.rstrip("/")))  # the page's own origin
        asyncio.run(attempt(url.rstrip("/").replace("127.0.0.1", "localhost")))
    finally:
        srv.stop()


def test_bad_messages_get_an_error_and_the_server_goes_on() -> None:
    srv = WebServer(
        "viewer.html", handlers={"echo": lambda m: {"type": "echo", "x": m.get("x")}, "boom": lambda m: 1 / 0}
    )
    url = srv.start()
    try:
        bad = [
            "not json",
            "[1, 2]",
            "3",
            json.dumps({"cmd": 5}),
            json.dumps({"cmd": "nope"}),
            b"\x00\x01",
            json.dumps({"cmd": "ack", "seq": "x"}),
            json.dumps({"cmd": "boom"}),
            json.dumps({"cmd": "echo", "x": 7}),
        ]
        texts, _ = talk(url, bad, seconds=0.8)
        errors = [t["message"] for t in texts if t["type"] == "error"]
        assert len(errors) == 8, errors
        assert any("not JSON" in e for e in errors) and any("unknown command 'nope'" in e for e in errors)
        assert any("binary" in e for e in errors) and any("ZeroDivisionError" in e for e in errors)
        assert {"type": "echo", "x": 7} in texts  # still answering after all that
    finally:
        srv.stop()


def test_every_log_line_reaches_the_page_once_in_order() -> None:
    srv = WebServer("viewer.html")
    url = srv.start()
    try:
        lines: list[dict] = []
        t = threading.Thread(target=lambda: lines.extend(talk(url, [], seconds=1.0)[0]))
        t.start()
        while srv.n_pages == 0:
            time.sleep(0.01)
        for k in range(300):
            srv.publish_log([{"step": k, "kind": "message", "text": f"line {k}.{j}", "slots": []} for j in range(3)])
        t.join()
    finally:
        srv.stop()
    texts = [ln["text"] for m in lines if m["type"] == "log" for ln in m["lines"]]
    assert texts == [f"line {k}.{j}" for k in range(300) for j in range(3)]
    assert all(m["dropped"] == 0 for m in lines if m["type"] == "log")


def test_a_slow_page_gets_only_the_latest_frames_and_never_blocks_the_publisher() -> None:
    srv = WebServer("viewer.html", max_fps=0)
    url = srv.start()
    try:
        frames: list[bytes] = []
        # a slow page: 0.3 s per frame
        t = threading.Thread(target=lambda: frames.extend(talk(url, [], seconds=1.5, ack_delay=0.3)[1]))
        t.start()
        while srv.n_pages == 0:
            time.sleep(0.01)
        pos = np.zeros((2000, 3), np.float32)
        t0 = time.perf_counter()
        seq = 0
        while time.perf_counter() - t0 < 1.2:
            seq += 1
            srv.publish_frame(seq, pack_frame(seq, seq, 0, {"pos": pos}))  # never waits on the page
        t.join()
        got = [unpack_frame(f)[0]["seq"] for f in frames]
        assert seq > 1000  # thousands of publishes in 1.2 s: nothing waited on the page
        assert 1 <= len(got) <= 10 and got == sorted(got)  # a few frames, each newer than the last
        assert got[-1] > 100  # it skipped ahead to recent frames rather than queueing old ones
    finally:
        srv.stop()


def test_render_mode_web_streams_steps_and_obeys_pause_and_step() -> None:
    env = agentsim_env.make("navigation", n_agents=4, render_mode="web")
    stop = threading.Event()
    env.reset(seed=0)
    url = env.viewer.url
    assert url.startswith("http://127.0.0.1:") and env.render() is None
    acts = {a: env.action_space(a).sample() for a in env.agents}

    def loop() -> None:
        while not stop.is_set():
            env.step({a: acts[a] for a in env.agents}) if env.agents else env.reset()

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    try:
        texts, frames = talk(url, [{"cmd": "select", "slot": 1}], seconds=1.0)
        kinds = [t["type"] for t in texts]
        assert "scene" in kinds and "agent" in kinds, kinds
        assert len(frames) > 5, [unpack_frame(f)[0] for f in frames]
        assert "rays" in unpack_frame(frames[-1])[1]
        talk(url, [{"cmd": "pause"}], seconds=0.6)
        s0 = env.world.tick  # steps ever taken (episodes may end and reset meanwhile)
        time.sleep(0.3)
        assert env.world.tick == s0  # paused: the env waits in its step hook
        talk(url, [{"cmd": "step"}, {"cmd": "step"}], seconds=0.5)
        assert env.world.tick == s0 + 2
        texts, _ = talk(
            url,
            [{"cmd": "speed", "value": -1}, {"cmd": "select", "slot": 99}, {"cmd": "resume"}],
            seconds=0.4,
        )
        errors = [t["message"] for t in texts if t["type"] == "error"]
        assert any("speed" in e and "0.1..10000" in e for e in errors) and any("0..3" in e for e in errors)
        time.sleep(0.2)
        assert env.world.tick > s0 + 2  # resumed
    finally:
        stop.set()
        env.viewer.controls.close()  # a paused step returns
        t.join(10)
        env.close()
    assert env.viewer is None


def test_the_last_step_of_a_burst_reaches_the_page_when_the_simulation_goes_idle() -> None:
    env = agentsim_env.make("navigation", n_agents=4, collisions=False)
    env.reset(seed=0)
    v = WebViewer(quiet=True)
    v.attach(env.world, env.scenario)
    v.new_episode()
    got: list[int] = []

    def page() -> None:
        _, frames = talk(v.url, [], seconds=1.5)
        got.extend(unpack_frame(f)[0]["step"] for f in frames)

    t = threading.Thread(target=page)
    t.start()
    try:
        while v.server.n_pages == 0:
            time.sleep(0.01)
        time.sleep(0.2)
        for _ in range(12):  # a burst much faster than the frame-rate cap, then nothing
            env.step({a: env.action_space(a).sample() for a in env.agents})
        t.join()
    finally:
        v.close()
    assert got and got[-1] == 12, got


def test_viewer_hook_costs_nothing_without_a_page() -> None:
    env = agentsim_env.make("navigation", n_agents=4)
    env.reset(seed=0)
    v = WebViewer(quiet=True)
    v.attach(env.world, env.scenario)
    v.new_episode()
    try:
        for _ in range(20):
            env.step({a: env.action_space(a).sample() for a in env.agents})
        assert v.server.frames_sent == 0 and v.seq == 1  # only new_episode's frame was packed
    finally:
        v.close()
    assert v.hook not in env.world.hooks


def test_replay_serves_the_recorded_positions(tmp_path: Any) -> None:
    from agentsim_env.recorder.read import open_store
    from agentsim_env.recorder.web_replay import ReplayViewer

    db = tmp_path / "r.db"
    assert (
        main(
            [
                "run",
                "navigation",
                "--episodes",
                "1",
                "--set",
                "n_agents=3",
                "--record",
                str(db),
                "--out",
                "",
                "--quiet",
            ]
        )
        == 0
    )
    v = ReplayViewer(db, episode=0, quiet=True)
    url = v.start()
    try:
        texts, frames = talk(
            url, [{"cmd": "pause"}, {"cmd": "seek", "step": 5}, {"cmd": "seek", "step": 10**6}], seconds=0.8
        )
        _, stepped = talk(url, [{"cmd": "step"}], seconds=0.5)  # paused at 5: one step shows 6, no more
        _, played = talk(url, [{"cmd": "play"}], seconds=0.5)
    finally:
        v.close()
    assert unpack_frame(stepped[-1])[0]["step"] == 6
    assert unpack_frame(played[-1])[0]["step"] > 6
    scene = next(t for t in texts if t["type"] == "scene")
    assert scene["mode"] == "replay" and scene["replay"]["first_step"] == 0 and len(scene["objects"]["kind"]) > 0
    errors = [t["message"] for t in texts if t["type"] == "error"]
    assert len(errors) == 1 and "seek: 'step' must be an integer in 0.." in errors[0]
    header, arrays = unpack_frame(frames[-1])
    assert header["step"] == 5
    steps = open_store(db).table("steps")
    rows = steps[(steps.step == 5)].sort_values("agent")
    np.testing.assert_allclose(arrays["pos"][rows.agent.to_numpy()], rows[["x", "y", "z"]].to_numpy(), atol=1e-4)
    # the rebuilt static scene is the recorded episode's (same seed)
    env = agentsim_env.make("navigation", n_agents=3)
    env.reset(seed=0)
    assert np.allclose(np.array(scene["objects"]["centre"]), np.round(env.world.scene.centre, 3))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["view"], "give a SCENARIO"),
        (["view", "navigation", "--port", "70000"], "--port must be an integer in 0..65535"),
        (["view", "navigation", "--speed", "-2"], "--speed must be"),
        (["view", "navigation", "--replay", "x.db"], "--replay plays a store"),
        (["view", "navigation", "--policy", "nope"], "--policy must be one of"),
        (["view", "navigation", "--set", "n_agents=0"], "n_agents"),
        (["view", "navigation", "--episodes", "0"], "--episodes must be"),
        (["view", "--replay", "/nonexistent/x.db"], "x.db"),
        (["zones", "check", "/nonexistent/zones.json"], "zones.json"),
    ],
)
def test_view_and_zones_bad_input_is_one_clear_line(argv: list[str], message: str, capsys: Any) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("agentsim: error:") and message in err, err


def test_zones_check_lists_the_zones(capsys: Any) -> None:
    from agentsim_env.uav.zones import default_zones_path

    assert main(["zones", "check", str(default_zones_path())]) == 0
    out = capsys.readouterr().out
    assert "valid" in out and "| 0 |" in out


def test_view_runs_a_few_steps_and_stops(capsys: Any) -> None:
    assert main(["view", "navigation", "--set", "n_agents=3", "--steps", "15", "--speed", "0", "--no-wait"]) == 0
    assert "http://127.0.0.1:" in capsys.readouterr().err


def test_host_other_than_loopback_prints_a_warning(capsys: Any) -> None:
    v = WebViewer(host="0.0.0.0")
    env = agentsim_env.make("navigation", n_agents=2)
    env.reset(seed=0)
    try:
        v.attach(env.world, env.scenario)
    finally:
        v.close()
    assert "WARNING" in capsys.readouterr().err
