"""The shipped release strategies B0-B8 (domain reference 5.2), one ``ReleaseStrategy`` class each.

Each class declares its options as fields (with ``bounds``) and builds its targets in ``pattern`` from the
generators of ``targets``. Sectors (domain 5.3): deterministic patterns (B1-LD, B2, B3, B4, B5, B8) are built
for the whole zone and only the points in the wedge are kept; random patterns (B0, B1, B6) and the ergodic
trajectory (B7) produce ``sector_quota(N, sector)`` targets inside the wedge.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from agentsim_env.policies.release.planning import TWO_PI, in_sector, sector_quota
from agentsim_env.policies.release.strategy import Bound, Choice, Pattern, PlanContext, ReleaseStrategy
from agentsim_env.policies.release.targets import (
    cvt_points,
    drop_clusters,
    ergodic_points,
    lane_points,
    orient,
    random_wedge_points,
    ring_points,
    serpentine,
    spiral_points,
    tour,
)

__all__ = [
    "SHIPPED",
    "B0Uniform",
    "B1InverseCdf",
    "B1LDSunflower",
    "B2Rings",
    "B3Spiral",
    "B4Boustrophedon",
    "B5Cvt",
    "B6DropClusters",
    "B7Ergodic",
    "B8Teleport",
]


@dataclass(frozen=True, kw_only=True)
class B0Uniform(ReleaseStrategy):
    """B0: uniform random targets (ignores the profile), toured nearest-neighbour + 2-opt."""

    name: ClassVar[str] = "B0_uniform"
    description: ClassVar[str] = "uniform random targets r = R sqrt(u) (ignores the profile), NN + 2-opt tour"

    def pattern(self, ctx: PlanContext) -> Pattern:
        """Random targets uniform over the disc (or wedge), in tour order."""
        pts = random_wedge_points(ctx.profile, ctx.n_sensors, ctx.sector, ctx.rng, follow_profile=False)
        return Pattern(tour(pts, ctx.start, self.two_opt))


@dataclass(frozen=True, kw_only=True)
class B1InverseCdf(ReleaseStrategy):
    """B1: random targets distributed as the profile (inverse-CDF radii), toured nearest-neighbour + 2-opt."""

    name: ClassVar[str] = "B1_inverse_cdf"
    description: ClassVar[str] = "profile-distributed random targets r = F^-1(u), NN + 2-opt tour"

    def pattern(self, ctx: PlanContext) -> Pattern:
        """Profile-distributed random targets in the wedge, in tour order."""
        pts = random_wedge_points(ctx.profile, ctx.n_sensors, ctx.sector, ctx.rng)
        return Pattern(tour(pts, ctx.start, self.two_opt))


@dataclass(frozen=True, kw_only=True)
class B1LDSunflower(ReleaseStrategy):
    """B1-LD: the sunflower low-discrepancy set following the profile, toured nearest-neighbour + 2-opt."""

    name: ClassVar[str] = "B1LD_sunflower"
    description: ClassVar[str] = "sunflower low-discrepancy targets following the profile, NN + 2-opt tour"

    def layout(self, ctx: PlanContext) -> NDArray[np.float64]:
        """The whole zone's points ``(N, 2)`` (offsets), before the wedge is cut out."""
        return np.asarray(ctx.profile.low_discrepancy(ctx.n_sensors), dtype=np.float64)

    def pattern(self, ctx: PlanContext) -> Pattern:
        """The layout's points in the wedge, in tour order."""
        pts = self.layout(ctx)
        return Pattern(tour(pts[in_sector(pts, ctx.sector)], ctx.start, self.two_opt))


@dataclass(frozen=True, kw_only=True)
class B2Rings(ReleaseStrategy):
    """B2: concentric rings (equal mass per ring), releases evenly spaced on each circle.

    Args:
        n_rings: Number of rings (``None``: about ``sqrt(N / 2 pi)``, or isotropic spacing).
        ring_radii: ``"cdf"`` (radii at CDF midpoints, equal counts) or ``"isotropic"`` (radial spacing
            ``1 / sqrt(N rho)``, counts by annulus mass).
    """

    name: ClassVar[str] = "B2_rings"
    description: ClassVar[str] = (
        "concentric rings at CDF midpoints, equal mass per ring, releases evenly spaced on circles"
    )
    release_speed: ClassVar[float] = 5.0
    bounds: ClassVar = {"n_rings": Bound(1), "ring_radii": Choice(("cdf", "isotropic"))}

    n_rings: int | None = None
    ring_radii: str = "cdf"

    def pattern(self, ctx: PlanContext) -> Pattern:
        """The rings' points in the wedge, flown ring by ring (outermost first), alternating direction."""
        pts, ring, theta = ring_points(ctx.profile, ctx.n_sensors, self.n_rings, self.ring_radii)
        keep = in_sector(pts, ctx.sector)
        rel = np.mod(theta - ctx.wedge[0], TWO_PI)
        # Outer ring first when starting outside: groups sorted by decreasing radius.
        pts = serpentine(pts[keep], -ring[keep], rel[keep], ctx.start)
        return Pattern(pts, info={"n_rings": int(np.unique(ring).size)})


