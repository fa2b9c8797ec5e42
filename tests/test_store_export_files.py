"""What ``agentsim export`` leaves behind when it is stopped, and an export that writes all its files or none.

A child process runs ``agentsim export`` and is stopped while it writes ``steps.csv`` (a pause patched into the
CSV writer, so the moment is exact, not a race). A SIGTERM lets it remove its temporary files; a SIGKILL cannot,
so the next export in that folder removes the files of exports whose process is gone.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from agentsim_env.cli import main
from agentsim_env.recorder.read import TABLES
from tests.store_helpers import small_store

ROOT = Path(__file__).resolve().parents[1]
CHILD_TIMEOUT_S = 120


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_store(tmp_path_factory.mktemp("export") / "run.db")


EXPORTER = """
import sys
from agentsim_env.cli import main
from agentsim_env.recorder import read

db, out = sys.argv[1], sys.argv[2]
write = read.Store._write_csv


def paused(self, table, path):
    write(self, table, path)
    if table == "steps":  # the file is written, not yet renamed: wait here to be stopped
        print("paused", flush=True)
        sys.stdin.read()


read.Store._write_csv = paused
sys.exit(main(["export", db, "--out", out]))
"""


def _stopped_export(store: Path, out: Path, sig: int) -> tuple[int, list[str]]:
    """Run an export, stop it with ``sig`` while it writes, and return its exit status and what it left."""
    script = out.parent / "exporter.py"
    script.write_text(EXPORTER, encoding="utf-8")
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, str(script), str(store), str(out)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "paused"
        assert any(p.name.startswith(".steps.csv.tmp-") for p in out.iterdir())
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=CHILD_TIMEOUT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "Traceback" not in err, err
    return proc.returncode, sorted(p.name for p in out.iterdir())


def test_sigterm_during_export_leaves_no_temporary_file(store: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    code, left = _stopped_export(store, out, signal.SIGTERM)
    assert code == 128 + signal.SIGTERM
    assert left == []  # neither temporary files nor a part of the tables


def test_a_later_export_removes_what_a_killed_one_left(store: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    code, left = _stopped_export(store, out, signal.SIGKILL)
    assert code == -signal.SIGKILL
    assert left and all(".tmp-" in name for name in left)  # the tables written so far, none renamed
    alive = out / f".steps.csv.tmp-{os.getppid()}-{socket.gethostname()}"  # an export still running: kept
    alive.write_text("partial")
    other = out / ".notes.tmp-1"  # not an export's file: kept
    other.write_text("mine")
    assert main(["export", str(store), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([alive.name, other.name, *(f"{t}.csv" for t in TABLES)])


def test_an_interrupted_export_writes_no_table(store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """KeyboardInterrupt (Ctrl-C) while a table is written: no file of this export stays, old ones are kept."""
    from agentsim_env.recorder import read

    out = tmp_path / "out"
    out.mkdir()
    (out / "runs.csv").write_text("an earlier export\n")
    write = read.Store._write_csv

    def interrupted(self: read.Store, table: str, path: Path) -> None:
        write(self, table, path)
        if table == "steps":
            raise KeyboardInterrupt

    monkeypatch.setattr(read.Store, "_write_csv", interrupted)
    with pytest.raises(KeyboardInterrupt):
        read.export(store, out)
    assert sorted(p.name for p in out.iterdir()) == ["runs.csv"]
    assert (out / "runs.csv").read_text() == "an earlier export\n"
