"""Distance-threshold collisions between agents and between agents and static objects.

As in AgentSimJS, a batch pass compares distances with a threshold: two agents collide when their centres are
closer than ``r_a + r_b + margin``; an agent collides with an object when the distance from its centre to the
object's surface is below ``r + margin``. The result is event arrays (who, with which agent or object); the
world sets the agents involved offline. Objects of other worlds are never considered.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from agentsim_env.core.scene import BOX, CYLINDER
from agentsim_env.core.spatial import Grid, cell_of, grow
from agentsim_env.core.threads import RowThreads

# Kernels compile with error_model="numpy": every division in them is guarded or by a validated positive
# value, and dropping the per-division zero check of the default model made the scan ~20 % faster.


_EMPTY = np.zeros(0, dtype=np.int64)
_EMPTY.flags.writeable = False


@dataclass(slots=True)
class CollisionEvents:
    """Collisions found in one step; one row per (agent, cause).

    Attributes:
        agent: Slot that was hit ``(C,)``.
        other_agent: Slot of the other agent, or -1 ``(C,)``.
        obj: Object id, or -1 ``(C,)``.
    """

    agent: np.ndarray
    other_agent: np.ndarray
    obj: np.ndarray

    @classmethod
    def empty(cls) -> CollisionEvents:
        """No collisions (the three columns share one read-only empty array: most steps have no collision)."""
        return cls(_EMPTY, _EMPTY, _EMPTY)

    def __len__(self) -> int:
        return int(self.agent.shape[0])

    def concat(self, other: CollisionEvents) -> CollisionEvents:
        """Both sets of events, self first."""
        return CollisionEvents(
            np.concatenate([self.agent, other.agent]),
            np.concatenate([self.other_agent, other.other_agent]),
            np.concatenate([self.obj, other.obj]),
        )


@nb.njit(cache=True, error_model="numpy")
def surface_distance(px: float, py: float, pz: float, kind: int, c: np.ndarray, h: np.ndarray) -> float:
    """Distance from a point to an object's surface (0 inside)."""
    if kind == BOX:
        dx = max(abs(px - c[0]) - h[0], 0.0)
        dy = max(abs(py - c[1]) - h[1], 0.0)
        dz = max(abs(pz - c[2]) - h[2], 0.0)
        return np.sqrt(dx * dx + dy * dy + dz * dz)
    if kind == CYLINDER:
        dr = max(np.hypot(px - c[0], py - c[1]) - h[0], 0.0)
        dz = max(abs(pz - c[2]) - h[2], 0.0)
        return np.sqrt(dr * dr + dz * dz)
    d = np.sqrt((px - c[0]) ** 2 + (py - c[1]) ** 2 + (pz - c[2]) ** 2) - h[0]
    return max(d, 0.0)


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _max_radius(radius, online):  # type: ignore[no-untyped-def]
    # The largest radius of an online slot, -1 when none is online.
    rmax = -1.0
    for i in range(radius.shape[0]):
        if online[i] and radius[i] > rmax:
            rmax = radius[i]
    return rmax


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _agent_agent(lo, hi, rmax, pos, radius, world, cell_start, items, ox, oy, cell, nx, ny, margin):  # type: ignore[no-untyped-def]
    # Pairs (i < j, found from i's side in grid order, as spatial.neighbor_pairs) whose centres are closer
    # than r_i + r_j + margin, for the grid items lo..hi-1; 2 r_max + margin bounds every threshold, so one
    # cell range serves all.
    n = 0
    out_i = np.empty(16, dtype=np.int64)
    out_j = np.empty(16, dtype=np.int64)
    max_dist = 2.0 * rmax + margin
    r2 = max_dist * max_dist
    for idx in range(lo, hi):
        i = items[idx]
        w = world[i]
        x0, y0 = cell_of(pos[i, 0] - max_dist, pos[i, 1] - max_dist, ox, oy, cell, nx, ny)
        x1, y1 = cell_of(pos[i, 0] + max_dist, pos[i, 1] + max_dist, ox, oy, cell, nx, ny)
        for a in range(x0, x1 + 1):
            base = (w * nx + a) * ny
            for q in range(cell_start[base + y0], cell_start[base + y1 + 1]):
                j = items[q]
                if j <= i:
                    continue
                dx = pos[j, 0] - pos[i, 0]
                dy = pos[j, 1] - pos[i, 1]
                dz = pos[j, 2] - pos[i, 2]
                d2 = dx * dx + dy * dy + dz * dz
                if d2 <= r2 and np.sqrt(d2) < radius[i] + radius[j] + margin:
                    if n == out_i.shape[0]:
                        out_i, out_j = grow(out_i, n), grow(out_j, n)
                    out_i[n] = i
                    out_j[n] = j
                    n += 1
    return out_i[:n], out_j[:n]


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _agent_object(
    lo,
    hi,
    pos,
    radius,
    online,
    world,
    okind,
    ocentre,
    ohalf,
    oworld,
    cell_start,
    items,
    ox,
    oy,
    cell,
    nx,
    ny,
    margin,
):  # type: ignore[no-untyped-def]
    # One pass into growable buffers, agents lo..hi-1 in slot order.
    n = 0
    out_a = np.empty(16, dtype=np.int64)
    out_o = np.empty(16, dtype=np.int64)
    for i in range(lo, hi):
        if not online[i]:
            continue
        reach = radius[i] + margin
        x0, y0 = cell_of(pos[i, 0] - reach, pos[i, 1] - reach, ox, oy, cell, nx, ny)
        x1, y1 = cell_of(pos[i, 0] + reach, pos[i, 1] + reach, ox, oy, cell, nx, ny)
        first = n  # this agent's rows start here
        last = -1
        for a in range(x0, x1 + 1):
            for b in range(y0, y1 + 1):
                k = (world[i] * nx + a) * ny + b
                for q in range(cell_start[k], cell_start[k + 1]):
                    o = items[q]
                    if o == last or oworld[o] != world[i]:
                        continue
                    d = surface_distance(pos[i, 0], pos[i, 1], pos[i, 2], okind[o], ocentre[o], ohalf[o])
                    if d < reach:
                        last = o
                        # An object listed in several cells is reported once per agent.
                        dup = False
                        for r in range(first, n):
                            if out_o[r] == o:
                                dup = True
                                break
                        if dup:
                            continue
                        if n == out_a.shape[0]:
                            out_a, out_o = grow(out_a, n), grow(out_o, n)
                        out_a[n] = i
                        out_o[n] = o
                        n += 1
    return out_a[:n], out_o[:n]


