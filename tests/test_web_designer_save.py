"""The designer's Save: the file's mode and owner are kept, new files follow the umask, links are written
through, what the process may not write is refused with a message for the page, and the write is atomic."""

from __future__ import annotations

import json
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("websockets", reason="the viewer extra installs websockets")

from agentsim_env.render.web.server import ClientError  # noqa: E402
from agentsim_env.uav.designer import designer_handlers  # noqa: E402
from agentsim_env.uav.zones import load_zones, zones_from_dict  # noqa: E402

NOBODY = 65534
ZONES = {
    "version": 1,
    "map_size": [600, 400],
    "zones": [{"name": "z", "centre": [300, 200], "radius": 80, "n_sensors": 100}],
}
OLD = '{"map_size": [100, 100], "zones": [{"centre": [50, 50], "radius": 10, "n_sensors": 1}]}\n'


def save(path: Path) -> dict[str, Any]:
    """The Save handler's reply for ``ZONES`` written to ``path``."""
    reply = designer_handlers(path)["zones.save"]({"cmd": "zones.save", "zones": json.loads(json.dumps(ZONES))})
    assert reply is not None
    return reply


def mode(path: Path) -> int:
    """Permission bits of ``path`` (links followed)."""
    return stat.S_IMODE(os.stat(path).st_mode)


def only(folder: Path) -> list[str]:
    """Names in ``folder`` (a temporary file left behind would show here)."""
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture
def umask() -> Iterator[None]:
    """Run with umask 027, restored afterwards."""
    old = os.umask(0o027)
    try:
        yield
    finally:
        os.umask(old)


def test_a_new_file_follows_the_umask(tmp_path: Path, umask: None) -> None:
    path = tmp_path / "new.json"
    save(path)
    assert mode(path) == 0o640  # 0666 less 027
    assert load_zones(path) == zones_from_dict(ZONES) and only(tmp_path) == ["new.json"]


@pytest.mark.parametrize("old_mode", [0o644, 0o664, 0o600, 0o444])
def test_an_existing_file_keeps_its_mode(tmp_path: Path, umask: None, old_mode: int) -> None:
    path = tmp_path / "zones.json"
    path.write_text(OLD, encoding="utf-8")
    path.chmod(old_mode)
    if old_mode == 0o444 and not os.access(path, os.W_OK):
        pytest.skip("a read-only file is refused to this user: see the non-root test")
    save(path)
    assert mode(path) == old_mode and load_zones(path) == zones_from_dict(ZONES)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="only root can give a file away")
def test_an_existing_file_keeps_its_owner(tmp_path: Path) -> None:
    path = tmp_path / "zones.json"
    path.write_text(OLD, encoding="utf-8")
    os.chown(path, NOBODY, NOBODY)
    save(path)
    st = os.stat(path)
    assert (st.st_uid, st.st_gid) == (NOBODY, NOBODY) and load_zones(path) == zones_from_dict(ZONES)


def test_a_link_is_written_through_to_its_target(tmp_path: Path) -> None:
    real = tmp_path / "real.json"
    real.write_text(OLD, encoding="utf-8")
    real.chmod(0o640)
    link = tmp_path / "link.json"
    link.symlink_to(real.name)  # relative, as `ln -s real.json link.json` makes it
    reply = save(link)
    assert reply["path"] == str(link)
    assert link.is_symlink() and os.readlink(link) == "real.json"
    assert load_zones(real) == zones_from_dict(ZONES) and mode(real) == 0o640
    assert only(tmp_path) == ["link.json", "real.json"]


def test_a_dangling_link_creates_its_target(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "sub" / "new.json")
    save(link)
    assert link.is_symlink() and load_zones(tmp_path / "sub" / "new.json") == zones_from_dict(ZONES)


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_what_is_not_a_regular_file_is_refused(tmp_path: Path, kind: str) -> None:
    path = tmp_path / "zones.json"
    if kind == "folder":
        path.mkdir()
    else:
        os.mkfifo(path)
    with pytest.raises(ClientError, match="cannot write .*not a regular file"):
        save(path)
    assert path.is_dir() if kind == "folder" else stat.S_ISFIFO(os.stat(path).st_mode)
    assert only(tmp_path) == ["zones.json"]