@dataclass(frozen=True, kw_only=True)
class B3Spiral(ReleaseStrategy):
    """B3: Archimedean spiral whose pitch equals the local spacing ``c / sqrt(rho)``, ``N`` releases."""

    name: ClassVar[str] = "B3_spiral"
    description: ClassVar[str] = "Archimedean spiral with variable pitch Delta(r) = s(r) = c / sqrt(rho(r)), N releases"
    release_speed: ClassVar[float] = 5.0

    def pattern(self, ctx: PlanContext) -> Pattern:
        """The spiral from its nearer end; in a wedge, the turns' arcs flown back and forth."""
        pts, th = spiral_points(ctx.profile, ctx.n_sensors)
        if ctx.sector is None:
            return Pattern(orient(pts, ctx.start))
        keep = in_sector(pts, ctx.sector)
        turn = np.floor((th[keep] - ctx.wedge[0]) / TWO_PI)
        return Pattern(serpentine(pts[keep], -turn, th[keep], ctx.start))


@dataclass(frozen=True, kw_only=True)
class B4Boustrophedon(ReleaseStrategy):
    """B4: lawnmower lanes over the zone box, a release each time the accumulated mass gains one sensor.

    Args:
        lane_spacing: Distance between lanes (m; ``None``: ``R sqrt(pi / N)``).
    """

    name: ClassVar[str] = "B4_boustrophedon"
    description: ClassVar[str] = "lawnmower lanes over the box, release each time accumulated rho*Delta*ds gains 1"
    release_speed: ClassVar[float] = 5.0
    bounds: ClassVar = {"lane_spacing": Bound(0.0, lo_open=True)}

    lane_spacing: float | None = None

    def pattern(self, ctx: PlanContext) -> Pattern:
        """The lanes' releases in the wedge, from the nearer end."""
        pts = lane_points(ctx.profile, ctx.n_sensors, self.lane_spacing)
        return Pattern(orient(pts[in_sector(pts, ctx.sector)], ctx.start))


@dataclass(frozen=True, kw_only=True)
class B5Cvt(B1LDSunflower):
    """B5: density-weighted centroidal Voronoi layout (Lloyd from the sunflower set), toured NN + 2-opt.

    Args:
        lloyd_iters: Lloyd iterations.
        grid: Cells per axis of the Lloyd grid (``None``: about 80 cells per generator, 128-512).
    """

    name: ClassVar[str] = "B5_cvt"
    description: ClassVar[str] = (
        "density-weighted CVT (Lloyd on a grid, phi = rho^2) from the sunflower set, NN + 2-opt tour"
    )
    bounds: ClassVar = {"lloyd_iters": Bound(0), "grid": Bound(1)}

    lloyd_iters: int = 30
    grid: int | None = None

    def layout(self, ctx: PlanContext) -> NDArray[np.float64]:
        """The whole zone's CVT generators ``(N, 2)`` (offsets)."""
        return cvt_points(ctx.profile, ctx.n_sensors, self.lloyd_iters, self.grid)


@dataclass(frozen=True, kw_only=True)
class B6DropClusters(ReleaseStrategy):
    """B6: k-means drop points on B1 targets; the UAV hovers at each and releases its cluster's sensors.

    Args:
        n_drops: Drop points per wedge (``None``: a tenth of the wedge's sensors, at least 1).
    """

    name: ClassVar[str] = "B6_drop_clusters"
    description: ClassVar[str] = "k-means drop points on B1 targets; hover and release each cluster's sensors"
    release_speed: ClassVar[float] = 0.0
    plan_mode: ClassVar[str] = "hover"
    bounds: ClassVar = {"n_drops": Bound(1)}

    n_drops: int | None = None

    def pattern(self, ctx: PlanContext) -> Pattern:
        """Every target moved to its cluster's drop point, drops in tour order."""
        pts = random_wedge_points(ctx.profile, ctx.n_sensors, ctx.sector, ctx.rng)
        nq = pts.shape[0]
        if nq == 0:
            return Pattern(pts)
        pts, groups, counts = drop_clusters(
            pts, self.n_drops or max(1, round(nq / 10)), ctx.start, self.two_opt, ctx.rng
        )
        return Pattern(pts, hover_groups=groups, info={"drop_counts": counts})


