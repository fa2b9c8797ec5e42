"""Live window for ``render_mode="human"`` (the only pygame-ce importer).

pygame-ce is optional (``pip install "agentsim-env[render]"``); it is imported when the first frame is shown.
Headless machines can set ``SDL_VIDEODRIVER=dummy``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


def _pygame() -> Any:
    try:
        import pygame
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError(
            'render_mode="human" needs pygame-ce: pip install "agentsim-env[render]" (or pip install pygame-ce)'
        ) from exc
    return pygame


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
        """Display an ``(H, W, 3)`` uint8 frame, creating the window on first use."""
        pg = _pygame()
        h, w, _ = frame.shape
        if self._screen is None:
            pg.display.init()
            pg.display.set_caption(self.title)
            self._screen = pg.display.set_mode((w, h))
            self._clock = pg.time.Clock()
        pg.event.pump()
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
