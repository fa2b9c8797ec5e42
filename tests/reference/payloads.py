"""Fine-step reference fall of released payloads (the oracle of :func:`agentsim_env.payloads.predict_landing`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agentsim_env.payloads.ballistic import FallParams, WindFn, _integrate


def reference_fall(
    p0: ArrayLike,
    v0: ArrayLike,
    params: FallParams,
    wind_fn: WindFn | None = None,
    dt: float = 1e-4,
    t_max: float = 600.0,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Fine-step RK4 reference fall (slow for large ``n``).

    Args:
        p0: Release positions ``(n, 3)`` or ``(3,)`` with ``z > 0``.
        v0: Release velocities, same shape.
        params: Node parameters.
        wind_fn: Wind velocity as a function of height, ``z (n,) -> (n, 3)``; ``None`` is still air.
        dt: Integration step in seconds.
        t_max: Give up (``ValueError``) after this many simulated seconds.

    Returns:
        ``(xy (n, 2), t_fall (n,))``.
    """
    return _integrate(p0, v0, params, wind_fn, dt, t_max)