def test_the_data_is_synced_before_the_rename(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "zones.json"
    path.write_text(OLD, encoding="utf-8")
    events: list[str] = []
    fsync, replace = os.fsync, os.replace

    def traced_fsync(fd: int) -> None:
        events.append("fsync-file" if stat.S_ISREG(os.fstat(fd).st_mode) else "fsync-folder")
        fsync(fd)

    def traced_replace(src: Any, dst: Any) -> None:
        events.append("rename")
        replace(src, dst)

    monkeypatch.setattr(os, "fsync", traced_fsync)
    monkeypatch.setattr(os, "replace", traced_replace)
    save(path)
    assert events[:2] == ["fsync-file", "rename"]


# ------------------------------------------------------------------- a user who may not write the file
def _save_as_nobody(path: Path) -> str:
    """The Save handler's outcome in a forked child that runs as uid/gid 65534 (what the page would show).

    A fork, not a new interpreter: the child keeps the modules already loaded, so it needs no access to the
    interpreter's own files, only to ``path``'s folder.
    """
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: drop to nobody, save, report through the pipe, and leave without cleanup
        text = "error: no outcome"
        try:
            os.setgroups([])
            os.setgid(NOBODY)
            os.setuid(NOBODY)
            try:
                text = "saved " + json.dumps(save(path))
            except ClientError as exc:
                text = f"refused: {exc}"
        except BaseException as exc:  # noqa: BLE001 - reported to the parent
            text = f"error: {exc!r}"
        finally:
            os.write(write_end, text.encode("utf-8", "backslashreplace"))
            os._exit(0)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as fh:
        out = fh.read().decode("utf-8")
    os.waitpid(pid, 0)
    return out


@pytest.fixture
def shared_folder() -> Iterator[Path]:
    """A folder every user may write (pytest's own temporary folders are closed to other users)."""
    folder = Path(tempfile.mkdtemp(prefix="designer-save-"))
    folder.chmod(0o777)
    try:
        yield folder
    finally:
        shutil.rmtree(folder)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="runs the save as another user")
def test_a_file_the_user_may_not_write_is_refused(shared_folder: Path) -> None:
    path = shared_folder / "zones.json"
    path.write_text(OLD, encoding="utf-8")
    path.chmod(0o444)  # owned by root; the folder is writable, so a rename could still replace it
    out = _save_as_nobody(path)
    assert out.startswith(f"refused: cannot write {path}: permission denied"), out
    assert "may not write" in out and "0444" in out
    assert path.read_text(encoding="utf-8") == OLD and mode(path) == 0o444 and os.stat(path).st_uid == 0
    assert only(shared_folder) == ["zones.json"]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="runs the save as another user")
def test_a_file_whose_owner_a_replacement_cannot_keep_is_refused(shared_folder: Path) -> None:
    path = shared_folder / "zones.json"
    path.write_text(OLD, encoding="utf-8")
    path.chmod(0o666)  # nobody may write it, but a file nobody creates cannot belong to root
    out = _save_as_nobody(path)
    assert out.startswith(f"refused: cannot write {path}: cannot keep the owner"), out
    assert path.read_text(encoding="utf-8") == OLD and os.stat(path).st_uid == 0
    assert only(shared_folder) == ["zones.json"]
    os.chown(path, NOBODY, NOBODY)  # nobody's own file: saved, still nobody's and 0666
    assert _save_as_nobody(path).startswith("saved ")
    assert os.stat(path).st_uid == NOBODY and mode(path) == 0o666 and load_zones(path) == zones_from_dict(ZONES)
