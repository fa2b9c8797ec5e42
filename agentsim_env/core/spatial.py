"""One uniform-grid neighbour index per step, keyed by world.

The grid bins the horizontal position of every active slot into square cells of side ``cell``; worlds have
separate cell ranges, so nothing is ever found across worlds. It is built once per step (a counting sort,
O(S + cells)) and shared by the proximity sensor, collisions and the comms range graph. Positions outside
the map are clamped into the border cells: clamping is monotone, so a radius query that clamps its own cell
range still visits every item within the radius (distances are always checked exactly).

Static objects get their own grid (``build_object_grid``), rebuilt only when the scene changes; an object
is registered in every cell its footprint's bounding square touches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

# Kernels compile with error_model="numpy": every division in them is guarded or by a validated positive
# value, and dropping the per-division zero check of the default model made the scan ~20 % faster.


@dataclass(slots=True, frozen=True)
class GridSpec:
    """Geometry of a uniform grid shared by every world.

    Attributes:
        origin_x: Minimum x of the map.
        origin_y: Minimum y of the map.
        cell: Cell side in metres.
        nx: Cells along x.
        ny: Cells along y.
        n_worlds: Number of worlds.
    """

    origin_x: float
    origin_y: float
    cell: float
    nx: int
    ny: int
    n_worlds: int

    @classmethod
    def for_bounds(
        cls, bounds: tuple[float, float, float, float], cell: float, n_worlds: int, max_cells: int = 1 << 22
    ) -> GridSpec:
        """Grid covering ``bounds = (xmin, xmax, ymin, ymax)`` with cells of about ``cell`` metres.

        The cell grows when ``n_worlds * nx * ny`` would exceed ``max_cells`` so memory stays bounded.
        """
        if cell <= 0:
            raise ValueError(f"cell must be > 0, got {cell}")
        xmin, xmax, ymin, ymax = (float(b) for b in bounds)
        if not (xmax > xmin and ymax > ymin):
            raise ValueError(f"bounds must satisfy xmin < xmax and ymin < ymax, got {bounds}")
        c = float(cell)
        while True:
            nx = max(1, int(np.ceil((xmax - xmin) / c)))
            ny = max(1, int(np.ceil((ymax - ymin) / c)))
            if nx * ny * n_worlds <= max_cells:
                break
            c *= 1.5
        return cls(xmin, ymin, c, nx, ny, int(n_worlds))

    @property
    def n_cells(self) -> int:
        """Total number of cells over all worlds."""
        return self.nx * self.ny * self.n_worlds


@dataclass(slots=True)
class Grid:
    """A built grid in CSR form: items of cell ``c`` are ``items[cell_start[c]:cell_start[c + 1]]``."""

    spec: GridSpec
    cell_start: np.ndarray
    items: np.ndarray


@nb.njit(cache=True, error_model="numpy")
def cell_of(x: float, y: float, ox: float, oy: float, cell: float, nx: int, ny: int) -> tuple[int, int]:
    """Cell ``(cx, cy)`` holding the point ``(x, y)``, clamped to the grid (numba; part of the public API).

    Kernels of the sensors, comms and collisions find the cells a query box touches with it, so every user
    of the step's grid agrees with ``build_grid`` on which cell a point falls in.
    """
    cx = int(np.floor((x - ox) / cell))
    cy = int(np.floor((y - oy) / cell))
    cx = min(max(cx, 0), nx - 1)
    cy = min(max(cy, 0), ny - 1)
    return cx, cy


@nb.njit(cache=True, error_model="numpy")
def _build(pos, world, active, ox, oy, cell, nx, ny, n_cells):  # type: ignore[no-untyped-def]
    # Counting sort in three linear passes (count, prefix sum, place); placing slots in descending order
    # while decrementing each cell's end pointer leaves the items of a cell ascending and turns the end
    # pointers into start pointers, so no separate copy of the offsets is needed.
    s = pos.shape[0]
    key = np.empty(s, dtype=np.int64)
    counts = np.zeros(n_cells + 1, dtype=np.int64)
    for i in range(s):
        if not active[i]:
            key[i] = -1
            continue
        cx, cy = cell_of(pos[i, 0], pos[i, 1], ox, oy, cell, nx, ny)
        k = (world[i] * nx + cx) * ny + cy
        key[i] = k
        counts[k] += 1
    total = 0
    for c in range(n_cells):
        total += counts[c]
        counts[c] = total
    counts[n_cells] = total
    items = np.empty(total, dtype=np.int64)
    for i in range(s - 1, -1, -1):
        k = key[i]
        if k >= 0:
            counts[k] -= 1
            items[counts[k]] = i
    return counts, items


def build_grid(spec: GridSpec, pos: np.ndarray, world: np.ndarray, active: np.ndarray) -> Grid:
    """Bin every active slot by world and horizontal cell.

    Args:
        spec: Grid geometry.
        pos: Positions ``(S, 3)`` (or ``(S, 2)``).
        world: World id per slot ``(S,)``.
        active: Which slots to index ``(S,)``.

    Returns:
        The grid; items are slot indices in ascending order within each cell.
    """
    if world.shape[0] and (int(world.min()) < 0 or int(world.max()) >= spec.n_worlds):
        raise ValueError(f"world ids must be in [0, {spec.n_worlds}), got {int(world.min())}..{int(world.max())}")
    cs, items = _build(
        np.ascontiguousarray(pos),
        world,
        active,
        spec.origin_x,
        spec.origin_y,
        spec.cell,
        spec.nx,
        spec.ny,
        spec.n_cells,
    )
    return Grid(spec, cs, items)


@nb.njit(cache=True, error_model="numpy")
def _build_objects(cx, cy, rad, world, ox, oy, cell, nx, ny, n_cells):  # type: ignore[no-untyped-def]
    o = cx.shape[0]
    counts = np.zeros(n_cells + 1, dtype=np.int64)
    for p in range(2):
        if p == 1:
            for c in range(n_cells):
                counts[c + 1] += counts[c]
            fill = counts[:-1].copy()
            items = np.empty(counts[n_cells], dtype=np.int64)
        for i in range(o):
            x0, y0 = cell_of(cx[i] - rad[i], cy[i] - rad[i], ox, oy, cell, nx, ny)
            x1, y1 = cell_of(cx[i] + rad[i], cy[i] + rad[i], ox, oy, cell, nx, ny)
            for a in range(x0, x1 + 1):
                for b in range(y0, y1 + 1):
                    k = (world[i] * nx + a) * ny + b
                    if p == 0:
                        counts[k + 1] += 1
                    else:
                        items[fill[k]] = i
                        fill[k] += 1
    return counts, items


def build_object_grid(spec: GridSpec, centre: np.ndarray, footprint_radius: np.ndarray, world: np.ndarray) -> Grid:
    """Register every object in all cells its footprint's bounding square touches.

    Args:
        spec: Grid geometry (its own: object queries read their cells through the grid's spec).
        centre: Object centres ``(O, 3)``.
        footprint_radius: Horizontal bounding radius per object ``(O,)``.
        world: World id per object ``(O,)``.

    Returns:
        The object grid (an object may appear in several cells, at most once per cell).
    """
    cs, items = _build_objects(
        np.ascontiguousarray(centre[:, 0]),
        np.ascontiguousarray(centre[:, 1]),
        np.ascontiguousarray(footprint_radius, dtype=np.float64),
        world.astype(np.int64),
        spec.origin_x,
        spec.origin_y,
        spec.cell,
        spec.nx,
        spec.ny,
        spec.n_cells,
    )
    return Grid(spec, cs, items)


@nb.njit(cache=True, error_model="numpy")
def grow(a, n):  # type: ignore[no-untyped-def]
    """Double a kernel's result buffer, keeping its first ``n`` entries (numba; public API)."""
    b = np.empty(max(2 * a.shape[0], 16), dtype=a.dtype)
    b[:n] = a[:n]
    return b


@nb.njit(cache=True, error_model="numpy")
def _pairs(pos, world, cell_start, items, ox, oy, cell, nx, ny, max_dist, out_i, out_j, out_d):  # type: ignore[no-untyped-def]
    # One pass into growable buffers. Each pair (i < j) is found once: from i's side.
    n = 0
    r2 = max_dist * max_dist
    for idx in range(items.shape[0]):
        i = items[idx]
        w = world[i]
        x0, y0 = cell_of(pos[i, 0] - max_dist, pos[i, 1] - max_dist, ox, oy, cell, nx, ny)
        x1, y1 = cell_of(pos[i, 0] + max_dist, pos[i, 1] + max_dist, ox, oy, cell, nx, ny)
        for a in range(x0, x1 + 1):
            base = (w * nx + a) * ny
            # The rows of one column are consecutive cells: one contiguous run of items.
            for q in range(cell_start[base + y0], cell_start[base + y1 + 1]):
                j = items[q]
                if j <= i:
                    continue
                dx = pos[j, 0] - pos[i, 0]
                dy = pos[j, 1] - pos[i, 1]
                dz = pos[j, 2] - pos[i, 2]
                d2 = dx * dx + dy * dy + dz * dz
                if d2 <= r2:
                    if n == out_i.shape[0]:
                        out_i, out_j, out_d = grow(out_i, n), grow(out_j, n), grow(out_d, n)
                    out_i[n] = i
                    out_j[n] = j
                    out_d[n] = np.sqrt(d2)
                    n += 1
    return out_i[:n], out_j[:n], out_d[:n]


def neighbor_pairs(
    grid: Grid, pos: np.ndarray, world: np.ndarray, max_dist: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All pairs of indexed slots within ``max_dist`` (3D distance) of each other, in the same world.

    Args:
        grid: A grid built from ``pos`` this step.
        pos: Positions ``(S, 3)``.
        world: World id per slot ``(S,)``.
        max_dist: Distance threshold in metres.

    Returns:
        ``(i, j, d)``: slot arrays with ``i < j`` and their distances, each pair once.
    """
    sp = grid.spec
    cap = max(16, grid.items.shape[0])
    return _pairs(
        np.ascontiguousarray(pos),
        world,
        grid.cell_start,
        grid.items,
        sp.origin_x,
        sp.origin_y,
        sp.cell,
        sp.nx,
        sp.ny,
        float(max_dist),
        np.empty(cap, dtype=np.int64),
        np.empty(cap, dtype=np.int64),
        np.empty(cap),
    )
