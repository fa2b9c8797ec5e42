"""Plain reference of the network-lifetime simulation (:func:`agentsim_env.uav.wsn.lifetime.simulate_lifetime`):
scipy re-routing of the whole network after every death instead of the kernel's decremental one."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from agentsim_env.uav.wsn.lifetime import (
    _DEFAULT_RADIO,
    _ROUND_SLACK,
    CAUSE_DISCONNECTED,
    CAUSE_ENERGY,
    LifetimeResult,
    _inputs,
    _summary,
    routing_tree,
)
from agentsim_env.uav.wsn.radio import RadioParams


def simulate_lifetime_reference(
    sensors: ArrayLike,
    sinks: ArrayLike,
    r_c: float,
    radio: RadioParams = _DEFAULT_RADIO,
    e0: ArrayLike | None = None,
) -> LifetimeResult:
    """Plain reference for ``simulate_lifetime``: full scipy re-routing after every death (small n only).

    Args:
        sensors: ``(n, 2)`` sensor positions.
        sinks: ``(m, 2)`` sink positions.
        r_c: Communication range in metres.
        radio: Radio constants.
        e0: Initial energies (scalar or ``(n,)``); default ``radio.e0``.

    Returns:
        Same as ``simulate_lifetime``.
    """
    p, s, energy = _inputs(sensors, sinks, r_c, e0, radio)
    n = p.shape[0]
    res = energy.copy()
    death = np.zeros(n, dtype=np.int64)
    cause = np.zeros(n, dtype=np.int8)
    cost, parent, load = routing_tree(p, s, r_c, radio)
    alive = np.isfinite(cost)
    fnd_static = float(np.min(energy[alive] / load[alive])) if alive.any() else math.inf
    t, events = 0, 0
    while alive.any():
        rounds = np.floor(res[alive] / load[alive] * (1.0 + _ROUND_SLACK)).astype(np.int64)
        jump = int(rounds.min())
        t += jump
        events += 1
        res[alive] -= jump * load[alive]
        dying = np.flatnonzero(alive)[rounds == jump]
        alive[dying] = False
        death[dying], cause[dying] = t, CAUSE_ENERGY
        cost, parent, load = routing_tree(p, s, r_c, radio, alive)
        cut = alive & ~np.isfinite(cost)
        alive &= ~cut
        death[cut], cause[cut] = t, CAUSE_DISCONNECTED
    return _summary(death, cause, fnd_static, events, events)
