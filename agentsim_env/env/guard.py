"""Refuse overlapping calls into one env from two threads.

An env is one set of arrays that ``reset`` and ``step`` rewrite in place; two threads inside it at once
interleave their stages and return a mix of both (or fail far from the cause). :class:`CallGuard` is held for
the length of each call that changes the env: a call that finds it taken raises ``RuntimeError`` naming both
calls and both threads, before it changes anything. Handing an env from one thread to another between calls is
fine; only overlapping calls are refused.

The guard is a non-blocking lock: taking and releasing it costs well under a microsecond, nothing next to a
step. A refused call never waits (waiting would hide the bug the error reports).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager


class CallGuard:
    """Held by one env call at a time (``enter`` at the start, ``exit`` in a ``finally``).

    Copies and unpickled envs get a fresh, free guard (a lock is neither copyable nor picklable, and the copy
    is a different env).
    """

    __slots__ = ("_lock", "_call", "_thread")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._call = ""
        self._thread: threading.Thread | None = None

    def enter(self, call: str) -> None:
        """Take the guard for ``call`` (a method name such as ``"step"``).

        Raises:
            RuntimeError: Another call holds it: the message names both calls and their threads.
        """
        if not self._lock.acquire(blocking=False):
            # the holder may finish meanwhile: read its name once, and say "another call" if it is gone
            held, holder = self._call, self._thread
            where = f"thread {holder.name!r}" if holder is not None else "another thread"
            raise RuntimeError(
                f"{call}() called from thread {threading.current_thread().name!r} while {held or 'another'}() "
                f"runs in {where}: an env serves one call at a time; use one env per thread, or a lock around "
                "every call"
            )
        self._call = call
        self._thread = threading.current_thread()

    def exit(self) -> None:
        """Release the guard (the call that took it has returned or raised)."""
        self._thread = None
        self._lock.release()

    @contextmanager
    def hold(self, call: str) -> Iterator[None]:
        """``with guard.hold("close"):``, for calls off the hot path (``enter``/``exit`` cost less)."""
        self.enter(call)
        try:
            yield
        finally:
            self.exit()

    def __reduce__(self) -> tuple[type[CallGuard], tuple[()]]:
        return (CallGuard, ())