_ONE = RowThreads(1)


def _joined(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    if len(parts) == 1:
        return parts[0]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def find_collisions(
    pos: np.ndarray,
    radius: np.ndarray,
    online: np.ndarray,
    world: np.ndarray,
    agent_grid: Grid,
    scene_kind: np.ndarray,
    scene_centre: np.ndarray,
    scene_half: np.ndarray,
    scene_world: np.ndarray,
    object_grid: Grid | None,
    margin: float = 0.0,
    threads: RowThreads | None = None,
) -> CollisionEvents:
    """Find agent-agent and agent-object collisions by distance threshold.

    Args:
        pos: Positions ``(S, 3)``.
        radius: Radii ``(S,)``.
        online: Online mask ``(S,)`` (offline slots never collide).
        world: World id per slot.
        agent_grid: Grid of online agents built this step.
        scene_kind: Object kinds ``(O,)``.
        scene_centre: Object centres ``(O, 3)``.
        scene_half: Object half extents ``(O, 3)``.
        scene_world: Object worlds ``(O,)``.
        object_grid: Grid of objects (``None`` when there are none).
        margin: Extra distance added to every threshold.
        threads: Row ranges to run on (default: one range on the calling thread); the events do not depend
            on it (each range's rows are joined in range order, which is the one-range order).

    Returns:
        Events; an agent-agent collision yields one row for each of the two agents (all pairs' first
        agents, then their second agents), followed by agent-object rows in slot order.
    """
    pos = np.ascontiguousarray(pos)
    threads = threads if threads is not None else _ONE
    sp = agent_grid.spec
    m = float(margin)
    rmax = _max_radius(radius, online)
    i = j = a_obj = o_obj = _EMPTY
    if rmax >= 0.0:
        cs, items = agent_grid.cell_start, agent_grid.items
        i, j = _joined(
            threads.run(
                lambda lo, hi, _: _agent_agent(
                    lo,
                    hi,
                    rmax,
                    pos,
                    radius,
                    world,
                    cs,
                    items,
                    sp.origin_x,
                    sp.origin_y,
                    sp.cell,
                    sp.nx,
                    sp.ny,
                    m,
                ),
                items.shape[0],
            )
        )
    if object_grid is not None and scene_kind.shape[0] > 0:
        og, so = object_grid, object_grid.spec
        a_obj, o_obj = _joined(
            threads.run(
                lambda lo, hi, _: _agent_object(
                    lo,
                    hi,
                    pos,
                    radius,
                    online,
                    world,
                    scene_kind,
                    scene_centre,
                    scene_half,
                    scene_world,
                    og.cell_start,
                    og.items,
                    so.origin_x,
                    so.origin_y,
                    so.cell,
                    so.nx,
                    so.ny,
                    m,
                ),
                pos.shape[0],
            )
        )
    if not i.size and not a_obj.size:  # the common step: nothing hit, no concatenation
        return CollisionEvents.empty()
    none_a = np.full(i.shape[0] * 2, -1, dtype=np.int64)
    none_o = np.full(a_obj.shape[0], -1, dtype=np.int64)
    return CollisionEvents(
        np.concatenate([i, j, a_obj]), np.concatenate([j, i, none_o]), np.concatenate([none_a, o_obj])
    )
