"""Errors of ``agentsim evaluate`` name real config keys and say what is wrong with a path."""

from __future__ import annotations

from pathlib import Path

import pytest

from agentsim_env.cli import main
from agentsim_env.uav.config import UavReleaseConfig


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: "), err
    return err


def test_fleet_too_small_names_the_config_keys(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ev"
    assert (
        main(
            [
                "evaluate",
                "--strategies",
                "B0_uniform",
                "--seeds",
                "1",
                "--set",
                "n_uavs=1",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 2
    )
    err = _one_error_line(capsys)
    assert "payload_per_uav" not in err
    # every key the message suggests raising is a real config key
    fields = set(UavReleaseConfig.__dataclass_fields__) | set(UavReleaseConfig.aliases)
    assert "raise n_uavs or payload" in err and {"n_uavs", "payload"} <= fields
    assert "--set n_uavs=4" in err  # the smallest fleet that carries the 150 default sensors
    assert not out.exists()


def test_missing_model_path_says_it_does_not_exist(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / "nonexistent" / "foo"
    assert main(["evaluate", "--strategies", "all", str(missing), "--out", str(tmp_path / "ev"), "--quiet"]) == 2
    err = _one_error_line(capsys)
    assert "does not exist" in err and "not a folder" not in err
    a_file = tmp_path / "model.zip"
    a_file.write_bytes(b"")
    assert main(["evaluate", "--strategies", str(a_file), "--out", str(tmp_path / "ev"), "--quiet"]) == 2
    assert "is a file, not a folder" in _one_error_line(capsys)
