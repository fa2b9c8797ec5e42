"""Checkpoints of a training run: atomic writes, the list of checkpoints, and the one to resume from.

A checkpoint is ``checkpoints/step_<N>.zip`` (the SB3 model: weights, optimiser, step count) with its clocks in
``step_<N>.json`` (wall and CPU seconds, finished episodes). These, the model and the config files of a run are
written to a temporary file in the same folder (``.<name>.<pid>.tmp``), synced to disk and renamed over their
name, so a crash or ``kill -9`` leaves either the old file or the new one, never part of one; the sidecar is
written before its zip, so a zip always has its clocks. A temporary file left by a killed write is removed when
the next run in the folder starts.

Resuming tries the checkpoints newest first and takes the first that loads, naming every one it skipped and why;
folders and other files named like checkpoints are not checkpoints.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "Resumed",
    "checkpoints",
    "find_resumable",
    "latest_checkpoint",
    "read_clocks",
    "remove_stale_temps",
    "write_atomic",
    "write_json_atomic",
    "write_model_atomic",
]

_NAME = re.compile(r"step_(\d+)\.zip")
#: The temporary files of ``write_atomic`` for the files a run writes (anything else in the folder is not ours).
_TEMP = re.compile(r"\.(step_\d+\.(zip|json)|model\.zip|config\.json|curve\.csv)\.\d+\.tmp")
#: Skipped checkpoints named in a "none loads" error (the rest are counted).
_MAX_NAMED = 4


def _temp_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def _sync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (where the platform allows a folder to be synced)."""
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_atomic(path: str | Path, write: Callable[[Path], Any]) -> Path:
    """Write ``path`` whole or not at all: ``write(tmp)`` writes a temporary file beside it, then a rename.

    Args:
        path: The file to (re)write.
        write: Writes the content to the file path it is given.

    Returns:
        ``path``.

    Raises:
        OSError: From the write or the rename; the temporary file is removed and ``path`` is unchanged.
    """
    path = Path(path)
    tmp = _temp_path(path)
    try:
        write(tmp)
        with open(tmp, "rb") as f:  # on disk before the rename, so the new name never points at lost data
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _sync_folder(path.parent)
    return path


def write_json_atomic(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON to ``path`` atomically (see ``write_atomic``)."""
    text = json.dumps(obj, indent=2)
    return write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def write_model_atomic(model: Any, path: str | Path) -> Path:
    """Save an SB3 model as ``path`` atomically (see ``write_atomic``)."""
    return write_atomic(path, model.save)


def remove_stale_temps(folder: str | Path) -> list[Path]:
    """Remove the temporary files that writes killed half way left in ``folder`` (only those of a run's files).

    Returns:
        The files removed.
    """
    removed = []
    with contextlib.suppress(OSError):
        for p in Path(folder).iterdir():
            if _TEMP.fullmatch(p.name) and p.is_file() and not p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()
                    removed.append(p)
    return removed


def checkpoints(out: str | Path) -> list[Path]:
    """The checkpoint files ``checkpoints/step_<N>.zip`` of a run folder, newest (largest N) first.

    Folders, temporary files and other names that merely look like a checkpoint are left out.
    """
    folder = Path(out) / "checkpoints"
    if not folder.is_dir():
        return []
    found = []
    for p in folder.iterdir():
        m = _NAME.fullmatch(p.name)
        if m and p.is_file():
            found.append((int(m.group(1)), p))
    return [p for _, p in sorted(found, reverse=True)]


def latest_checkpoint(out: str | Path) -> Path | None:
    """The newest checkpoint file of a run folder (``None`` when there is none); it is not loaded."""
    found = checkpoints(out)
    return found[0] if found else None


def read_clocks(path: str | Path) -> dict[str, float] | None:
    """The clocks of a checkpoint's sidecar ``step_<N>.json`` (``None`` when missing or not valid)."""
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(raw, dict):
        return None
    clocks = {}
    for key in ("wall_s", "cpu_s", "episodes"):
        v = raw.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            return None
        clocks[key] = float(v)
    return clocks


@dataclass
class Resumed:
    """The checkpoint a run resumes from.

    Attributes:
        model: The loaded model.
        path: Its ``step_<N>.zip``.
        clocks: Wall and CPU seconds and finished episodes at the checkpoint (``None``: its sidecar is missing or
            not valid JSON with those numbers).
        skipped: Newer checkpoints that did not load, with the reason.
    """

    model: Any
    path: Path
    clocks: dict[str, float] | None
    skipped: list[tuple[Path, str]] = field(default_factory=list)


def _attempts(out: Path, load: Callable[[Path], Any]) -> Iterator[tuple[Path, Any, str | None]]:
    from agentsim_env.policies.learned import ModelFileError

    for path in checkpoints(out):
        try:
            yield path, load(path), None
        except ModelFileError as exc:
            yield path, None, exc.reason


def find_resumable(out: str | Path, load: Callable[[Path], Any]) -> Resumed:
    """The newest checkpoint of the run folder ``out`` that loads; nothing is written.

    Args:
        out: The run folder.
        load: Loads one checkpoint (``agentsim_env.policies.learned.load_model`` with the env); raises
            ``ModelFileError`` for one that does not load.

    Returns:
        The model, its checkpoint, its clocks and the newer checkpoints skipped.

    Raises:
        ValueError: No checkpoint, or none that loads (each is named with its reason, in one line).
    """
    out = Path(out)
    skipped: list[tuple[Path, str]] = []
    for path, model, reason in _attempts(out, load):
        if reason is None:
            return Resumed(model, path, read_clocks(path.with_suffix(".json")), skipped)
        skipped.append((path, reason))
    where = str(out / "checkpoints")
    if not skipped:
        raise ValueError(f"--resume: no checkpoint in {where!r}")
    named = "; ".join(f"{p.name}: {reason}" for p, reason in skipped[:_MAX_NAMED])
    more = f"; and {len(skipped) - _MAX_NAMED} more" if len(skipped) > _MAX_NAMED else ""
    raise ValueError(f"--resume: no checkpoint in {where!r} loads, nothing was changed: {named}{more}")
