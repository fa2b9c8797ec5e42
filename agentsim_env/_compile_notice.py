"""One line on stderr when a simulation kernel is compiled rather than loaded from numba's on-disk cache.

The kernels are ``@numba.njit(cache=True)`` functions. numba's dispatcher (``Dispatcher.compile`` in
``numba/core/dispatcher.py``) first tries its on-disk cache and returns when that succeeds; only on a miss does
it compile, inside ``numba.core.event.trigger_event("numba:compile", data={"dispatcher": ..., ...})``. So a
listener on the ``"numba:compile"`` event hears exactly the real compilations, of every jitted function
(numba's own overloads included, hence the filter on the function's module), and nothing else: no call of a
compiled kernel goes through it, so the step hot path pays nothing.

The first time a function of this package compiles in a process, the listener prints ``NOTICE`` to stderr;
later compilations in that process print nothing. ``AGENTSIM_QUIET_COMPILE=1`` (read when the notice would be
printed) turns it off, and ``mark_shown`` tells it that the process has already told the user (the CLI's own
compile notice does).

``install`` keeps ``import agentsim_env`` from importing numba: when numba is not imported yet, it waits for
numba's import to complete (a finder on ``sys.meta_path`` that drops itself at that point) and registers the
listener then, before any kernel can be decorated or compiled.

This module imports nothing from the package.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import os
import sys
import threading
from collections.abc import Sequence
from types import ModuleType
from typing import Any

#: The line printed (once per process) when a kernel compiles.
NOTICE = (
    "agentsim: compiling simulation kernels (first use after an install or upgrade, cached afterwards; "
    "'agentsim warmup' does this ahead of time)..."
)
#: Set to 1 (or true/yes/on) to silence the notice.
QUIET_ENV = "AGENTSIM_QUIET_COMPILE"
#: Modules whose jitted functions count as simulation kernels.
PACKAGE_PREFIX = "agentsim_env"

_lock = threading.Lock()
_state = {"shown": False, "registered": False}


def quiet() -> bool:
    """Whether ``AGENTSIM_QUIET_COMPILE`` asks for no notice."""
    return os.environ.get(QUIET_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def mark_shown() -> None:
    """Record that this process has already announced a compilation: the listener stays silent from now on."""
    _state["shown"] = True


def shown() -> bool:
    """Whether the notice (or another announcement recorded by ``mark_shown``) was given in this process."""
    return _state["shown"]


def is_package_function(func: Any) -> bool:
    """Whether ``func`` (a dispatcher's Python function) is defined in this package."""
    module = getattr(func, "__module__", None) or ""
    return module == PACKAGE_PREFIX or module.startswith(PACKAGE_PREFIX + ".")


def notify(func: Any) -> bool:
    """Print ``NOTICE`` when ``func`` belongs to the package and nothing was announced yet; return whether printed."""
    if _state["shown"] or not is_package_function(func):
        return False
    with _lock:
        if _state["shown"]:
            return False
        _state["shown"] = True
    if quiet():
        return False
    try:
        print(NOTICE, file=sys.stderr, flush=True)
    except (OSError, ValueError):  # closed or missing stderr
        return False
    return True


def _register() -> None:
    """Register the ``"numba:compile"`` listener (once per process)."""
    with _lock:
        if _state["registered"]:
            return
        _state["registered"] = True
    from numba.core import event

    class _CompileListener(event.Listener):  # type: ignore[misc]
        """Hears the start of every real compilation (cache misses) and forwards the function."""

        def on_start(self, ev: Any) -> None:
            data = ev.data
            dispatcher = data.get("dispatcher") if isinstance(data, dict) else None
            notify(getattr(dispatcher, "py_func", None))

        def on_end(self, ev: Any) -> None:
            pass

    event.register("numba:compile", _CompileListener())


class _AfterNumbaImport(importlib.abc.MetaPathFinder):
    """Finds nothing itself; on the import of ``numba`` it lets the loader run and then registers the listener."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        """The spec the other finders give for ``numba``, its loader set to register the listener once loaded."""
        if fullname != "numba":
            return None
        if self in sys.meta_path:
            sys.meta_path.remove(self)
        for finder in sys.meta_path:
            find = getattr(finder, "find_spec", None)
            spec = find(fullname, path, target) if find is not None else None
            if spec is not None:
                break
        else:
            return None
        loader = spec.loader
        exec_module = getattr(loader, "exec_module", None)
        if loader is None or exec_module is None:
            return spec

        def exec_then_register(module: ModuleType) -> None:
            try:
                exec_module(module)
            finally:
                try:
                    del loader.exec_module  # type: ignore[attr-defined]  # back to the class's method
                except AttributeError:
                    pass
            _register()

        try:
            loader.exec_module = exec_then_register  # type: ignore[method-assign]
        except (AttributeError, TypeError):  # a loader that takes no attributes: register right away instead
            return None
        return spec


def install() -> None:
    """Arrange for the compile notice: register the listener now if numba is imported, else once it is."""
    if "numba.core.event" in sys.modules or "numba" in sys.modules:
        _register()
        return
    if not any(isinstance(f, _AfterNumbaImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _AfterNumbaImport())


__all__ = [
    "NOTICE",
    "PACKAGE_PREFIX",
    "QUIET_ENV",
    "install",
    "is_package_function",
    "mark_shown",
    "notify",
    "quiet",
    "shown",
]
