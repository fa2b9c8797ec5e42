"""The ``beacon_ring`` release strategy: every sensor on one ring around the zone centre, flown in order."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from agentsim_env.policies.release import Bound, Pattern, PlanContext, ReleaseStrategy
from agentsim_env.policies.release.planning import sector_quota


@dataclass(frozen=True, kw_only=True)
class BeaconRing(ReleaseStrategy):
    """Sensors evenly spaced on a circle at ``radius_share`` of the zone radius (each UAV flies its wedge)."""

    name: ClassVar[str] = "beacon_ring"
    description: ClassVar[str] = "one ring at a share of the zone radius, evenly spaced"
    release_speed: ClassVar[float] = 5.0
    bounds: ClassVar = {"radius_share": Bound(0.0, 1.0, lo_open=True)}

    radius_share: float = 0.6

    def pattern(self, ctx: PlanContext) -> Pattern:
        """This wedge's share of the zone's sensors on the ring, in angular order."""
        n = sector_quota(ctx.n_sensors, ctx.sector)
        theta0, width = ctx.wedge
        theta = theta0 + width * (np.arange(n) + 0.5) / max(n, 1)
        r = self.radius_share * ctx.radius
        return Pattern(np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1).reshape(-1, 2))
