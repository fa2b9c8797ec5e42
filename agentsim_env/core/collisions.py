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
from agentsim_env.core.spatial import Grid, _cell_of, neighbor_pairs


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
        """No collisions."""
        e = np.zeros(0, dtype=np.int64)
        return cls(e, e.copy(), e.copy())

    def __len__(self) -> int:
        return int(self.agent.shape[0])

    def concat(self, other: CollisionEvents) -> CollisionEvents:
        """Both sets of events, self first."""
        return CollisionEvents(
            np.concatenate([self.agent, other.agent]),
            np.concatenate([self.other_agent, other.other_agent]),
            np.concatenate([self.obj, other.obj]),
        )


@nb.njit(cache=True)
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


@nb.njit(cache=True)
def _agent_object(pos, radius, online, world, okind, ocentre, ohalf, oworld, cell_start, items,
                  ox, oy, cell, nx, ny, margin, fill, out_a, out_o):  # type: ignore[no-untyped-def]
    n = 0
    for i in range(pos.shape[0]):
        if not online[i]:
            continue
        reach = radius[i] + margin
        x0, y0 = _cell_of(pos[i, 0] - reach, pos[i, 1] - reach, ox, oy, cell, nx, ny)
        x1, y1 = _cell_of(pos[i, 0] + reach, pos[i, 1] + reach, ox, oy, cell, nx, ny)
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
                        # An object listed in several cells is reported once: skip repeats of this agent.
                        dup = False
                        if fill:
                            for r in range(n - 1, -1, -1):
                                if out_a[r] != i:
                                    break
                                if out_o[r] == o:
                                    dup = True
                                    break
                            if not dup:
                                out_a[n] = i
                                out_o[n] = o
                        if not dup:
                            n += 1
                        last = o
    return n


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

    Returns:
        Events; an agent-agent collision yields one row for each of the two agents.
    """
    events = CollisionEvents.empty()
    if online.any():
        rmax = float(radius[online].max())
        i, j, d = neighbor_pairs(agent_grid, pos, world, 2.0 * rmax + margin)
        hit = d < radius[i] + radius[j] + margin
        i, j = i[hit], j[hit]
        if i.size:
            neg = np.full(2 * i.size, -1, dtype=np.int64)
            events = CollisionEvents(np.concatenate([i, j]), np.concatenate([j, i]), neg)
    if object_grid is not None and scene_kind.shape[0] > 0:
        sp = object_grid.spec
        args = (np.ascontiguousarray(pos), radius, online, world, scene_kind, scene_centre, scene_half,
                scene_world, object_grid.cell_start, object_grid.items, sp.origin_x, sp.origin_y, sp.cell,
                sp.nx, sp.ny, float(margin))
        e = np.zeros(0, dtype=np.int64)
        n = _agent_object(*args, False, e, e)
        out_a = np.empty(n, dtype=np.int64)
        out_o = np.empty(n, dtype=np.int64)
        m = _agent_object(*args, True, out_a, out_o)
        out_a, out_o = out_a[:m], out_o[:m]
        events = events.concat(CollisionEvents(out_a, np.full(m, -1, dtype=np.int64), out_o))
    return events
