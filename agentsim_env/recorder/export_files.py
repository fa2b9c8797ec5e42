"""Temporary files of an export, named so that a later export can tell whose they are.

An export writes ``steps.csv`` as ``.steps.csv.tmp-<pid>-<host>`` in the target folder and renames it when every
table is written. The process removes its temporary files itself on an error, Ctrl-C or SIGTERM; a process killed
outright (SIGKILL, a power cut) cannot, so each export first removes the temporary files of exports of this host
whose process no longer exists (and those of the earlier ``.NAME.tmp-<pid>`` form, which carried no host).
"""

from __future__ import annotations

import os
import re
import socket
from collections.abc import Iterable
from pathlib import Path

from agentsim_env.recorder.schema import _pid_alive

_TEMP = re.compile(r"\.(?P<name>.+)\.tmp-(?P<pid>[0-9]{1,9})(?:-(?P<host>.+))?")


def temp_path(path: Path) -> Path:
    """The temporary file ``path`` is written to before it is renamed: ``.NAME.tmp-<pid>-<host>`` beside it."""
    return path.with_name(f".{path.name}.tmp-{os.getpid()}-{socket.gethostname()}")


def remove_stale(folder: Path, names: Iterable[str]) -> list[Path]:
    """Remove the temporary files in ``folder`` of exports of ``names`` whose process has ended.

    Only files named as :func:`temp_path` names them, for one of ``names``, by a process of this host that no
    longer exists are removed; a temporary file of an export still running (here or on another host sharing the
    folder) is kept.

    Args:
        folder: The export folder.
        names: The file names an export writes (``steps.csv``...).

    Returns:
        The files removed.
    """
    wanted, host = set(names), socket.gethostname()
    removed = []
    for p in folder.iterdir():
        m = _TEMP.fullmatch(p.name)
        if m is None or m["name"] not in wanted or m["host"] not in (None, host) or _pid_alive(int(m["pid"])):
            continue
        try:
            p.unlink()
        except OSError:  # another export removed it first, or it is no file of ours (a folder)
            continue
        removed.append(p)
    return removed


__all__ = ["remove_stale", "temp_path"]
