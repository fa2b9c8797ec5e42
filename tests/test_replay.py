"""Replaying recorded episodes from the store (``agentsim_env.recorder.replay``, ``agentsim replay``), video
writing (``agentsim_env.render.video``) and the ``RecordVideo`` ParallelEnv wrapper."""

from __future__ import annotations

import sqlite3
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.cli import main
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.recorder import record
from agentsim_env.recorder.replay import (
    HEADER,
    agent_color,
    replay_frames,
    replay_info,
    write_replay,
)
from agentsim_env.render.record_video import RecordVideo
from agentsim_env.render.video import write_video

Image = pytest.importorskip("PIL.Image")
STEPS = 30
N = 4


def _play(env: Any, seed: int) -> None:
    env.reset(seed=seed)
    for a in env.possible_agents:
        env.action_space(a).seed(seed)
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store with one navigation run of two episodes (seeds 0 and 1)."""
    path = tmp_path_factory.mktemp("replay") / "run.db"
    env = record(agentsim_env.make("navigation", n_agents=N, max_steps=STEPS), path)
    for seed in (0, 1):
        _play(env, seed)
    env.close()
    return path


def _rows(path: Path, episode: int, step: int) -> dict[int, tuple[float, float, int]]:
    con = sqlite3.connect(path)
    try:
        rows = con.execute(
            "SELECT agent, x, y, online FROM steps WHERE run = 1 AND episode = ? AND world = 0 AND step = ?",
            (episode, step),
        ).fetchall()
    finally:
        con.close()
    return {int(a): (x, y, int(o)) for a, x, y, o in rows}


def _png(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


def test_png_frames_one_per_recorded_step_with_agents_where_the_store_puts_them(store: Path, tmp_path: Path) -> None:
    info = replay_info(store, episode=1)
    assert info.run == 1 and info.scenario == "navigation" and info.n_agents == N
    con = sqlite3.connect(store)
    (n_steps,) = con.execute("SELECT count(DISTINCT step) FROM steps WHERE run = 1 AND episode = 1").fetchone()
    con.close()
    assert n_steps == STEPS + 1 == len(info.steps)  # step 0 after the reset, then every step
    paths = write_replay(store, tmp_path / "frames", episode=1)
    assert [p.name for p in paths] == [f"frame_{k:05d}.png" for k in range(n_steps)]
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [p.name for p in paths]
    shapes = {_png(p).shape for p in paths}
    assert shapes == {info.canvas.shape}
    cv = info.canvas
    r = max(info.radius * cv.scale, 3.0)
    checked = 0
    for k in (0, STEPS // 2, STEPS):
        img = _png(paths[k])
        rows = _rows(store, 1, k)
        for a, (x, y, online) in rows.items():
            cx, cy = cv.px(x, y)
            others = [cv.px(ox, oy) for b, (ox, oy, _) in rows.items() if b != a]
            if not online or any(np.hypot(cx - ox, cy - oy) < 3 * r + 6 for ox, oy in others):
                continue  # overlapping discs: the later agent hides this one
            color = agent_color(a)
            assert (img[int(cy), int(cx)] == color).all(), (k, a, img[int(cy), int(cx)], color)
            # the agent's disc, found in the image by its colour, is centred on the recorded position
            ys, xs = np.nonzero((img == color).all(axis=2))
            near = np.hypot(xs + 0.5 - cx, ys + 0.5 - cy) <= 2 * r
            assert near.sum() >= 0.5 * np.pi * r * r
            assert np.hypot(xs[near].mean() + 0.5 - cx, ys[near].mean() + 0.5 - cy) < r / 2 + 1
            checked += 1
    assert checked >= 3
    # a header band on top
    assert (_png(paths[0])[: HEADER // 4] == _png(paths[0])[0, 0]).all()


def test_frames_every_k_and_the_last_step(store: Path) -> None:
    frames = list(replay_frames(store, episode=0, every=7, size=128))
    info = replay_info(store, episode=0, size=128)
    assert info.frame_steps(7) == [0, 7, 14, 21, 28, 30]
    assert len(frames) == 6
    assert all(f.dtype == np.uint8 and f.shape == info.canvas.shape for f in frames)
    longest = max(frames[0].shape[0] - HEADER, frames[0].shape[1])
    assert longest in (127, 128)  # the map's longest side is `size` pixels
    # a replay of the other episode differs
    other = next(iter(replay_frames(store, episode=1, size=128)))
    assert not np.array_equal(frames[0], other)


def test_replay_png_folder_replaces_earlier_frames(store: Path, tmp_path: Path) -> None:
    out = tmp_path / "f"
    assert len(write_replay(store, out, episode=0)) == STEPS + 1
    assert len(write_replay(store, out, episode=0, every=10)) == 4
    assert len(list(out.glob("frame_*.png"))) == 4


def test_replay_gif_and_mp4(store: Path, tmp_path: Path) -> None:
    [gif] = write_replay(store, tmp_path / "v" / "r.gif", episode=0, every=3)
    n = len(replay_info(store, episode=0).frame_steps(3))
    with Image.open(gif) as im:
        assert im.n_frames == n
        assert im.info["duration"] == pytest.approx(300, abs=10)  # real time: dt 0.1 s x 3 steps
    iio = pytest.importorskip("imageio.v2")
    pytest.importorskip("imageio_ffmpeg")
    [mp4] = write_replay(store, tmp_path / "r.mp4", episode=1, fps=12)
    reader = iio.get_reader(str(mp4), format="FFMPEG")
    try:
        assert reader.count_frames() == STEPS + 1
        assert reader.get_meta_data()["fps"] == pytest.approx(12)
        h, w, _ = replay_info(store, episode=1).canvas.shape
        assert reader.get_data(0).shape[:2] == (h + h % 2, w + w % 2)
    finally:
        reader.close()


def test_batched_world_and_a_config_that_no_longer_builds(tmp_path: Path) -> None:
    path = tmp_path / "b.db"
    env = record(BatchedEnv("navigation", 2, n_agents=2, max_steps=4), path)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(4):
        env.step(rng.uniform(-1, 1, (2, 2, env.act_dim)).astype(np.float32))
    env.close()
    assert len(list(replay_frames(path, world=1))) == 5
    con = sqlite3.connect(path)
    with con:
        con.execute("UPDATE runs SET scenario = 'gone', config = '{\"map\": 1}'")
    con.close()
    info = replay_info(path, world=1)  # extent of the recorded positions
    con = sqlite3.connect(path)
    xmin, xmax = con.execute("SELECT min(x), max(x) FROM steps WHERE world = 1 AND episode = 0").fetchone()
    con.close()
    assert info.canvas.bounds[0] < xmin and info.canvas.bounds[1] > xmax
    assert len(list(replay_frames(path, world=1))) == 5


def test_uav_release_draws_landed_sensors(tmp_path: Path) -> None:
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.policies.rollout import run_episode
    from agentsim_env.recorder.replay import _LANDED

    path = tmp_path / "u.db"
    env = record(agentsim_env.make("uav_release", zones="tiny", n_agents=1, payload=20), path)
    run_episode(env, make_policy("uav_release", env), 0)
    env.close()
    info = replay_info(path)
    *_, last = replay_frames(path, every=10_000)
    con = sqlite3.connect(path)
    landed = con.execute("SELECT land_x, land_y FROM sensors WHERE land_x IS NOT NULL").fetchall()
    con.close()
    assert len(landed) == 20
    hits = [(last[int(cy), int(cx)] == _LANDED).all() for cx, cy in (info.canvas.px(x, y) for x, y in landed)]
    assert sum(hits) >= 15  # a UAV or its trail end may sit on a few


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"run": 5}, "no run 5; runs in the store: 1"),
        ({"episode": 4}, "has no episode 4; recorded episodes: 0-1"),
        ({"world": 1}, "has no world 1; its worlds: 0"),
        ({"every": 0}, "every must be an integer >= 1"),
    ],
)
def test_replay_errors_name_what_exists(store: Path, kwargs: dict[str, int], needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        replay_frames(store, **kwargs)


def test_replay_of_a_missing_store(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="no such store"):
        replay_frames(tmp_path / "none.db")
    assert not (tmp_path / "none.db").exists()


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    return err


def test_cli_replay(store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "c.gif"
    assert main(["replay", str(store), "--episode", "1", "--every", "10", "--fps", "5", "--out", str(out)]) == 0
    assert f"written: {out}" in capsys.readouterr().out
    with Image.open(out) as im:
        assert im.n_frames == 4
    assert (
        main(
            [
                "replay",
                str(store),
                "--run",
                "1",
                "--episode",
                "0",
                "--size",
                "64",
                "--out",
                str(tmp_path / "pngs"),
            ]
        )
        == 0
    )
    assert len(list((tmp_path / "pngs").glob("frame_*.png"))) == STEPS + 1


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--episode", "9"], "recorded episodes: 0-1"),
        (["--run", "3", "--episode", "0"], "runs in the store: 1"),
        (["--episode", "0", "--fps", "0"], "--fps must be > 0"),
    ],
)
def test_cli_replay_errors(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], needle: str
) -> None:
    out = tmp_path / "v.mp4"
    assert main(["replay", str(store), *argv, "--out", str(out)]) == 2
    assert needle in _one_error_line(capsys)
    assert not out.exists()


def test_cli_replay_missing_store(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path / "x.db"), "--episode", "0", "--out", str(tmp_path / "f")]) == 2
    assert "no such store" in _one_error_line(capsys)
    assert not (tmp_path / "f").exists()


def test_missing_video_extra_names_it(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    for mod in ("imageio", "imageio.v2", "imageio_ffmpeg"):
        monkeypatch.setitem(sys.modules, mod, None)  # import raises ImportError
    with pytest.raises(ImportError, match=r'pip install "agentsim-env\[video\]"'):
        write_video([np.zeros((4, 4, 3), np.uint8)], tmp_path / "a.mp4", 10)
    assert main(["replay", str(store), "--episode", "0", "--out", str(tmp_path / "a.mp4")]) == 2
    assert 'pip install "agentsim-env[video]"' in _one_error_line(capsys)
    assert not (tmp_path / "a.mp4").exists()
    env = agentsim_env.make("navigation", n_agents=2, render_mode="rgb_array")
    with pytest.raises(ImportError, match=r"agentsim-env\[video\]"):
        RecordVideo(env, tmp_path / "videos")
    for mod in ("PIL", "PIL.Image"):
        monkeypatch.setitem(sys.modules, mod, None)
    with pytest.raises(ImportError, match=r"agentsim-env\[video\]"):
        write_video([np.zeros((4, 4, 3), np.uint8)], tmp_path / "a.gif", 10)


def test_write_video_checks_its_input(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="must end in .mp4 or .gif"):
        write_video([np.zeros((4, 4, 3), np.uint8)], tmp_path / "a.avi", 10)
    with pytest.raises(ValueError, match="fps must be a number > 0"):
        write_video([np.zeros((4, 4, 3), np.uint8)], tmp_path / "a.gif", 0)
    with pytest.raises(ValueError, match="no frames"):
        write_video([], tmp_path / "a.gif", 10)
    with pytest.raises(ValueError, match="first one's shape"):
        write_video([np.zeros((4, 4, 3), np.uint8), np.zeros((4, 6, 3), np.uint8)], tmp_path / "b.gif", 10)
    assert not (tmp_path / "b.gif").exists()


# ------------------------------------------------------------------------------------------ RecordVideo
def test_record_video_needs_rgb_array(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="render_mode='rgb_array'.*got render_mode=None"):
        RecordVideo(agentsim_env.make("navigation", n_agents=2), tmp_path)
    env = agentsim_env.make("navigation", n_agents=2, render_mode="rgb_array")
    with pytest.raises(ValueError, match="every_n"):
        RecordVideo(env, tmp_path, every_n=0)
    with pytest.raises(ValueError, match="fmt"):
        RecordVideo(env, tmp_path, fmt="avi")


@pytest.mark.parametrize("fmt", ["mp4", "gif"])
def test_record_video_every_second_episode(tmp_path: Path, fmt: str) -> None:
    if fmt == "mp4":
        pytest.importorskip("imageio_ffmpeg")
    base = agentsim_env.make("navigation", n_agents=2, max_steps=6, render_mode="rgb_array")
    env = RecordVideo(base, tmp_path / "videos", every_n=2, name_prefix="nav", fmt=fmt)
    assert env.possible_agents == base.possible_agents and env.metadata is base.metadata
    assert env.observation_space("agent_0") is base.observation_space("agent_0")
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        assert set(obs) == set(env.agents)
        assert env.recording == (seed % 2 == 0)
        _ = env.state()
        while env.agents:
            env.step({a: env.action_space(a).sample() for a in env.agents})
        assert not env.recording
    env.close()
    names = sorted(p.name for p in (tmp_path / "videos").iterdir())
    assert names == [f"nav-episode-0.{fmt}", f"nav-episode-2.{fmt}"]
    assert env.written == [tmp_path / "videos" / n for n in names]
    if fmt == "mp4":
        import imageio.v2 as iio

        reader = iio.get_reader(str(env.written[0]), format="FFMPEG")
        try:
            assert reader.count_frames() == 7  # the reset, then 6 steps
            assert reader.get_meta_data()["fps"] == pytest.approx(base.metadata["render_fps"])
        finally:
            reader.close()


def test_record_video_writes_a_cut_episode_on_close_and_reset(tmp_path: Path) -> None:
    base = agentsim_env.make("navigation", n_agents=2, max_steps=50, render_mode="rgb_array")
    env = RecordVideo(base, tmp_path, episode_trigger=lambda k: k in (1, 2), fmt="gif", fps=5)
    for _ in range(3):
        env.reset(seed=0)
        env.step({a: env.action_space(a).sample() for a in env.agents})
    assert [p.name for p in env.written] == ["rl-video-episode-1.gif"]  # cut short by the next reset
    env.close()
    assert [p.name for p in env.written] == ["rl-video-episode-1.gif", "rl-video-episode-2.gif"]
    with Image.open(env.written[1]) as im:
        assert im.info["duration"] == pytest.approx(200, abs=10)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pettingzoo.test imports its old API
def test_record_video_passes_the_parallel_api_test(tmp_path: Path) -> None:
    from pettingzoo.test import parallel_api_test

    base = agentsim_env.make("navigation", n_agents=2, max_steps=20, render_mode="rgb_array")
    env = RecordVideo(base, tmp_path, every_n=1000, fmt="gif")
    parallel_api_test(env, num_cycles=30)
    env.close()
    assert [p.name for p in env.written] == ["rl-video-episode-0.gif"]
