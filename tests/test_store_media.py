"""Reading a store from read-only media, and what a reader leaves beside a store it may write.

Read-only media are simulated honestly: the test runs the commands in a child process that sees the store's
folder as a read-only mount (``unshare -m`` and a read-only bind mount, where the test runs as root, since root
writes through any file mode), or, for any other user, in a folder of mode 0555 holding a file of mode 0444. In
both, SQLite cannot create the ``NAME-shm`` file a WAL store needs next to it, which is what a store on a CD, a
read-only network share or a container's read-only volume looks like.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import sqlite3
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from agentsim_env.cli import main
from agentsim_env.recorder.read import TABLES
from tests.store_helpers import small_store

ROOT = Path(__file__).resolve().parents[1]
CHILD_TIMEOUT_S = 120


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return small_store(tmp_path_factory.mktemp("media") / "run.db")


# ------------------------------------------------------------------------------------------ read-only media
READER = """
import json, sys
from agentsim_env.cli import main
from agentsim_env.recorder.read import open_store

db, out = sys.argv[1], sys.argv[2]
codes = {
    "runs": main(["runs", db]),
    "export": main(["export", db, "--out", out + "/export"]),
    "replay": main(["replay", db, "--episode", "0", "--out", out + "/frames"]),
}
try:
    with open_store(db) as store:
        codes["rows"] = [r["step_rows"] for r in store.run_rows()]
except ValueError as exc:
    codes["rows"] = str(exc)
print(json.dumps(codes))
"""


def _mount_read_only() -> list[str] | None:
    """A command prefix running its command with the folder given after it mounted read-only (None: no way)."""
    if shutil.which("unshare") is None:
        return None
    if subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode != 0:
        return None
    script = 'mount --bind "$1" "$1" && mount -o remount,bind,ro "$1" "$1" && shift && exec "$@"'
    return ["unshare", "-m", "sh", "-c", script, "sh"]


@pytest.fixture
def read_only_folder(tmp_path: Path) -> Iterator[tuple[Path, list[str]]]:
    """A folder the child sees read-only, and the command prefix that makes it so."""
    folder = tmp_path / "media"
    folder.mkdir()
    if os.geteuid() == 0:
        prefix = _mount_read_only()
        if prefix is None:
            pytest.skip("root writes a 0555 folder anyway, and unshare -m (for a read-only mount) is not available")
        yield folder, [*prefix, str(folder)]
        return
    yield folder, []
    for p in folder.rglob("*"):
        p.chmod(0o644)
    folder.chmod(0o755)


def _read_in_child(folder: Path, prefix: list[str], db: Path, out: Path) -> tuple[dict[str, object], str]:
    if not prefix:  # permissions do the job for this user
        for p in folder.iterdir():
            p.chmod(0o444)
        folder.chmod(0o555)
    script = out / "reader.py"
    script.write_text(READER, encoding="utf-8")
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [*prefix, sys.executable, str(script), str(db), str(out)],
        capture_output=True,
        text=True,
        env=env,
        timeout=CHILD_TIMEOUT_S,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr


def test_a_store_on_read_only_media_is_read(
    store: Path, tmp_path: Path, read_only_folder: tuple[Path, list[str]]
) -> None:
    folder, prefix = read_only_folder
    db = folder / "run.db"
    shutil.copy(store, db)
    out = tmp_path / "out"
    out.mkdir()
    codes, err = _read_in_child(folder, prefix, db, out)
    assert codes == {"runs": 0, "export": 0, "replay": 0, "rows": [18]}, err
    assert sorted(p.name for p in (out / "export").iterdir()) == sorted(f"{t}.csv" for t in TABLES)
    assert (out / "export" / "steps.csv").read_text().count("\n") == 1 + 18
    assert len(list((out / "frames").glob("frame_*.png"))) == 6
    assert sorted(p.name for p in folder.iterdir()) == ["run.db"]  # nothing was created beside it


def test_a_write_ahead_log_without_its_index_is_refused_on_read_only_media(
    store: Path, tmp_path: Path, read_only_folder: tuple[Path, list[str]]
) -> None:
    """Committed rows still in ``NAME-wal``: reading the main file alone would miss them, so it is refused."""
    folder, prefix = read_only_folder
    work = tmp_path / "work.db"
    shutil.copy(store, work)
    con = sqlite3.connect(work)
    con.execute("PRAGMA wal_autocheckpoint = 0")
    with con:
        con.execute("UPDATE runs SET label = 'only in the log'")
    shutil.copy(work, folder / "run.db")
    shutil.copy(work.with_name("work.db-wal"), folder / "run.db-wal")
    con.close()
    out = tmp_path / "out"
    out.mkdir()
    codes, err = _read_in_child(folder, prefix, folder / "run.db", out)
    assert codes["runs"] == codes["export"] == codes["replay"] == 2, err
    assert "run.db-wal" in str(codes["rows"]) and "writable folder" in str(codes["rows"])
    lines = [ln for ln in err.splitlines() if ln.startswith("agentsim: error:")]
    assert len(lines) == 3 and all("run.db-wal" in ln for ln in lines), err
    assert not (out / "export").exists() or not any((out / "export").iterdir())


def test_reading_a_writable_store_leaves_only_the_store_and_recovers_dead_runs(store: Path, tmp_path: Path) -> None:
    """Beside a store it may write, a reader leaves no ``-wal`` / ``-shm`` behind (a ``mode=ro`` connection
    would), and marks a run left ``running`` by a process that no longer exists ``incomplete``, as a writer does."""
    from agentsim_env.recorder.read import open_store

    db = tmp_path / "run.db"
    shutil.copy(store, db)
    con = sqlite3.connect(db)
    with con:
        con.execute("UPDATE runs SET status = 'running', pid = 999999999, host = ?", (socket.gethostname(),))
    con.close()
    with open_store(db) as s:
        assert [r["status"] for r in s.run_rows()] == ["incomplete"]
    assert main(["runs", str(db)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.db"]
