"""How ``agentsim run`` ends early, and ``--render``'s refusal to play on where no window can be shown.

SIGTERM and Ctrl-C (and, with ``--render``, closing the window or Esc) end a run after the step in progress: the
store keeps every recorded step (the run is marked ``incomplete``), the summary table and the trajectory PNG cover
the episodes that ended, and one ``agentsim: ...`` line on stderr says what stopped it. Exit status: 0 for the
window, 130 for Ctrl-C, 143 for SIGTERM (128 + the signal, as shells report a signal's end). A second signal
while the first is being honoured stops at once.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType, TracebackType
from typing import Any

#: What ended a run, by signal: (words for the stop line, exit status).
SIGNAL_STOPS: dict[int, tuple[str, int]] = {signal.SIGTERM: ("SIGTERM", 143), signal.SIGINT: ("Ctrl-C", 130)}
WINDOW_STOP = ("window closed", 0)


class StopRun(Exception):
    """The live run was asked to end (window closed, SIGTERM, Ctrl-C).

    Attributes:
        words: What stopped it, for the stop line (``"SIGTERM"``, ``"Ctrl-C"``, ``"window closed"``).
        code: The exit status the command returns.
    """

    def __init__(self, words: str, code: int) -> None:  # noqa: D107 - documented above
        super().__init__(words)
        self.words = words
        self.code = code


def check_display(scenario: str) -> None:
    """Refuse ``--render`` on a machine that cannot show a window.

    Args:
        scenario: The scenario asked for (named in the suggested ``agentsim view`` command).

    Raises:
        ValueError: No display (headless SDL driver, no ``DISPLAY``/``WAYLAND_DISPLAY``, SDL cannot start its
            video system, or pygame-ce missing); the message names the reason and the browser viewer instead.
    """
    from agentsim_env.render.window import display_problem

    reason = display_problem()
    if reason is not None:
        raise ValueError(
            f"--render needs a display: {reason}; on this machine use 'agentsim view {scenario}' "
            "(the 3D viewer, in a browser) or run without --render"
        )


def _cause(exc: BaseException) -> BaseException | None:
    """The stop behind ``exc``: an exception raised inside a numba kernel's call reaches the caller as a
    ``SystemError`` whose cause is the original one."""
    from agentsim_env.render.window import WindowClosed

    seen: BaseException | None = exc
    for _ in range(8):
        if seen is None or isinstance(seen, (StopRun, WindowClosed, KeyboardInterrupt)):
            return seen
        seen = seen.__cause__ or seen.__context__
    return None


def is_stop(exc: BaseException) -> bool:
    """Whether ``exc`` asks the run to end (``StopRun``, ``WindowClosed``, ``KeyboardInterrupt``, or caused by one)."""
    return _cause(exc) is not None


def as_stop(exc: BaseException) -> StopRun:
    """The ``StopRun`` for a stop raised as (or caused by) ``StopRun``, ``WindowClosed`` or ``KeyboardInterrupt``."""
    cause = _cause(exc)
    if isinstance(cause, StopRun):
        return cause
    if isinstance(cause, KeyboardInterrupt):
        return StopRun(*SIGNAL_STOPS[signal.SIGINT])
    return StopRun(*WINDOW_STOP)


def stop_line(stop: StopRun, done: int, total: int, store: str | None, run: int | None) -> str:
    """The one line printed to stderr when a live run was stopped."""
    how = "window closed" if stop.words == WINDOW_STOP[0] else f"stopped by {stop.words}"
    line = f"agentsim: {how} after {done} of {total} episodes"
    if store:
        line += f"; recorded steps kept in {store} (run {run}, marked incomplete)"
    return line


class LiveStop:
    """While entered, SIGTERM and SIGINT ask the run to stop at the next step (``check`` raises ``StopRun``).

    The handlers only set a flag: stopping between steps never cuts a step's write to the store in half. A
    second signal raises at once. Outside the main thread (where Python allows no handlers) nothing changes.
    """

    def __init__(self) -> None:  # noqa: D107 - documented above
        self.pending: StopRun | None = None
        self._saved: dict[int, Any] = {}

    def __enter__(self) -> LiveStop:
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNAL_STOPS:
                self._saved[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        for sig, previous in self._saved.items():
            signal.signal(sig, previous)
        self._saved.clear()

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        stop = StopRun(*SIGNAL_STOPS[signum])
        if self.pending is not None:
            raise stop
        self.pending = stop

    def check(self) -> None:
        """Raise the pending ``StopRun``, if a signal asked for one.

        Raises:
            StopRun: SIGTERM or Ctrl-C arrived since the run started.
        """
        if self.pending is not None:
            raise self.pending


__all__ = ["LiveStop", "StopRun", "as_stop", "check_display", "is_stop", "stop_line"]
