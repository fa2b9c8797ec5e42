"""The ``beacon_ring`` release strategy: landing targets evenly spaced on a ring around the zone centre."""

from __future__ import annotations

import numpy as np


def ring_targets(n_sensors: int, radius: float) -> np.ndarray:
    """``(n_sensors, 2)`` landing targets (offsets from the zone centre, metres) on a circle, in visiting order."""
    angles = np.linspace(0.0, 2 * np.pi, n_sensors, endpoint=False)
    return radius * np.column_stack([np.cos(angles), np.sin(angles)])
