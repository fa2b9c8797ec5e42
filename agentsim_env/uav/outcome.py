"""End-of-mission scoring for ``uav_release``: connectivity and lifetime of the landed network.

The lifetime term is normalised by the first-node-dies round (FND) of the oracle layout (B8: each zone's
sunflower low-discrepancy points, placed exactly), so scores compare across zone files.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.payloads import PayloadSet
from agentsim_env.uav.wsn.connectivity import connectivity
from agentsim_env.uav.wsn.evaluate import WsnConfig, sink_positions
from agentsim_env.uav.wsn.lifetime import simulate_lifetime
from agentsim_env.uav.zones import ZoneSet

LIFETIME_RATIO_CAP = 2.0  # a lucky layout can outlive the oracle; cap the bonus so it stays bounded


def oracle_points(zones: ZoneSet) -> np.ndarray:
    """The B8 oracle layout: every zone's low-discrepancy points at their exact positions ``(N, 2)``."""
    parts = [np.asarray(z.centre) + z.radial_profile().low_discrepancy(z.n_sensors) for z in zones.zones]
    return np.vstack(parts)


def oracle_fnd(zones: ZoneSet, wsn: WsnConfig) -> float:
    """FND (rounds) of the oracle layout; at least 1 so it can divide."""
    sinks = sink_positions(wsn.sink, zones.centres())
    res = simulate_lifetime(oracle_points(zones), sinks, wsn.r_c, wsn.radio)
    return max(float(res.fnd), 1.0)


def final_bonus(payloads: PayloadSet, world: int, zones: ZoneSet, config: Any, fnd_oracle: float) -> float:
    """``w_lcc * LCC fraction + w_lifetime * min(FND / FND_oracle, 2)`` of world ``world``'s landed sensors."""
    landed = payloads.landed_xy(world=world)
    if landed.shape[0] == 0:
        return 0.0
    wsn = config.wsn
    sinks = sink_positions(wsn.sink, zones.centres())
    lcc = connectivity(landed, wsn.r_c, sinks).lcc_fraction
    fnd = simulate_lifetime(landed, sinks, wsn.r_c, wsn.radio).fnd
    return float(config.w_lcc * lcc + config.w_lifetime * min(fnd / fnd_oracle, LIFETIME_RATIO_CAP))
