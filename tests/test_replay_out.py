"""``agentsim replay --out``: a name with an unknown extension is refused, with the supported ones listed."""

from __future__ import annotations

from pathlib import Path

import pytest

from agentsim_env.cli import main
from tests.store_helpers import small_store


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_store(tmp_path_factory.mktemp("replay_out") / "run.db")


@pytest.mark.parametrize("name", ["x.avi", "x.MOV", "frames.png"])
def test_unknown_extension_is_an_error(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    out = tmp_path / name
    assert main(["replay", str(store), "--episode", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("agentsim: error: --out"), err
    assert ".mp4" in err and ".gif" in err and "folder" in err
    assert not out.exists()


@pytest.mark.parametrize("name", ["frames", "frames.v2/", "existing.d"])
def test_folders_are_still_accepted(store: Path, tmp_path: Path, name: str) -> None:
    if name == "existing.d":
        (tmp_path / name).mkdir()
    out = tmp_path / name
    arg = str(out) + ("/" if name.endswith("/") else "")  # Path drops a trailing slash
    assert main(["replay", str(store), "--episode", "0", "--size", "32", "--out", arg]) == 0
    assert len(list(out.glob("frame_*.png"))) == 6