@dataclass(frozen=True, kw_only=True)
class B7Ergodic(ReleaseStrategy):
    """B7: spectral multiscale coverage trajectory for ``phi = rho``, releases at constant intervals in the zone.

    Args:
        modes: Cosine modes per axis (``None``: ``clip(ceil(sqrt(n)), 8, 64)``).
        spacing: Trajectory length between releases (m; ``None``: the side of the area per release).
        substeps: Integration steps per release interval.
        turn_radius: Smallest turn radius (m; ``None``: ``spacing``).
    """

    name: ClassVar[str] = "B7_ergodic"
    description: ClassVar[str] = (
        "spectral multiscale coverage trajectory for phi = rho, constant-interval in-zone releases"
    )
    bounds: ClassVar = {
        "modes": Bound(2),
        "spacing": Bound(0.0, lo_open=True),
        "substeps": Bound(1),
        "turn_radius": Bound(0.0, lo_open=True),
    }

    modes: int | None = None
    spacing: float | None = None
    substeps: int = 4
    turn_radius: float | None = None

    def pattern(self, ctx: PlanContext) -> Pattern:
        """The trajectory's in-zone releases, in trajectory order."""
        n = sector_quota(ctx.n_sensors, ctx.sector)
        pts = ergodic_points(
            ctx.profile, n, ctx.sector, ctx.start, self.modes, self.spacing, self.substeps, self.turn_radius
        )
        return Pattern(pts)


#: The layouts B8 can place, by option value.
_B8_BASES: dict[str, type[B1LDSunflower]] = {B1LDSunflower.name: B1LDSunflower, B5Cvt.name: B5Cvt}


@dataclass(frozen=True, kw_only=True)
class B8Teleport(ReleaseStrategy):
    """B8: the reference layout (B1-LD or B5 points) placed exactly: a teleport plan, no flight.

    A teleport plan is not flyable: ``ReleasePolicy`` flies it as hover releases over the targets, every UAV
    at its layer above the lowest altitude (``layer_altitudes``). The evaluation's ``B8_teleport`` reference
    row places the points without flying.

    Args:
        base: The layout placed: ``"B1LD_sunflower"`` or ``"B5_cvt"``.
        lloyd_iters: Lloyd iterations of the B5 layout.
        grid: Lloyd grid of the B5 layout (``None``: automatic).
    """

    name: ClassVar[str] = "B8_teleport"
    description: ClassVar[str] = "teleport placement of the B1-LD (or B5) points: no flight, zero landing error"
    release_speed: ClassVar[float] = 0.0
    plan_mode: ClassVar[str] = "teleport"
    bounds: ClassVar = {"base": Choice(tuple(_B8_BASES)), "lloyd_iters": Bound(0), "grid": Bound(1)}

    base: str = B1LDSunflower.name
    lloyd_iters: int = 30
    grid: int | None = None

    def pattern(self, ctx: PlanContext) -> Pattern:
        """The base layout's points in the wedge (no tour: they are placed, not flown)."""
        base = _B8_BASES[self.base]
        own = set(base.options()) - set(ReleaseStrategy.options())  # the layout's own options: lloyd_iters, grid
        shared = {k: getattr(self, k) for k in own if k in self.options()}
        pts = base(**shared).layout(ctx)
        return Pattern(pts[in_sector(pts, ctx.sector)])

    def layer_altitudes(
        self,
        zone_altitudes: NDArray[np.float64],
        n_uavs: int,
        layer_spacing: float,
        band: tuple[float, float],
    ) -> NDArray[np.float64]:
        """Every UAV works at its layer above the band's floor in every zone (zone altitudes ignored)."""
        lo, hi = band
        out = np.empty((n_uavs, zone_altitudes.shape[0]))
        out[:] = np.clip(lo + layer_spacing * np.arange(n_uavs), lo, hi)[:, None]
        return out


#: The shipped strategies, in their order B0 ... B8.
SHIPPED: tuple[type[ReleaseStrategy], ...] = (
    B0Uniform,
    B1InverseCdf,
    B1LDSunflower,
    B2Rings,
    B3Spiral,
    B4Boustrophedon,
    B5Cvt,
    B6DropClusters,
    B7Ergodic,
    B8Teleport,
)
