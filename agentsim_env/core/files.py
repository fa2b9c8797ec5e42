"""Reading and writing small user files (zone files) with bounded work.

``read_regular`` reads at most a limit plus one byte, and only from a regular file: a device such as
``/dev/zero`` reports a size of 0 and never ends, and a FIFO blocks its reader until someone writes, so both are
refused after ``fstat`` on the opened descriptor (opened without blocking). ``parse_json`` refuses duplicate
keys, which ``json`` would otherwise resolve silently to the last value, and nesting past a bound.
``write_atomically`` replaces a file through a temporary file in the same folder (fsync, then rename), keeping
the old file's mode and owner, writing through symbolic links to the file they name, and refusing what the
process may not write.
"""

from __future__ import annotations

import errno
import json
import os
import secrets
import stat
from pathlib import Path
from typing import Any

from agentsim_env.core.validation import short_repr

__all__ = ["file_kind", "json_depth", "parse_json", "read_regular", "write_atomically"]

_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
)


def _flag(name: str) -> int:
    """The ``os.O_*`` flag ``name``, or 0 where the platform lacks it (Windows has no O_NONBLOCK)."""
    return int(getattr(os, name, 0))


def file_kind(mode: int) -> str:
    """What a ``st_mode`` names, in words (``"a regular file"``, ``"a FIFO (named pipe)"``, ...)."""
    for test, words in _KINDS:
        if test(mode):
            return words
    return "a regular file" if stat.S_ISREG(mode) else "not a regular file"


def read_regular(path: str | os.PathLike[str], limit: int, what: str = "file") -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, reading at most ``limit + 1`` of them.

    Args:
        path: The file.
        limit: Most bytes accepted.
        what: What the file is, named in the errors (e.g. ``"a zone file"``).

    Returns:
        The file's bytes.

    Raises:
        ValueError: If ``path`` is a folder, a device, a FIFO, a socket or over ``limit`` bytes; the message
            starts with the path.
        OSError: When the file cannot be opened or read.
    """
    # O_NONBLOCK: opening a FIFO that nobody writes returns at once instead of waiting for a writer
    fd = os.open(path, os.O_RDONLY | _flag("O_NONBLOCK") | _flag("O_CLOEXEC") | _flag("O_BINARY"))
    with os.fdopen(fd, "rb", buffering=0) as fh:
        st = os.fstat(fd)  # the opened file, so nothing can swap it between the check and the read
        if stat.S_ISDIR(st.st_mode):
            raise ValueError(f"{path}: is a folder, not {what}")
        if not stat.S_ISREG(st.st_mode):
            kind = file_kind(st.st_mode)
            raise ValueError(f"{path}: is {kind}, not a regular file; {what} must be a regular file")
        if st.st_size > limit:
            raise ValueError(f"{path}: {st.st_size:,} bytes; {what} is at most {limit:,} bytes")
        chunks, left = [], limit + 1
        while left > 0:  # a file that grows after fstat is still read only up to the limit
            chunk = fh.read(min(left, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            left -= len(chunk)
    data = b"".join(chunks)
    if len(data) > limit:
        raise ValueError(f"{path}: more than {limit:,} bytes; {what} is at most {limit:,} bytes")
    return data


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object's pairs as a dict, refusing a key given twice (``json`` would keep the last silently)."""
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {short_repr(key, 60)} in a JSON object; each field may be given only once")
        out[key] = value
    return out


def json_depth(value: Any, limit: int) -> int:
    """Nesting depth of decoded JSON (a scalar is 0, ``[]`` is 1), counted up to ``limit + 1`` and no further.

    Args:
        value: Decoded JSON (dicts, lists and scalars).
        limit: Depth past which counting stops (so the walk is cheap whatever the input).

    Returns:
        The depth, or ``limit + 1`` when it is deeper than ``limit``.
    """
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:  # iterative: a deep value must not exhaust the interpreter's recursion
        item, depth = stack.pop()
        if isinstance(item, (dict, list)):
            depth += 1
            if depth > limit:
                return limit + 1
            deepest = max(deepest, depth)
            stack.extend((v, depth) for v in (item.values() if isinstance(item, dict) else item))
    return deepest


