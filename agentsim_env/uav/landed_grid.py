"""Coarse local grid of landed sensors around each UAV (an observation channel).

For every UAV a square window of side ``extent`` centred on it and aligned with the world axes is cut into
``cells x cells`` cells; each cell counts the landed sensors of the UAV's world that fall in it. Counts are
divided by ``scale`` and clipped to ``[0, 1]`` so that the channel is bounded for learning.

Layout: ``out[u, iy, ix]`` with ``ix`` along +x (east) and ``iy`` along +y (north), cell ``(0, 0)`` at the
window's south-west corner. A sensor at offset ``(dx, dy)`` from the UAV falls in
``ix = floor((dx + extent / 2) * cells / extent)`` (same for ``iy``); the window is half open,
``[-extent/2, extent/2)`` on each axis.

Cost: sensors are sorted by world once per call, and a numba kernel visits, for each UAV, only the sensors
of its own world, so a batch of independent worlds costs the sum of ``U_w * n_w`` rather than ``U * n``.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from agentsim_env.core.validation import check_float, check_int

__all__ = ["local_counts"]


@njit(cache=True)
def _count_kernel(
    uav_xy: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    sensor_xy: np.ndarray,
    order: np.ndarray,
    cells: int,
    extent: float,
    counts: np.ndarray,
) -> None:
    """Add one to ``counts[u, iy, ix]`` for each sensor ``order[lo[u]:hi[u]]`` inside UAV ``u``'s window."""
    half = 0.5 * extent
    per_m = cells / extent
    for u in range(uav_xy.shape[0]):
        x0 = uav_xy[u, 0] - half
        y0 = uav_xy[u, 1] - half
        for k in range(lo[u], hi[u]):
            s = order[k]
            fx = (sensor_xy[s, 0] - x0) * per_m
            fy = (sensor_xy[s, 1] - y0) * per_m
            # Compare the floats before casting: a huge or NaN offset must not wrap into a valid cell.
            if fx >= 0.0 and fx < cells and fy >= 0.0 and fy < cells:
                ix = min(int(fx), cells - 1)
                iy = min(int(fy), cells - 1)
                counts[u, iy, ix] += 1.0


def local_counts(
    uav_xy: ArrayLike,
    uav_world: ArrayLike,
    sensor_xy: ArrayLike,
    sensor_world: ArrayLike,
    cells: int = 8,
    extent: float = 80.0,
    scale: float = 4.0,
    *,
    landed: ArrayLike | None = None,
    out: NDArray[np.float32] | None = None,
) -> NDArray[np.float32]:
    """Normalised counts of landed sensors in a square window around each UAV.

    Args:
        uav_xy: UAV positions ``(U, 2)`` in metres (only x and y are used; pass ``pos[:, :2]``).
        uav_world: World id of each UAV ``(U,)`` (integers).
        sensor_xy: Landing positions ``(n, 2)`` in metres.
        sensor_world: World id of each sensor ``(n,)``.
        cells: Cells per side (>= 1).
        extent: Side length of the window in metres (> 0); cells are ``extent / cells`` wide.
        scale: Count that maps to 1.0 (> 0); larger counts clip to 1.
        landed: Optional ``(n,)`` boolean mask selecting the sensors to count (e.g. those already landed);
            ``None`` counts all of them.
        out: Optional preallocated ``(U, cells, cells)`` float32 buffer, overwritten and returned.

    Returns:
        ``(U, cells, cells)`` float32 array with values in ``[0, 1]``, indexed ``[u, iy, ix]``.

    Raises:
        ValueError: On bad shapes or parameter values.
    """
    check_int("cells", cells, 1)
    check_float("extent", extent, 0.0, lo_open=True)
    check_float("scale", scale, 0.0, lo_open=True)
    uxy = np.ascontiguousarray(uav_xy, dtype=np.float64)
    uw = np.asarray(uav_world).astype(np.int64, copy=False)
    sxy = np.ascontiguousarray(sensor_xy, dtype=np.float64)
    sw = np.asarray(sensor_world).astype(np.int64, copy=False)
    if uxy.ndim != 2 or uxy.shape[1] != 2:
        raise ValueError(f"uav_xy must have shape (U, 2), got {uxy.shape}")
    if uw.shape != (uxy.shape[0],):
        raise ValueError(f"uav_world must have shape ({uxy.shape[0]},), got {uw.shape}")
    if sxy.ndim != 2 or sxy.shape[1] != 2:
        raise ValueError(f"sensor_xy must have shape (n, 2), got {sxy.shape}")
    if sw.shape != (sxy.shape[0],):
        raise ValueError(f"sensor_world must have shape ({sxy.shape[0]},), got {sw.shape}")
    shape = (uxy.shape[0], cells, cells)
    if out is None:
        out = np.zeros(shape, dtype=np.float32)
    else:
        if out.shape != shape or out.dtype != np.float32:
            raise ValueError(f"out must be a float32 array of shape {shape}, got {out.dtype} {out.shape}")
        out.fill(0.0)

    idx = np.arange(sxy.shape[0], dtype=np.int64)
    if landed is not None:
        mask = np.asarray(landed, dtype=bool)
        if mask.shape != (sxy.shape[0],):
            raise ValueError(f"landed must have shape ({sxy.shape[0]},), got {mask.shape}")
        idx = idx[mask]
    # Stable sort by world, then each UAV's sensors are the contiguous run [lo, hi) of its world id.
    order = idx[np.argsort(sw[idx], kind="stable")]
    sorted_worlds = sw[order]
    lo = np.searchsorted(sorted_worlds, uw, side="left").astype(np.int64)
    hi = np.searchsorted(sorted_worlds, uw, side="right").astype(np.int64)
    _count_kernel(uxy, lo, hi, sxy, order, cells, float(extent), out)
    # Counts stay exact in float32 (< 2^24 per cell), so dividing afterwards loses nothing.
    np.multiply(out, np.float32(1.0 / scale), out=out)
    np.clip(out, 0.0, 1.0, out=out)
    return out
