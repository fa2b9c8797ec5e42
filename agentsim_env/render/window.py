"""Live window for ``render_mode="human"`` (the only pygame-ce importer).

pygame-ce is optional (``pip install "agentsim-env[render]"``); it is imported when the first frame is shown.
Headless machines can set ``SDL_VIDEODRIVER=dummy`` (frames are then drawn to no screen).

Closing the window (its close button, or Esc) raises ``WindowClosed`` from the ``step`` or ``reset`` that showed
the frame; that step has been taken (and recorded, under a recorder). SDL is asked to leave the process's signal
handlers alone, so SIGINT and SIGTERM behave as in any Python program (SDL would otherwise turn SIGTERM into a
window event that a program which does not read them never sees).
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

#: SDL video drivers that draw to no screen.
HEADLESS_DRIVERS = ("dummy", "offscreen", "evdev")
INSTALL_HINT = 'pygame-ce: pip install "agentsim-env[render]" (or pip install pygame-ce)'


class WindowClosed(Exception):
    """The live window was closed by its user (close button or Esc)."""


def _pygame() -> Any:
    # before the first import: no banner on stdout, and SDL keeps its hands off SIGINT/SIGTERM
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    os.environ.setdefault("SDL_NO_SIGNAL_HANDLERS", "1")
    try:
        import pygame
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError(f'render_mode="human" needs {INSTALL_HINT}') from exc
    return pygame


def display_problem() -> str | None:
    """Why no window can be shown on this machine, or None when one can.

    Checks, cheapest first: pygame-ce installed, ``SDL_VIDEODRIVER`` not a headless driver, on Linux a
    ``DISPLAY`` or ``WAYLAND_DISPLAY``, then SDL's own start of the video system (which is stopped again).

    Returns:
        A short reason (e.g. ``"SDL_VIDEODRIVER=dummy draws to no screen"``), or None.
    """
    chosen = os.environ.get("SDL_VIDEODRIVER", "").strip()
    if chosen and all(d.strip().lower() in HEADLESS_DRIVERS for d in chosen.split(",")):
        return f"SDL_VIDEODRIVER={chosen} draws to no screen"
    if (
        sys.platform.startswith("linux")
        and not chosen
        and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    ):  # without either, SDL tries every driver (printing their errors) and may settle on none that shows
        return "neither DISPLAY nor WAYLAND_DISPLAY is set"
    try:
        pg = _pygame()
    except ImportError:
        return f"pygame-ce is not installed ({INSTALL_HINT})"
    x11_only = sys.platform.startswith("linux") and not chosen and not os.environ.get("WAYLAND_DISPLAY")
    if x11_only:  # only X11 can work: SDL would go on to Wayland (printing libwayland's errors) and offscreen
        os.environ["SDL_VIDEODRIVER"] = "x11"
    try:
        pg.display.init()
        driver = str(pg.display.get_driver())
    except pg.error as exc:
        where = f"DISPLAY={os.environ.get('DISPLAY')}" if x11_only else "the display"
        return f"{where} cannot be opened ({exc})"
    finally:
        pg.display.quit()
        if x11_only:
            del os.environ["SDL_VIDEODRIVER"]
    if driver.lower() in HEADLESS_DRIVERS:
        return f"SDL chose its {driver!r} video driver, which draws to no screen"
    return None


@dataclass(slots=True)
class Window:
    """A pygame window that shows RGB frames at a fixed rate.

    Attributes:
        title: Window caption.
        fps: Frames per second (the window waits to keep this rate).
    """

    title: str = "agentsim"
    fps: int = 10
    _screen: Any = None
    _clock: Any = None

    def show(self, frame: np.ndarray) -> None:
        """Display an ``(H, W, 3)`` uint8 frame, creating the window on first use.

        Raises:
            WindowClosed: The user closed the window (it is closed here; the next frame opens a new one).
        """
        pg = _pygame()
        h, w, _ = frame.shape
        if self._screen is None:
            pg.display.init()
            pg.display.set_caption(self.title)
            self._screen = pg.display.set_mode((w, h))
            self._clock = pg.time.Clock()
        # read the events (not just pump them): the close button only arrives as an event
        for event in pg.event.get():
            if event.type in (pg.QUIT, pg.WINDOWCLOSE) or (event.type == pg.KEYDOWN and event.key == pg.K_ESCAPE):
                self.close()
                raise WindowClosed(f"the {self.title!r} window was closed")
        surf = pg.surfarray.make_surface(np.ascontiguousarray(frame.swapaxes(0, 1)))
        self._screen.blit(surf, (0, 0))
        pg.display.flip()
        self._clock.tick(self.fps)

    def close(self) -> None:
        """Close the window if it is open."""
        if self._screen is not None:
            _pygame().display.quit()
            self._screen = None

    def __getstate__(self) -> dict[str, Any]:
        # a window is never pickled; a copy opens its own on the next frame
        return {"title": self.title, "fps": self.fps, "_screen": None, "_clock": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        for k, v in state.items():
            object.__setattr__(self, k, v)
