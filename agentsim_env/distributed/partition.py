"""Spatial partition of one world into shards: vertical strips along x, and each strip's halo.

The map ``[x_min, x_max]`` is cut into ``K`` strips of equal width; strip ``r`` is owned by shard
``owner[r]`` (the identity at start; a strip whose shard went offline passes to the nearest live shard). A slot
belongs to the strip its x coordinate falls in (the right edge belongs to the right strip, the map's last edge to
the last strip).

The **halo** of a shard is every slot within ``halo`` metres (in x) of one of its strips and owned by another
shard: the copies ("ghosts") a shard needs so that whatever its own agents sense, hit or link to is present.
``halo_width`` derives the distance from the interactions of a scenario (proximity range plus the largest body,
collision distance, overlay and "nearest" ranges). Strips must be at least a halo wide, so that a halo only
reaches the two neighbouring strips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim_env.sim import World


def halo_width(world: World) -> float:
    """The widest interaction distance of ``world`` in metres (after a reset configured its slots).

    The largest of: the proximity range plus the largest body radius (a ray reaches the surface of a body whose
    centre is that far), twice the largest radius plus the collision margin, and with comms the overlay's link
    range, the "nearest" range and the bus's range limit. A small relative margin covers rounding.
    """
    st, cfg = world.state, world.config
    r_max = float(st.radius.max()) if st.n_slots else 0.0
    reach = [float(st.sensor_range.max()) + r_max, 2.0 * r_max + float(cfg.collision_margin)]
    if world.comms is not None:
        reach += [float(world.comms.overlay.max_range), float(world.comms.cfg.nearest_range)]
        if world.comms.cfg.max_range is not None:  # the bus's range check reads the sender's position
            reach.append(float(world.comms.cfg.max_range))
    return max(reach) * (1.0 + 1e-9) + 1e-6


@dataclass(slots=True)
class Strips:
    """``K`` vertical strips of equal width over ``[x_min, x_max]`` and which shard owns each.

    Attributes:
        edges: ``(K + 1,)`` strip edges along x.
        halo: Halo width in metres.
        owner: ``(K,)`` int64: the shard owning each strip.
    """

    edges: np.ndarray
    halo: float
    owner: np.ndarray

    @classmethod
    def build(cls, bounds: tuple[float, float, float, float], n_shards: int, halo: float) -> Strips:
        """``n_shards`` strips over the map ``bounds`` (x_min, x_max, y_min, y_max).

        Raises:
            ValueError: When a strip would be narrower than the halo (naming ``shards`` and the widths).
        """
        x0, x1 = float(bounds[0]), float(bounds[1])
        width = (x1 - x0) / n_shards
        if n_shards > 1 and width < halo:
            most = max(1, int((x1 - x0) // halo))
            raise ValueError(
                f"shards={n_shards}: each strip would be {width:.1f} m wide, narrower than the halo of "
                f"{halo:.1f} m (the widest sensing, collision or radio distance); use shards <= {most}, or a "
                f"larger map"
            )
        return cls(np.linspace(x0, x1, n_shards + 1), float(halo), np.arange(n_shards, dtype=np.int64))

    @property
    def n_strips(self) -> int:
        """Number of strips K."""
        return int(self.owner.shape[0])

    def strip_of(self, x: np.ndarray) -> np.ndarray:
        """``(n,)`` int64: the strip each x coordinate falls in."""
        return np.searchsorted(self.edges[1:-1], x, side="right").astype(np.int64)

    def owner_of(self, x: np.ndarray) -> np.ndarray:
        """``(n,)`` int64: the shard owning each x coordinate."""
        return self.owner[self.strip_of(x)]

    def ghosts(self, x: np.ndarray, slots: np.ndarray, shard: int) -> np.ndarray:
        """The slots among ``slots`` (x coordinates ``x``) that shard ``shard`` needs as ghosts.

        A slot of strip ``r`` is within the halo of strip ``r - 1`` when it lies within ``halo`` of its left
        edge, and of strip ``r + 1`` when within ``halo`` of its right edge; it is a ghost of ``shard`` when
        such a strip is the shard's and its own strip is not.
        """
        r = self.strip_of(x)
        own = self.owner[r]
        left = (x - self.edges[r] <= self.halo) & (r > 0)
        right = (self.edges[r + 1] - x <= self.halo) & (r < self.n_strips - 1)
        near = (left & (self.owner[np.maximum(r - 1, 0)] == shard)) | (
            right & (self.owner[np.minimum(r + 1, self.n_strips - 1)] == shard)
        )
        return slots[near & (own != shard)]

    def reassign(self, dead: int, alive: np.ndarray) -> None:
        """Give every strip of shard ``dead`` to the live shard whose strips are nearest (``alive``: ``(K,)`` bool).

        Raises:
            RuntimeError: When no shard is alive.
        """
        if not alive.any():
            raise RuntimeError("every shard is offline: the simulation cannot go on (reset() restarts them)")
        mine = np.flatnonzero(self.owner == dead)
        live_strips = np.flatnonzero(alive[self.owner])
        for r in mine:
            nearest = live_strips[np.argmin(np.abs(live_strips - r) * 2 + (live_strips > r))]
            self.owner[r] = self.owner[nearest]
