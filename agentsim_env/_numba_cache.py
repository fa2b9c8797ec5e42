"""Where numba keeps the compiled kernels when the package's own directories are read-only.

The kernels compile with ``@numba.njit(cache=True)``. numba picks the cache directory of a function when the
function is decorated, that is when its module is imported, trying its locators in order
(``numba.core.caching.CacheImpl._locator_classes``):

1. ``numba.config.CACHE_DIR``, when set (``UserProvidedCacheLocator``). numba reads it from
   ``NUMBA_CACHE_DIR`` (or a ``.numba_config.yaml``) when numba is imported, and again only when a compilation
   calls ``numba.core.config.reload_config``, never at decoration time;
2. the ``__pycache__`` directory next to the source file (``InTreeCacheLocator``);
3. numba's user-wide cache directory, ``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba`` on Linux
   (``UserWideCacheLocator``).

A locator is usable when its directory can be created and a temporary file written in it. When none is, the
decorator raises ``RuntimeError: cannot cache function ...: no locator available``, so a read-only install run
without a writable home directory could not even import its kernels.

``ensure_numba_cache`` runs when the package is imported, before any kernel module, and does nothing unless
the package's directories and the user-wide directory are all unusable and no cache directory was chosen.
Then it points ``NUMBA_CACHE_DIR`` (and ``numba.config.CACHE_DIR``, when numba is already imported) at a
private directory under the temporary directory, or, when even that cannot be written, lets the kernels
compile without a cache; either way it warns once. Child processes inherit the chosen directory.

This module imports nothing from the package.
"""

from __future__ import annotations

import os
import stat
import tempfile
import warnings
from collections.abc import Callable, Iterator

PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))
FALLBACK_PREFIX = "agentsim-env-numba-cache-"


def _writable(path: str, create: bool) -> bool:
    """numba's test of a cache directory: it exists (made if ``create``) and takes a temporary file.

    Without ``create``, a missing directory counts as writable when its parent is (numba would create it).
    """
    try:
        if create:
            os.makedirs(path, exist_ok=True)
        elif not os.path.isdir(path):
            return os.access(os.path.dirname(path), os.W_OK | os.X_OK)
        tempfile.TemporaryFile(dir=path).close()
    except OSError:
        return False
    return True


def _source_dirs(root: str) -> Iterator[str]:
    """``root`` and every package directory below it (those holding an ``__init__.py``)."""
    stack = [root]
    while stack:
        d = stack.pop()
        yield d
        try:
            with os.scandir(d) as entries:
                subs = [e.path for e in entries if e.is_dir(follow_symlinks=False) and e.name != "__pycache__"]
        except OSError:
            continue
        stack.extend(p for p in subs if os.path.isfile(os.path.join(p, "__init__.py")))


def in_tree_writable(root: str = PACKAGE_DIR) -> bool:
    """Whether numba can cache next to every source file of the package (its ``__pycache__`` directories)."""
    return all(_writable(os.path.join(d, "__pycache__"), create=False) for d in _source_dirs(root))


def private_dir(parent: str) -> str | None:
    """``parent/agentsim-env-numba-cache-<uid>``, created mode 0o700, or None when it cannot be used.

    numba unpickles what it finds in a cache directory, so a directory that another user owns or may write
    into is refused rather than used.
    """
    uid = os.getuid() if hasattr(os, "getuid") else None
    path = os.path.join(parent, f"{FALLBACK_PREFIX}{'user' if uid is None else uid}")
    try:
        os.mkdir(path, 0o700)
    except FileExistsError:
        pass
    except OSError:
        return None
    try:
        st = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode):
        return None
    if uid is not None and (st.st_uid != uid or st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)):
        return None
    return path if _writable(path, create=False) else None


def _compile_uncached() -> None:
    """Let ``cache=True`` functions that numba finds no cache location for compile without a cache.

    numba's dispatcher starts with a null cache and replaces it in ``enable_caching``; where that raises the
    "no locator available" error, the null cache stays.
    """
    from numba.core.dispatcher import Dispatcher

    enable: Callable[..., None] = Dispatcher.enable_caching
    if getattr(enable, "_uncached_fallback", False):
        return

    def enable_caching(self: Dispatcher) -> None:
        try:
            enable(self)
        except RuntimeError as exc:
            if "no locator available" not in str(exc):
                raise

    enable_caching._uncached_fallback = True  # type: ignore[attr-defined]
    Dispatcher.enable_caching = enable_caching  # type: ignore[method-assign]


def ensure_numba_cache(root: str = PACKAGE_DIR, temp_dir: Callable[[], str] = tempfile.gettempdir) -> str | None:
    """Give numba a writable cache directory when its default ones are unusable (see the module docstring).

    Args:
        root: The package directory whose kernels are cached.
        temp_dir: Where the fallback directory goes (``tempfile.gettempdir``; it raises when no temporary
            directory is usable).

    Returns:
        None when numba's own choice stands (nothing was changed), the fallback directory now in
        ``NUMBA_CACHE_DIR``, or ``""`` when the kernels compile without a cache.
    """
    if os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("NUMBA_CACHE_LOCATOR_CLASSES"):
        return None
    if not os.path.isdir(root) or in_tree_writable(root):
        return None
    try:  # numba is needed from here on: the locators' own settings and user-wide directory
        from numba.core import config
        from numba.misc.appdirs import AppDirs
    except ImportError:
        return None
    if getattr(config, "CACHE_DIR", "") or getattr(config, "CACHE_LOCATOR_CLASSES", ""):
        return None  # chosen in a .numba_config.yaml
    user_dir = AppDirs(appname="numba", appauthor=False).user_cache_dir
    if _writable(user_dir, create=True):
        return None
    try:
        path = private_dir(temp_dir())
    except OSError:  # no usable temporary directory either
        path = None
    if path is not None:
        os.environ["NUMBA_CACHE_DIR"] = path
        setattr(config, "CACHE_DIR", path)  # noqa: B010 (numba.config defines its settings at run time)
        # numba re-reads every NUMBA_* variable at the next compilation when it sees one change, which would
        # undo settings made in code since numba was imported: record this one as already read
        seen = getattr(getattr(config, "_env_reloader", None), "old_environ", None)
        if isinstance(seen, dict):
            seen["NUMBA_CACHE_DIR"] = path
        warnings.warn(
            f"agentsim_env: numba cannot cache kernels next to the package or in {user_dir} (not writable); "
            f"caching them in {path} (set NUMBA_CACHE_DIR to choose a directory)",
            RuntimeWarning,
            stacklevel=2,
        )
        return path
    _compile_uncached()
    warnings.warn(
        f"agentsim_env: no writable directory for numba's cache (the package, {user_dir}, the temporary "
        "directory); kernels compile at every start (set NUMBA_CACHE_DIR to a writable directory)",
        RuntimeWarning,
        stacklevel=2,
    )
    return ""


__all__ = ["FALLBACK_PREFIX", "PACKAGE_DIR", "ensure_numba_cache", "in_tree_writable", "private_dir"]