def parse_json(text: str, max_depth: int) -> Any:
    """Decode JSON text, refusing duplicate keys and nesting deeper than ``max_depth``.

    Args:
        text: The JSON text.
        max_depth: Most levels of objects and lists.

    Returns:
        The decoded value.

    Raises:
        ValueError: ``json.JSONDecodeError`` on malformed text; a plain ``ValueError`` on a duplicate key
            (naming it) or too deep a nesting (also when the parser's own recursion bound is hit first).
    """
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys)
    except RecursionError:
        raise ValueError(f"JSON nested too deeply (at most {max_depth} levels are allowed)") from None
    if json_depth(data, max_depth) > max_depth:
        raise ValueError(f"JSON nested more than {max_depth} levels deep; at most {max_depth} are allowed")
    return data


def _refuse(code: int, text: str, path: Path) -> OSError:
    """An ``OSError`` whose ``strerror`` is ``text`` (shown as is by callers that print ``strerror``)."""
    return OSError(code, text, str(path))


def _checked_target(path: Path) -> tuple[Path, os.stat_result | None]:
    """The file a write to ``path`` lands in (links followed) and its ``stat``, or None when it is new."""
    target = Path(os.path.realpath(path))
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    folder = target.parent
    if st is not None:
        if not stat.S_ISREG(st.st_mode):
            raise _refuse(
                errno.EINVAL,
                f"{target} is {file_kind(st.st_mode)}, not a regular file; nothing was written",
                target,
            )
        if not _may(target, os.W_OK):
            how = f"mode {stat.S_IMODE(st.st_mode):04o}, owner uid {st.st_uid}"
            raise _refuse(
                errno.EACCES,
                f"permission denied: this process may not write {target} ({how}); nothing was written",
                target,
            )
    elif not folder.is_dir():
        raise _refuse(errno.ENOENT, f"the folder {folder} does not exist; nothing was written", target)
    if not _may(folder, os.W_OK | os.X_OK):
        raise _refuse(
            errno.EACCES,
            f"permission denied: this process may not create files in {folder} (a file "
            "is replaced through a temporary file beside it); nothing was written",
            target,
        )
    return target, st


def _may(path: Path, mode: int) -> bool:
    """``os.access`` with the effective ids where the platform supports it (as the open and rename use them)."""
    if os.access in os.supports_effective_ids:
        return os.access(path, mode, effective_ids=True)
    return os.access(path, mode)


def write_atomically(path: str | os.PathLike[str], data: bytes) -> Path:
    """Replace the file at ``path`` with ``data`` so that a reader sees the old or the new bytes, never a mix.

    The bytes go to a temporary file in the target's folder, which is flushed to disk (fsync) and renamed over
    the target. A symbolic link is followed to the file it names (the link stays). An existing file keeps its
    mode and owner; a new file gets ``0o666`` less the umask, like any file the process creates.

    Args:
        path: The file to write.
        data: Its new content.

    Returns:
        The file written (``path`` with its links resolved).

    Raises:
        OSError: When the target is not a regular file, the process may not write it or its folder, its owner
            cannot be kept, or a write fails; ``strerror`` says which, and nothing was changed.
    """
    target, st = _checked_target(Path(path))
    fd, tmp = _create_temp(target)
    try:
        if st is not None:
            if (st.st_uid, st.st_gid) != _owner(fd):
                try:
                    os.fchown(fd, st.st_uid, st.st_gid)
                except PermissionError:
                    owner = f"uid {st.st_uid}, gid {st.st_gid}"
                    raise _refuse(
                        errno.EPERM,
                        f"cannot keep the owner of {target} ({owner}) on a replacement; nothing was written",
                        target,
                    ) from None
            os.fchmod(fd, stat.S_IMODE(st.st_mode))  # after the chown, which may clear set-id bits
        with os.fdopen(fd, "wb") as fh:
            fd = -1  # owned by fh now
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        if fd >= 0:
            os.close(fd)
        tmp.unlink(missing_ok=True)
        raise
    _sync_folder(target.parent)
    return target


def _create_temp(target: Path) -> tuple[int, Path]:
    """A new, empty temporary file beside ``target``, created with ``0o666`` (the umask applies)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | _flag("O_CLOEXEC") | _flag("O_BINARY")
    for _ in range(100):
        tmp = target.parent / f".{target.name}.{secrets.token_hex(6)}.tmp"
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise _refuse(errno.EEXIST, f"cannot create a temporary file beside {target}", target)


def _owner(fd: int) -> tuple[int, int]:
    """``(uid, gid)`` of an open file."""
    st = os.fstat(fd)
    return st.st_uid, st.st_gid


def _sync_folder(folder: Path) -> None:
    """Flush the folder's entry of the renamed file to disk where the platform allows it (best effort)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems do not sync folders; the rename itself has happened
        pass
    finally:
        os.close(fd)
