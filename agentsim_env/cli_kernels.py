"""Whether numba's kernel cache is warm, and the one-line notice of ``agentsim`` commands when it is not.

``agentsim warmup`` (and every command that compiled something) leaves a marker file in numba's cache directory
naming the versions that decide whether the cache is reused; a command finding no such marker announces, once,
that the first run compiles (``announce_compile``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from agentsim_env import _compile_notice

#: File in the numba cache directory whose content (versions) says the kernels were compiled and cached.
WARM_MARKER = ".agentsim-kernels-warm"
COMPILE_NOTICE = "agentsim: compiling simulation kernels (first run only, ~30 s)..."


def _kernel_cache_dir() -> Path | None:
    """The directory numba caches the package's kernels in (None: no writable one is known)."""
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if chosen:
        return Path(chosen)
    from agentsim_env._numba_cache import PACKAGE_DIR, in_tree_writable

    if in_tree_writable():
        return Path(PACKAGE_DIR) / "__pycache__"
    try:
        from numba.misc.appdirs import AppDirs
    except ImportError:
        return None
    return Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)


def _stamp() -> str:
    """What the warm marker records: the versions that decide whether numba's cache is reused."""
    from importlib.metadata import PackageNotFoundError, version

    import agentsim_env

    try:
        numba_version = version("numba")
    except PackageNotFoundError:
        numba_version = "?"
    py = ".".join(map(str, sys.version_info[:2]))
    return f"agentsim_env {agentsim_env.__version__} numba {numba_version} python {py}\n"


def kernels_cold() -> bool:
    """Whether the numba kernel cache looks cold (no warm marker with the current versions)."""
    d = _kernel_cache_dir()
    if d is None:
        return True
    try:
        return (d / WARM_MARKER).read_text(encoding="utf-8") != _stamp()
    except OSError:
        return True


def announce_compile() -> bool:
    """Print the one-line compile notice to stderr when the kernel cache is cold; return whether it was."""
    cold = kernels_cold()
    if cold and not _compile_notice.quiet():  # AGENTSIM_QUIET_COMPILE=1 silences both notices
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)
        _compile_notice.mark_shown()  # the library's own notice (on an actual compilation) would repeat it
    return cold


def mark_warm() -> None:
    """Record that the kernels are compiled and cached (silently skipped where the cache is not writable)."""
    d = _kernel_cache_dir()
    if d is None:
        return
    try:
        d.mkdir(parents=True, exist_ok=True)
        (d / WARM_MARKER).write_text(_stamp(), encoding="utf-8")
    except OSError:
        pass
