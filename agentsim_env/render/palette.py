"""Colours and sizes shared by the 2D pictures: ``rgb_array`` frames, trajectory PNGs and the store's replay frames.

Each agent of a world gets its own colour from a fixed qualitative palette of :data:`MAX_DISTINCT` colours
(matplotlib's tab10 without its grey, which reads as an obstacle or an offline agent, plus indigo, gold and teal)
while there are at most that many agents; beyond that a colour tells groups apart (group ``g`` takes colour
``g % MAX_DISTINCT``), since dozens of near-identical hues would not tell agents apart anyway.

Agents and markers are drawn at their true size when that is large enough and at a minimum size in pixels
otherwise (:func:`min_agent_px`, :func:`min_marker_px`), so they read on a map of any size.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_DISTINCT", "PALETTE", "agent_colors", "min_agent_px", "min_marker_px"]

PALETTE = np.array(
    [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [188, 189, 34],
        [23, 190, 207],
        [57, 59, 121],
        [231, 186, 82],
        [0, 128, 128],
    ],
    dtype=np.uint8,
)
"""The agent colours, RGB uint8, in the order agents (or groups) take them."""
MAX_DISTINCT = len(PALETTE)
"""Most agents of a world drawn in colours of their own; more are coloured by group."""


def agent_colors(n: int, groups: np.ndarray | None = None) -> np.ndarray:
    """The RGB colours of a world's ``n`` agents.

    Args:
        n: Agents of the world (in slot order).
        groups: ``(n,)`` group ids, used when ``n`` > :data:`MAX_DISTINCT` (None or negative ids: group 0).

    Returns:
        ``(n, 3)`` uint8: agent ``i`` in ``PALETTE[i]`` up to :data:`MAX_DISTINCT` agents, else in the colour
        of its group.
    """
    if n <= MAX_DISTINCT:
        return PALETTE[:n].copy()
    g = np.zeros(n, dtype=np.int64) if groups is None else np.maximum(np.asarray(groups, dtype=np.int64), 0)
    return PALETTE[g % MAX_DISTINCT]


def min_agent_px(size: int) -> float:
    """Smallest agent radius in pixels in a picture whose longest side is ``size`` pixels (8 at 512)."""
    return max(3.0, size / 64.0)


def min_marker_px(size: int) -> float:
    """Smallest marker (goal, target, sensor) radius in pixels, for a longest side of ``size`` pixels."""
    return max(2.0, size / 160.0)
