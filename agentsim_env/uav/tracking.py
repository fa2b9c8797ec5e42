"""Per-world deployment state for ``uav_release`` rewards: weighted coverage and radial fidelity, updated per landing.

Coverage is tracked on a lattice over the union of the zones (``wsn.coverage.zone_grid``); each lattice point
carries the importance ``phi = sum_k w_k * rho_k(|q - c_k|)`` of the zones containing it, and the weighted
coverage of a world is ``sum phi * covered / sum phi``. Each landing is credited with the coverage it added and
with the change of its zone's radial W1 distance to the target profile (an empty zone counts as W1 = 1).
"""

from __future__ import annotations

import numpy as np

from agentsim_env.uav.wsn.coverage import zone_grid
from agentsim_env.uav.wsn.fidelity import radial_w1
from agentsim_env.uav.zones import ZoneSet

EMPTY_W1 = 1.0


class DeploymentTracker:
    """Coverage and fidelity of the sensors landed so far, in each of B worlds.

    Args:
        zones: The hot zones.
        n_worlds: Number of worlds.
        r_s: Sensing radius in metres.
        resolution: Lattice spacing in metres.
    """

    def __init__(self, zones: ZoneSet, n_worlds: int, r_s: float, resolution: float = 2.0) -> None:
        self.zones = zones
        self.r_s = float(r_s)
        self.profiles = [z.radial_profile() for z in zones.zones]
        centres, radii = zones.centres(), zones.radii()
        self.grid = zone_grid(centres, radii, resolution)
        pts = self.grid.points
        phi = np.zeros(pts.shape[0])
        for k, (z, prof) in enumerate(zip(zones.zones, self.profiles)):
            inside = np.flatnonzero(self.grid.member[:, k])
            # a lattice point on the centre stands for its cell: a power-law density (infinite at r = 0) is
            # read a quarter cell out, so phi stays finite
            r = np.maximum(np.linalg.norm(pts[inside] - centres[k], axis=1), 0.25 * resolution)
            d = z.weight * prof.density(r)
            if inside.size and not d.sum() > 0:  # a profile narrower than the lattice: its mass on the nearest point
                d[np.argmin(r)] = z.weight / (resolution * resolution)
            phi[inside] += d
        self.phi = phi / phi.sum()
        self.covered = np.zeros((n_worlds, pts.shape[0]), dtype=bool)
        self.radii_landed: list[list[list[float]]] = [[[] for _ in zones.zones] for _ in range(n_worlds)]
        self.w1 = np.full((n_worlds, len(zones.zones)), EMPTY_W1)

    def reset_world(self, w: int) -> None:
        """Forget world ``w``'s landed sensors."""
        self.covered[w] = False
        self.radii_landed[w] = [[] for _ in self.zones.zones]
        self.w1[w] = EMPTY_W1

    def weighted_coverage(self, w: int) -> float:
        """Current weighted coverage of world ``w`` in [0, 1]."""
        return float(self.phi[self.covered[w]].sum())

    def land(self, world: np.ndarray, xy: np.ndarray, zone: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Register landings (in order) and return what each one changed.

        Args:
            world: World of each landed sensor ``(k,)``.
            xy: Landing points ``(k, 2)``.
            zone: Zone the sensor was meant for ``(k,)`` (-1: none; it then counts for no zone's fidelity).

        Returns:
            ``(coverage_gain (k,), w1_change (k,))``: weighted coverage added, and the change of the zone's W1
            (negative = closer to the target profile; 0 for sensors of no zone).
        """
        k = xy.shape[0]
        gain = np.zeros(k)
        dw1 = np.zeros(k)
        if k == 0:
            return gain, dw1
        hits = self.grid.tree.query_ball_point(xy, self.r_s)
        centres, radii = self.zones.centres(), self.zones.radii()
        for i in range(k):
            w = int(world[i])
            idx = np.asarray(hits[i], dtype=np.int64)
            if idx.size:
                new = idx[~self.covered[w, idx]]
                gain[i] = self.phi[new].sum()
                self.covered[w, new] = True
            z = int(zone[i])
            if z >= 0:
                lst = self.radii_landed[w][z]
                lst.append(float(np.hypot(*(xy[i] - centres[z]))))
                new_w1 = radial_w1(np.asarray(lst), self.profiles[z], float(radii[z]))
                dw1[i] = new_w1 - self.w1[w, z]
                self.w1[w, z] = new_w1
        return gain, dw1
