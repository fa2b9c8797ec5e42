"""Output folders: created and proven writable before any work, so a bad path fails first, not last."""

from __future__ import annotations

import os
from pathlib import Path


def prepare_out(out: str | os.PathLike[str], option: str = "--out") -> list[Path]:
    """Create output folder ``out`` and prove it writable (a probe file is written and deleted).

    Args:
        out: The folder.
        option: What names the folder in the error (an option such as ``--out``, or ``"export folder"``).

    Returns:
        The folders this call created, deepest first (for :func:`remove_created` when the command fails).

    Raises:
        ValueError: Naming the option, the path and the OS reason, when the folder cannot be created or written.
    """
    path = Path(out)
    created: list[Path] = []
    p = path
    while not p.exists() and not p.is_symlink() and p != p.parent:
        created.append(p)
        p = p.parent
    if path.exists() and not path.is_dir():
        raise ValueError(f"{option} {str(path)!r} cannot be used as the output folder: it is a file")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".agentsim-write-probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        remove_created(created)
        raise ValueError(f"{option} {str(path)!r} cannot be created or written: {exc.strerror or exc}") from None
    return created


def remove_created(folders: list[Path]) -> None:
    """Remove the folders :func:`prepare_out` created, where they are still empty (deepest first)."""
    for d in folders:
        try:
            d.rmdir()
        except OSError:
            pass


__all__ = ["prepare_out", "remove_created"]
