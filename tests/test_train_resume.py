"""Checkpoints and ``--resume`` under damage: checkpoints are written atomically (a write killed half way leaves
only complete checkpoints), resume falls back to the newest checkpoint that loads and says which it skipped, a
resume that cannot work changes nothing, and a damaged model file gives one clear error naming it; slow: a real
``kill -9`` during a checkpoint write."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("stable_baselines3")

from agentsim_env.train.config import TrainConfig, load_config  # noqa: E402

TINY = {
    "timesteps": 1024,
    "worlds": 2,
    "checkpoint_every": 512,
    "env": {"n_agents": 2},
    "ppo": {"n_steps": 64, "batch_size": 128},
    "eval": {"seeds": 1},
}
#: The same run as ``TINY`` on the command line.
CLI = [
    "--timesteps",
    "1024",
    "--worlds",
    "2",
    "--quiet",
    "--no-eval",
    "--set",
    "checkpoint_every=512",
    "env.n_agents=2",
    "ppo.n_steps=64",
    "ppo.batch_size=128",
    "eval.seeds=1",
]


def _cfg() -> TrainConfig:
    return load_config("navigation", TINY)


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished tiny run: model.zip, config files, curve.csv, checkpoints step_512 and step_1024."""
    from agentsim_env.train.runner import train

    out = tmp_path_factory.mktemp("run") / "run"
    train(_cfg(), out)
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == [
        "step_1024.json",
        "step_1024.zip",
        "step_512.json",
        "step_512.zip",
    ]
    return out


