"""``agentsim view --replay RUN.db --out x.mp4``: the 3D replay view exported as a video.

The argument checks run before anything is loaded or started and end with one ``agentsim: error:`` line; the
export itself (headless Chromium) is the slow test at the end.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from agentsim_env.cli import main
from tests.store_helpers import small_store


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_store(tmp_path_factory.mktemp("export") / "run.db")


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    return err


@pytest.mark.parametrize(
    ("argv", "out", "needle"),
    [
        ([], "v.avi", "exported as .mp4, .gif (got .avi)"),
        ([], "frames", "exported as .mp4, .gif (got no suffix)"),
        (["--fps", "0"], "v.mp4", "--fps must be > 0, got 0.0"),
        (["--size", "100"], "v.mp4", "--size must be an integer in 160..1920"),
        (["--size", "5000"], "v.mp4", "--size must be an integer in 160..1920"),
        (["--every", "0"], "v.mp4", "--every must be an integer >= 1, got 0"),
        (["--size", "0"], "v.mp4", "--size must be an integer in 160..1920"),
        (["--episode", "7"], "v.mp4", "recorded episodes: 0"),
        (["--speed", "5"], "v.mp4", "--speed sets the pace of a live page"),
    ],
)
def test_bad_export_arguments_give_one_line(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], out: str, needle: str
) -> None:
    target = tmp_path / out
    assert main(["view", "--replay", str(store), *argv, "--out", str(target)]) == 2
    assert needle in _one_error_line(capsys)
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary file either


@pytest.mark.parametrize(
    "argv",
    [
        ["navigation", "--out", "x.mp4"],
        ["navigation", "--fps", "5"],
        ["navigation", "--every", "2"],
        ["--replay", "run.db", "--size", "320"],
    ],
)
def test_export_options_need_replay_and_out(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    assert main(["view", *argv]) == 2
    err = _one_error_line(capsys)
    assert "--out" in err and "--replay" in err


def test_missing_playwright_names_the_extra(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "playwright", None)  # import raises ImportError
    monkeypatch.setitem(sys.modules, "playwright.sync_api", None)
    target = tmp_path / "v.mp4"
    assert main(["view", "--replay", str(store), "--out", str(target)]) == 2
    assert 'Playwright: pip install "agentsim-env[viewer]"' in _one_error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_missing_chromium_says_what_to_install(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("playwright.sync_api", reason="the dev extra installs playwright")
    monkeypatch.setenv("AGENTSIM_CHROMIUM", str(tmp_path / "no-chromium"))
    target = tmp_path / "v.mp4"
    assert main(["view", "--replay", str(store), "--out", str(target)]) == 2
    err = _one_error_line(capsys)
    assert "AGENTSIM_CHROMIUM" in err and "apt install chromium" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(("limit", "every"), [(4, 2), (3, 3)])  # the last step is drawn too: 0, 2, 4, 5 is 4
def test_too_many_frames_suggests_an_every_that_fits(
    store: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    limit: int,
    every: int,
) -> None:
    from agentsim_env.recorder import web_video as export_video

    monkeypatch.setattr(export_video, "MAX_FRAMES", limit)  # the store's episode has 6 recorded steps
    assert main(["view", "--replay", str(store), "--out", str(tmp_path / "v.mp4")]) == 2
    assert f"would draw 6 frames, at most {limit}: pass --every {every}" in _one_error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_frame_size_is_16_9_and_even() -> None:
    from agentsim_env.recorder.web_video import frame_size

    assert frame_size(960) == (960, 540)
    assert frame_size(161) == (160, 90)
    assert all(v % 2 == 0 for s in range(160, 400) for v in frame_size(s))


@pytest.mark.slow
def test_export_has_one_frame_per_chosen_step_and_shows_the_agents_moving(tmp_path: Path) -> None:
    import imageio.v2 as iio

    from agentsim_env.recorder.replay import replay_info

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
    expected = len(replay_info(db).frame_steps(10))
    out = tmp_path / "videos" / "nav.mp4"
    assert main(["view", "--replay", str(db), "--out", str(out), "--every", "10", "--size", "320", "--fps", "5"]) == 0
    assert sorted(p.name for p in out.parent.iterdir()) == ["nav.mp4"]  # the temporary file was renamed
    reader = iio.get_reader(out)
    try:
        assert reader.get_meta_data()["fps"] == pytest.approx(5)
    finally:
        reader.close()
    frames = [np.asarray(f, dtype=float) for f in iio.mimread(out)]
    assert len(frames) == expected >= 4
    assert frames[0].shape == (180, 320, 3)
    # below the step label: the scene drawn (not a blank page), and agents moving from one frame to the next
    # (pixels that changed colour strongly; an unchanged frame, encoding noise included, has none or one)
    view = [f[30:] for f in frames]
    assert view[0].std() > 10

    def changed(a: np.ndarray, b: np.ndarray) -> int:
        return int((np.abs(a - b).max(axis=2) > 60).sum())

    assert changed(view[0], view[0]) == 0
    moved = [changed(a, b) for a, b in zip(view[:3], view[1:4], strict=True)]
    assert min(moved) >= 10, moved
    assert changed(view[0], view[-1]) >= 10


@pytest.mark.slow
def test_an_interrupted_export_leaves_no_file(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from agentsim_env.recorder import web_video as export_video

    calls = []
    decode = export_video._rgb

    def stop_at_the_third(png: bytes) -> np.ndarray:
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt  # Ctrl-C while frames are being written
        return decode(png)

    monkeypatch.setattr(export_video, "_rgb", stop_at_the_third)
    target = tmp_path / "v.mp4"
    assert main(["view", "--replay", str(store), "--out", str(target), "--size", "160"]) == 130
    assert "interrupted; no video written" in capsys.readouterr().err
    assert len(calls) == 3
    assert list(tmp_path.iterdir()) == []
