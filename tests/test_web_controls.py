"""The viewer's controls against what a page may send: the speed range, pacing that wakes for the controls, and a
simulation (live or replayed) that keeps running whatever a page sends.

A plain WebSocket client (``websockets``) stands in for the page.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest

import agentsim_env
from agentsim_env.cli import main
from agentsim_env.render.web.server import ClientError
from agentsim_env.render.web.viewer import MAX_SPEED, MIN_SPEED, Controls

pytest.importorskip("websockets")

from tests.web_client import talk  # noqa: E402

#: Speeds a page may send that are outside the documented range (JSON can carry NaN and Infinity too).
BAD_SPEEDS = [5e-324, 1e-6, MIN_SPEED / 2, -1, MAX_SPEED * 1.01, float("inf"), float("nan"), True, "5", None]


@pytest.mark.parametrize("value", BAD_SPEEDS, ids=repr)
def test_a_speed_outside_the_documented_range_is_refused(value: Any) -> None:
    c = Controls(5.0)
    with pytest.raises(
        ClientError,
        match=rf"speed: 'value' must be 0 .* or a number of steps per second in "
        rf"{MIN_SPEED:g}\.\.{MAX_SPEED:g}",
    ):
        c._speed({"cmd": "speed", "value": value})
    assert c.speed == 5.0  # unchanged
    c.pace()  # and pacing goes on at the old speed


@pytest.mark.parametrize("value", [0, MIN_SPEED, 1, 60.5, MAX_SPEED])
def test_a_speed_inside_the_range_is_taken(value: float) -> None:
    c = Controls()
    assert c._speed({"cmd": "speed", "value": value})["speed"] == value


@pytest.mark.parametrize("value", [5e-324, -1.0, MAX_SPEED * 2, float("nan")])
def test_controls_refuse_an_initial_speed_outside_the_range(value: float) -> None:
    with pytest.raises(ValueError, match=f"speed must be 0 .* {MIN_SPEED:g}..{MAX_SPEED:g}"):
        Controls(value)


def _pacing(c: Controls) -> threading.Thread:
    """A thread inside ``c.pace()`` that has to wait a whole step at the slowest speed (1 / MIN_SPEED s)."""
    t = threading.Thread(target=c.pace, daemon=True)
    t.start()
    time.sleep(0.2)
    assert t.is_alive()
    return t


@pytest.mark.parametrize("wake", ["speed", "resume", "pause", "step", "close"])
def test_a_slow_pace_wakes_at_once_when_the_controls_change(wake: str) -> None:
    c = Controls(MIN_SPEED)  # 10 s between steps
    t = _pacing(c)
    t0 = time.perf_counter()
    if wake == "close":
        c.close()
    else:
        c.handlers()[wake]({"cmd": wake, **({"value": 50} if wake == "speed" else {})})
    t.join(2.0)
    assert not t.is_alive(), f"pace() still sleeping after {wake}"
    assert time.perf_counter() - t0 < 1.0


def test_pace_keeps_the_rate() -> None:
    c = Controls(40.0)
    t0 = time.perf_counter()
    for _ in range(9):
        c.pace()
    assert 0.2 < time.perf_counter() - t0 < 0.6  # 9 intervals of 25 ms


def test_render_mode_web_steps_on_whatever_speed_a_page_sends() -> None:
    env = agentsim_env.make("navigation", n_agents=3, render_mode="web")
    env.reset(seed=0)
    url = env.viewer.url
    acts = {a: env.action_space(a).sample() for a in env.agents}
    stop = threading.Event()
    failure: list[BaseException] = []

    def loop() -> None:
        try:
            while not stop.is_set():
                env.step({a: acts[a] for a in env.agents}) if env.agents else env.reset()
        except BaseException as exc:  # noqa: BLE001 - recorded for the assertion below
            failure.append(exc)

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    try:
        texts, _ = talk(url, [{"cmd": "speed", "value": v} for v in (5e-324, 1e-6)], seconds=0.5)
        errors = [m["message"] for m in texts if m["type"] == "error"]
        assert len(errors) == 2 and all(f"{MIN_SPEED:g}..{MAX_SPEED:g}" in e for e in errors), errors
        # the slowest speed allowed, then a fast one: the simulation does not stay parked
        talk(url, [{"cmd": "speed", "value": MIN_SPEED}], seconds=0.3)
        time.sleep(0.3)
        talk(url, [{"cmd": "speed", "value": 50}, {"cmd": "resume"}], seconds=0.2)
        s0 = env.world.tick
        time.sleep(0.5)
        assert env.world.tick >= s0 + 5, (s0, env.world.tick)
        assert t.is_alive() and not failure, failure
    finally:
        stop.set()
        env.viewer.controls.close()
        t.join(10)
        env.close()
    assert not failure, failure


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store with one short navigation episode."""
    db = tmp_path_factory.mktemp("replay") / "r.db"
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
    return db


def test_replay_playback_survives_any_speed_and_wakes_for_a_new_one(recorded: Path) -> None:
    from agentsim_env.recorder.web_replay import ReplayViewer

    v = ReplayViewer(recorded, episode=0, quiet=True, speed=20.0)
    url = v.start()
    try:
        texts, _ = talk(url, [{"cmd": "speed", "value": 5e-324}], seconds=0.3)
        assert any(m["type"] == "error" and "speed" in m["message"] for m in texts), texts
        assert v._thread is not None and v._thread.is_alive()
        talk(url, [{"cmd": "seek", "step": 1}, {"cmd": "speed", "value": MIN_SPEED}], seconds=0.3)
        at = v.index
        talk(url, [{"cmd": "speed", "value": 100}], seconds=0.4)
        assert v.index > at + 5, (at, v.index)  # the playback woke for the new speed
        assert v._thread.is_alive()
    finally:
        v.close()
    assert v._thread is not None and not v._thread.is_alive()


@pytest.mark.parametrize("speed", ["0.01", "1e-300", "20000", "nan"])
def test_view_refuses_a_speed_outside_the_range_in_one_line(speed: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["view", "navigation", "--set", "n_agents=2", "--steps", "1", "--speed", speed]) == 2
    err = capsys.readouterr().err
    assert err.startswith("agentsim: error: --speed must be 0") and f"{MIN_SPEED:g}..{MAX_SPEED:g}" in err, err
    assert err.count("\n") == 1