@pytest.fixture
def run(trained: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny run, free to damage."""
    return Path(shutil.copytree(trained, tmp_path / "run"))


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _replace_member(path: Path, member: str, content: bytes) -> None:
    """Rewrite the zip at ``path`` with ``member``'s bytes replaced (a well-formed zip holding garbage)."""
    with zipfile.ZipFile(path) as src:
        items = [(info, src.read(info.filename)) for info in src.infolist()]
    with zipfile.ZipFile(path, "w") as dst:
        for info, data in items:
            dst.writestr(info, content if info.filename == member else data)


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every entry under ``folder``: file bytes, ``None`` for folders."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in folder.rglob("*")}


# ---------------------------------------------------------------------------------------------- fallback
def test_resume_skips_a_truncated_checkpoint_and_says_so(run: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.train.runner import train

    _truncate(run / "checkpoints" / "step_1024.zip")  # what a kill during its write left before
    res = train(_cfg(), run, resume=True)
    err = capsys.readouterr().err
    assert "skipped step_1024.zip: not a valid zip file" in err, err
    assert "step_512.zip" in err and res.resumed_from == run / "checkpoints" / "step_512.zip"
    assert [p.name for p, _ in res.skipped] == ["step_1024.zip"]
    assert res.timesteps == 1024 and [r["timesteps"] for r in res.curve][-1] == 1024
    from stable_baselines3 import PPO

    assert PPO.load(run / "checkpoints" / "step_1024.zip").num_timesteps == 1024  # written again, whole


def test_folders_and_temp_files_named_like_checkpoints_are_ignored(run: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.train.runner import latest_checkpoint, train

    ckpts = run / "checkpoints"
    (ckpts / "step_4096.zip").mkdir()
    (ckpts / "step_8192.zip.tmp").write_bytes(b"PK\x03\x04partial")
    stale = ckpts / ".step_2048.zip.4242.tmp"  # what a write killed half way leaves
    stale.write_bytes((ckpts / "step_1024.zip").read_bytes()[:1000])
    assert latest_checkpoint(run) == ckpts / "step_1024.zip"
    res = train(_cfg().replace(timesteps=1536), run, resume=True)
    assert res.resumed_from == ckpts / "step_1024.zip" and res.skipped == [] and res.timesteps == 1536
    assert "skipped" not in capsys.readouterr().err
    assert not stale.exists()  # the run's own leftovers are cleaned once the resume works
    assert (ckpts / "step_4096.zip").is_dir() and (ckpts / "step_8192.zip.tmp").is_file()  # not ours: kept


def test_a_checkpoint_with_a_garbage_policy_is_skipped_naming_the_part(
    run: Path, capsys: pytest.CaptureFixture
) -> None:
    from agentsim_env.train.runner import train

    _replace_member(run / "checkpoints" / "step_1024.zip", "policy.pth", b"garbage" * 50)
    res = train(_cfg(), run, resume=True)
    assert res.resumed_from == run / "checkpoints" / "step_512.zip"
    assert "skipped step_1024.zip: policy.pth is not a valid PyTorch file" in capsys.readouterr().err


def test_a_garbage_sidecar_is_tolerated(run: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.train.runner import train

    (run / "checkpoints" / "step_1024.json").write_text("{not json")
    res = train(_cfg().replace(timesteps=1536), run, resume=True)
    assert res.resumed_from == run / "checkpoints" / "step_1024.zip" and res.timesteps == 1536
    assert "step_1024.json" in capsys.readouterr().err
    assert res.wall_s > 0.0 and res.curve[-1]["episodes"] >= res.curve[0]["episodes"]  # clocks from curve.csv


def test_a_curve_row_cut_short_by_a_kill_is_dropped(run: Path) -> None:
    from agentsim_env.train.runner import train

    curve = run / "curve.csv"
    data = curve.read_bytes()
    curve.write_bytes(data[: data.rindex(b"\n", 0, len(data) - 1) + 1] + b"1024,1")  # the last row's append, killed
    res = train(_cfg().replace(timesteps=1536), run, resume=True)
    assert [r["timesteps"] for r in res.curve] == [256, 512, 768, 1280, 1536]
    assert curve.read_bytes().startswith(data[: data.rindex(b"\n", 0, len(data) - 1) + 1])  # kept rows as written


# ------------------------------------------------------------------------------------ failure changes nothing
def test_a_resume_that_cannot_work_changes_nothing(run: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.cli import main

    ckpts = run / "checkpoints"
    _truncate(ckpts / "step_1024.zip")
    _replace_member(ckpts / "step_512.zip", "policy.pth", b"garbage")
    (ckpts / "step_2048.zip").mkdir()
    before = _snapshot(run)
    args = [
        "train",
        "navigation",
        "--out",
        str(run),
        "--resume",
        *CLI,
        "--record-training",
        str(run / "t.db"),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("agentsim: error: --resume: no checkpoint in"), err
    assert "step_1024.zip: not a valid zip file" in err[0] and "step_512.zip: policy.pth" in err[0], err
    assert _snapshot(run) == before  # config.yaml, curve.csv, the store: nothing written, nothing added


def test_resume_of_a_missing_folder_creates_nothing(tmp_path: Path) -> None:
    from agentsim_env.train.runner import train

    with pytest.raises(ValueError, match="no checkpoint"):
        train(_cfg(), tmp_path / "nope", resume=True)
    assert not (tmp_path / "nope").exists()


# ------------------------------------------------------------------------------------------ atomic writes
def _crash_mid_write(target: Any) -> None:
    """Write the start of a zip to ``target`` (a path or a file), then fail as a full disk would."""
    if isinstance(target, (str, os.PathLike)):
        Path(target).write_bytes(b"PK\x03\x04 partial")
    else:
        target.write(b"PK\x03\x04 partial")
    raise OSError(28, "No space left on device")


def test_a_failed_checkpoint_write_leaves_no_checkpoint(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from stable_baselines3.common.base_class import BaseAlgorithm

    from agentsim_env.train.runner import train

    real_save = BaseAlgorithm.save
    calls = []

    def save(self: Any, path: Any, *args: Any, **kwargs: Any) -> None:
        calls.append(path)
        if len(calls) == 2:  # the second checkpoint
            _crash_mid_write(path)
        real_save(self, path, *args, **kwargs)

    monkeypatch.setattr(BaseAlgorithm, "save", save)
    with pytest.raises(OSError, match="No space left"):
        train(_cfg(), tmp_path)
    names = sorted(p.name for p in (tmp_path / "checkpoints").iterdir())
    assert "step_1024.zip" not in names and "step_512.zip" in names, names
    assert "step_1024.json" in names  # the clocks go first: a checkpoint zip never stands without them
    assert not any(n.endswith(".tmp") for n in names), names  # a failed write removes its temp file


def test_a_damaged_model_file_is_named(trained: Path, tmp_path: Path) -> None:
    import agentsim_env
    from agentsim_env.policies.learned import load_policy

    model = Path(shutil.copytree(trained, tmp_path / "m"))
    env = agentsim_env.make("navigation", n_agents=2)
    _replace_member(model / "model.zip", "policy.pth", b"garbage" * 50)
    with pytest.raises(ValueError, match=r"model\.zip.*: policy\.pth is not a valid PyTorch file"):
        load_policy(model, env)
    _truncate(model / "model.zip")
    with pytest.raises(ValueError, match=r"model\.zip.*: not a valid zip file"):
        load_policy(model, env)
    (model / "model.zip").unlink()
    (model / "model.zip").mkdir()
    with pytest.raises(ValueError, match="has no model.zip"):
        load_policy(model, env)
    (model / "checkpoints" / "step_512.zip").unlink()
    (model / "checkpoints" / "step_512.zip").mkdir()
    with pytest.raises(ValueError, match=r"step_512\.zip.*is a folder"):
        load_policy(model / "checkpoints" / "step_512.zip", env)


# ----------------------------------------------------------------------------------------------- kill -9
KILLED = """
import io, sys, time
from pathlib import Path
from stable_baselines3.common.base_class import BaseAlgorithm
from agentsim_env.train.config import load_config
from agentsim_env.train.runner import train

real_save, calls = BaseAlgorithm.save, []

def save(self, path, *args, **kwargs):  # the second checkpoint writes half its bytes, then stalls
    calls.append(path)
    if len(calls) < 2:
        return real_save(self, path, *args, **kwargs)
    buf = io.BytesIO()
    real_save(self, buf, *args, **kwargs)
    f = open(path, "wb") if isinstance(path, (str, Path)) else path
    f.write(buf.getvalue()[: len(buf.getvalue()) // 2])
    f.flush()
    Path("half_written").touch()
    time.sleep(120)

BaseAlgorithm.save = save
train(load_config("navigation", %r), "run")
"""


@pytest.mark.slow
def test_kill_9_during_a_checkpoint_write_leaves_only_complete_checkpoints(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    from agentsim_env.train.runner import train

    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED % (TINY,)],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 240
        while not (tmp_path / "half_written").exists():
            assert proc.poll() is None and time.monotonic() < deadline, "the training process ended early"
            time.sleep(0.1)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.kill()
        proc.wait()
    ckpts = tmp_path / "run" / "checkpoints"
    zips = sorted(ckpts.glob("step_*.zip"))
    assert [p.name for p in zips] == ["step_512.zip"], sorted(p.name for p in ckpts.iterdir())
    assert PPO.load(zips[0]).num_timesteps == 512
    res = train(_cfg(), tmp_path / "run", resume=True)
    assert res.resumed_from == zips[0] and res.timesteps == 1024
    assert sorted(p.name for p in ckpts.iterdir()) == [
        "step_1024.json",
        "step_1024.zip",
        "step_512.json",
        "step_512.zip",
    ]
