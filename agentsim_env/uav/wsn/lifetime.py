"""Network lifetime under minimum-energy multi-hop routing to the sink(s) (domain reference 2.2).

Model. Node ``i`` sends one ``k``-bit packet per round and relays its descendants' packets along a
shortest-path tree: the edge ``i -> j`` costs ``E_tx(k, d_ij) + E_rx(k)``, with ``E_rx = 0`` into a
(mains-powered) sink, and the tree is Dijkstra from the sinks on the reversed graph. Its per-round load is
``E_i = (1 + a_i) E_tx(k, d_i,parent) + a_i E_rx(k)``, ``a_i`` being its number of descendants.

Rounds and deaths (exact definitions). Loads are constant between two deaths, so the simulation jumps from
death to death: a node with residual energy ``e`` and load ``E`` completes ``floor(e / E)`` further rounds and
dies when it cannot afford the next one. Its *death round* is the number of rounds the network had completed
when it stopped delivering. When a node dies, only its former subtree is re-routed (a decremental Dijkstra
seeded from the unaffected neighbours; every other node keeps its exact shortest path). A node left with no
path to a sink is *functionally dead* from that round on (it spends nothing afterwards). Sensors with no path
to a sink at round 0 never deliver; they are excluded from the population (``cause == 0``, death round 0).

* ``fnd``: death round of the first node of the population (always an energy death);
* ``hnd``: round by which at least half the population is dead (energy or disconnection);
* ``lnd``: round by which all of the population is dead;
* ``fnd_static``: ``min_i E0_i / E_i`` on the round-0 tree (real-valued; a reward-shaping proxy);
* coverage lifetime (``coverage_lifetime``): the first death round ``t`` at which the fraction of the zones'
  area covered by sensors still alive and connected (death round ``> t``) drops strictly below
  ``threshold`` times its round-0 value; 0 when nothing is covered at round 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.sparse import csgraph

from agentsim_env.uav.wsn.connectivity import sink_edges, unit_disk_edges
from agentsim_env.uav.wsn.coverage import CoverageResult, ZoneGrid, check_points, cover_pairs
from agentsim_env.uav.wsn.radio import RadioParams, rx_energy, tx_energy

__all__ = [
    "LifetimeResult",
    "coverage_lifetime",
    "routing_tree",
    "simulate_lifetime",
]

# floor(e / E) is taken with this relative slack so that an exact multiple (0.5 J / 250 uJ = 2000 rounds)
# is not lost to rounding in the division.
_ROUND_SLACK = 1e-12
CAUSE_NEVER, CAUSE_ENERGY, CAUSE_DISCONNECTED = 0, 1, 2
_DEFAULT_RADIO = RadioParams()


@dataclass(frozen=True)
class LifetimeResult:
    """Outcome of a lifetime simulation (see the module docstring for the exact definitions).

    Attributes:
        fnd: First-node-dies round (0 when the population is empty).
        hnd: Half-nodes-dead round.
        lnd: Last-node-dies round.
        fnd_static: ``min E0_i / E_i`` on the round-0 routing tree (0 when the population is empty).
        death_round: ``(n,)`` int64 death round of each sensor (0 for sensors never connected).
        cause: ``(n,)`` int8: 0 never connected, 1 energy, 2 cut off from every sink.
        n_population: Number of sensors connected to a sink at round 0.
        n_events: Number of death events simulated.
        n_reroutes: Number of events that changed the routing tree.
    """

    fnd: float
    hnd: float
    lnd: float
    fnd_static: float
    death_round: NDArray[np.int64]
    cause: NDArray[np.int8]
    n_population: int
    n_events: int
    n_reroutes: int


# ---------------------------------------------------------------------------------------------- graph
def _graph(
    sensors: NDArray[np.float64],
    sinks: NDArray[np.float64],
    r_c: float,
    radio: RadioParams,
    edges: tuple[NDArray[np.int64], NDArray[np.float64]] | None,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """CSR adjacency over sensors ``0..n-1`` and sinks ``n..n+m-1`` with per-entry energies.

    Returns ``(indptr, nbr, txe, wt_in, wt_out)``: for the entry of row ``u`` pointing at ``x``, ``txe`` is
    ``E_tx(k, d_ux)``, ``wt_in`` the cost of ``x -> u`` and ``wt_out`` the cost of ``u -> x`` (``E_rx`` is
    added unless the receiver is a sink). Sink-to-sink links are omitted: sinks never relay.
    """
    n, m = sensors.shape[0], sinks.shape[0]
    pairs, lengths = unit_disk_edges(sensors, r_c) if edges is None else edges
    si, sj, slen = sink_edges(sensors, sinks, r_c)
    a = np.concatenate([pairs[:, 0], si])
    b = np.concatenate([pairs[:, 1], n + sj])
    d = np.concatenate([lengths, slen])
    rows = np.concatenate([a, b])
    cols = np.concatenate([b, a])
    dd = np.concatenate([d, d])
    order = np.argsort(rows, kind="stable")  # group by row; order within a row is irrelevant
    rows, cols, dd = rows[order], cols[order], dd[order]
    indptr = np.zeros(n + m + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n + m), out=indptr[1:])
    k = radio.packet_bits
    txe = tx_energy(k, dd, radio)
    erx = float(rx_energy(k, radio))
    wt_in = txe + np.where(rows < n, erx, 0.0)
    wt_out = txe + np.where(cols < n, erx, 0.0)
    return indptr, cols.astype(np.int64), txe, wt_in, wt_out


# ---------------------------------------------------------------------------------------------- kernel
@numba.njit(cache=True)
def _push(keys, vals, size, key, val):
    """Push onto a binary min-heap stored in two arrays; returns the new size."""
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if keys[p] <= key:
            break
        keys[i] = keys[p]
        vals[i] = vals[p]
        i = p
    keys[i] = key
    vals[i] = val
    return size + 1


@numba.njit(cache=True)
def _pop(keys, vals, size):
    """Pop the minimum of the heap; returns ``(key, val, new_size)``."""
    top_k, top_v = keys[0], vals[0]
    size -= 1
    key, val = keys[size], vals[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and keys[c + 1] < keys[c]:
            c += 1
        if keys[c] >= key:
            break
        keys[i] = keys[c]
        vals[i] = vals[c]
        i = c
    if size > 0:
        keys[i] = key
        vals[i] = val
    return top_k, top_v, size


@numba.njit(cache=True)
def _reroute(indptr, nbr, txe, wt_in, wt_out, n, alive, affected, dist, parent, ptx, settled, hk, hv):
    """Recompute shortest paths of the affected alive sensors; the others keep theirs (still optimal)."""
    size = 0
    for u in range(n):
        if not (alive[u] and affected[u]):
            continue
        settled[u] = False
        best, bp, btx = np.inf, -1, 0.0
        for e in range(indptr[u], indptr[u + 1]):
            v = nbr[e]
            if v >= n or (alive[v] and not affected[v]):
                cand = dist[v] + wt_out[e]
                if cand < best:
                    best, bp, btx = cand, v, txe[e]
        dist[u], parent[u], ptx[u] = best, bp, btx
        if bp >= 0:
            size = _push(hk, hv, size, best, u)
    while size > 0:
        d, u, size = _pop(hk, hv, size)
        if settled[u] or d > dist[u]:
            continue
        settled[u] = True
        for e in range(indptr[u], indptr[u + 1]):
            x = nbr[e]
            if x < n and alive[x] and affected[x] and not settled[x]:
                cand = d + wt_in[e]
                if cand < dist[x]:
                    dist[x], parent[x], ptx[x] = cand, u, txe[e]
                    size = _push(hk, hv, size, cand, x)


@numba.njit(cache=True)
def _simulate(indptr, nbr, txe, wt_in, wt_out, n, erx, e0):
    """Event-driven lifetime simulation; returns ``(death, cause, fnd_static, n_events, n_reroutes)``."""
    n_all = indptr.shape[0] - 1
    alive = np.ones(n, dtype=np.bool_)
    affected = np.ones(n, dtype=np.bool_)
    settled = np.zeros(n, dtype=np.bool_)
    dist = np.zeros(n_all)
    dist[:n] = np.inf
    parent = np.full(n_all, -1, dtype=np.int64)
    ptx = np.zeros(n)
    res = e0.copy()
    load = np.zeros(n)
    n_desc = np.zeros(n, dtype=np.int64)
    rounds = np.zeros(n, dtype=np.int64)
    state = np.zeros(n, dtype=np.int8)  # per event: 0 unknown, 1 route intact, 2 route broken
    stack = np.zeros(n, dtype=np.int64)
    death = np.zeros(n, dtype=np.int64)
    cause = np.zeros(n, dtype=np.int8)
    hk = np.empty(nbr.shape[0] + n_all + 1)
    hv = np.empty(nbr.shape[0] + n_all + 1, dtype=np.int64)

    _reroute(indptr, nbr, txe, wt_in, wt_out, n, alive, affected, dist, parent, ptx, settled, hk, hv)
    for i in range(n):
        if parent[i] < 0:
            alive[i] = False  # never connected: outside the population (cause 0, death round 0)
    t = 0
    fnd_static = np.inf
    n_events, n_reroutes = 0, 0
    while True:
        # Descendant counts: every alive node adds one to each ancestor below the sink.
        n_desc[:] = 0
        n_alive = 0
        for v in range(n):
            if alive[v]:
                n_alive += 1
                p = parent[v]
                while p < n:
                    n_desc[p] += 1
                    p = parent[p]
        if n_alive == 0:
            break
        jump = np.int64(9_000_000_000_000_000_000)
        for v in range(n):
            if alive[v]:
                load[v] = (1 + n_desc[v]) * ptx[v] + n_desc[v] * erx
                rounds[v] = np.int64(np.floor(res[v] / load[v] * (1.0 + 1e-12)))
                jump = min(jump, rounds[v])
                if n_events == 0:
                    fnd_static = min(fnd_static, e0[v] / load[v])
        t += jump
        n_events += 1
        for v in range(n):
            state[v] = 0
            if alive[v]:
                res[v] -= jump * load[v]
                if rounds[v] == jump:
                    alive[v] = False
                    death[v], cause[v] = t, 1
                    state[v] = 2
        # A node is affected when its path to the sink crosses a node that just died. Walk up with
        # memoisation so that each node is resolved once: O(n) per event.
        any_affected = False
        for v in range(n):
            if not alive[v] or state[v] != 0:
                continue
            top = 0
            u = v
            verdict = 1
            while True:
                if u >= n:
                    break
                if state[u] != 0:
                    verdict = state[u]
                    break
                stack[top] = u
                top += 1
                u = parent[u]
            for j in range(top):
                state[stack[j]] = verdict
            if verdict == 2:
                any_affected = True
        if any_affected:
            n_reroutes += 1
            for v in range(n):
                affected[v] = alive[v] and state[v] == 2
            _reroute(indptr, nbr, txe, wt_in, wt_out, n, alive, affected, dist, parent, ptx, settled, hk, hv)
            for v in range(n):
                if affected[v] and parent[v] < 0:
                    alive[v] = False
                    death[v], cause[v] = t, 2
    return death, cause, fnd_static, n_events, n_reroutes


def _summary(
    death: NDArray[np.int64], cause: NDArray[np.int8], fnd_static: float, n_events: int, n_reroutes: int
) -> LifetimeResult:
    """FND / HND / LND from per-node death rounds."""
    pop = np.sort(death[cause != CAUSE_NEVER])
    if pop.size == 0:
        return LifetimeResult(0.0, 0.0, 0.0, 0.0, death, cause, 0, n_events, n_reroutes)
    fnd, hnd, lnd = (float(pop[i]) for i in (0, math.ceil(pop.size / 2) - 1, -1))
    return LifetimeResult(fnd, hnd, lnd, float(fnd_static), death, cause, int(pop.size), n_events, n_reroutes)


def _inputs(
    sensors: ArrayLike, sinks: ArrayLike, r_c: float, e0: ArrayLike | None, radio: RadioParams
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Validate positions and initial energies."""
    p = check_points(sensors, "sensors")
    s = check_points(sinks, "sinks")
    if not (math.isfinite(float(r_c)) and float(r_c) > 0.0):
        raise ValueError(f"r_c must be a finite number > 0, got {r_c!r}")
    energy = np.full(p.shape[0], radio.e0) if e0 is None else np.asarray(e0, dtype=np.float64)
    energy = np.broadcast_to(energy, (p.shape[0],)).astype(np.float64)
    if not np.all(np.isfinite(energy) & (energy > 0.0)):
        raise ValueError("e0 must be finite and > 0 for every sensor")
    return p, s, energy


def simulate_lifetime(
    sensors: ArrayLike,
    sinks: ArrayLike,
    r_c: float,
    radio: RadioParams = _DEFAULT_RADIO,
    e0: ArrayLike | None = None,
    edges: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
) -> LifetimeResult:
    """Simulate rounds of minimum-energy convergecast until every connected sensor is dead.

    Args:
        sensors: ``(n, 2)`` sensor positions in metres.
        sinks: ``(m, 2)`` sink positions (mains-powered; several sinks act as one multi-gateway sink).
        r_c: Communication range in metres.
        radio: Radio constants (packet length and default initial energy ``radio.e0``).
        e0: Initial energy per sensor in joules (scalar or ``(n,)``); default ``radio.e0``.
        edges: Precomputed ``unit_disk_edges(sensors, r_c)`` to share with other metrics.

    Returns:
        FND / HND / LND, the static FND estimate and per-sensor death rounds.
    """
    p, s, energy = _inputs(sensors, sinks, r_c, e0, radio)
    indptr, nbr, txe, wt_in, wt_out = _graph(p, s, float(r_c), radio, edges)
    erx = float(rx_energy(radio.packet_bits, radio))
    death, cause, fnd_static, n_events, n_reroutes = _simulate(indptr, nbr, txe, wt_in, wt_out, p.shape[0], erx, energy)
    return _summary(death, cause, fnd_static, int(n_events), int(n_reroutes))


# ---------------------------------------------------------------------------------------------- reference
def routing_tree(
    sensors: ArrayLike,
    sinks: ArrayLike,
    r_c: float,
    radio: RadioParams = _DEFAULT_RADIO,
    alive: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
    """Minimum-energy routing tree with scipy's Dijkstra (reference implementation).

    Args:
        sensors: ``(n, 2)`` sensor positions.
        sinks: ``(m, 2)`` sink positions.
        r_c: Communication range in metres.
        radio: Radio constants.
        alive: ``(n,)`` bool mask of sensors taking part (default all).

    Returns:
        ``(cost, parent, load)``: per sensor, the energy of its cheapest route to a sink (``inf`` if none),
        its next hop (a sensor index, ``n + j`` for sink ``j``, ``-1`` if none) and its per-round load.
    """
    p, s, _ = _inputs(sensors, sinks, r_c, None, radio)
    n, m = p.shape[0], s.shape[0]
    on = np.ones(n, dtype=bool) if alive is None else np.asarray(alive, dtype=bool)
    indptr, nbr, txe, _, wt_out = _graph(p, s, float(r_c), radio, None)
    rows = np.repeat(np.arange(n + m), np.diff(indptr))
    keep = (rows >= n) | on[np.minimum(rows, n - 1)] if n else np.zeros(0, dtype=bool)
    keep &= (nbr >= n) | on[np.minimum(nbr, n - 1)]
    keep &= rows < n  # edges u -> x with u a sensor; sinks never send
    # Reversed graph: entry (x, u) carries the cost of u -> x, so Dijkstra from the sinks gives u's cost.
    rev = sparse.csr_matrix((wt_out[keep], (nbr[keep], rows[keep])), shape=(n + m, n + m))
    dist, pred = csgraph.dijkstra(
        rev, directed=True, indices=np.arange(n, n + m), return_predecessors=True, min_only=True
    )[:2]
    cost = np.where(on, dist[:n], np.inf)
    parent = np.where(np.isfinite(cost), pred[:n], -1).astype(np.int64)
    # Subtree sizes: children are strictly costlier than their parent, so decreasing cost is a valid order.
    desc = np.zeros(n, dtype=np.int64)
    for v in np.argsort(-np.where(np.isfinite(cost), cost, -1.0)):
        if np.isfinite(cost[v]) and parent[v] < n:
            desc[parent[v]] += 1 + desc[v]
    hop = np.where(parent >= 0, np.linalg.norm(p - np.vstack([p, s])[np.maximum(parent, 0)], axis=1), 0.0)
    k = radio.packet_bits
    load = np.where(parent >= 0, (1 + desc) * tx_energy(k, hop, radio) + desc * rx_energy(k, radio), 0.0)
    return cost, parent, load


# ---------------------------------------------------------------------------------------------- coverage
def coverage_lifetime(
    grid: ZoneGrid,
    sensors: ArrayLike,
    r_s: float,
    death_round: ArrayLike,
    threshold: float = 0.9,
    pairs: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
) -> CoverageResult:
    """Rounds until the alive-and-connected coverage falls below ``threshold`` of its round-0 value.

    A lattice point stays covered until the last of its covering sensors dies, so its "covered until" round is
    the maximum death round over the sensors within ``r_s``; the coverage at round ``t`` is the fraction of
    points whose covered-until round exceeds ``t``.

    Args:
        grid: Zone lattice.
        sensors: ``(n, 2)`` sensor positions.
        r_s: Sensing radius in metres.
        death_round: ``(n,)`` death rounds (``LifetimeResult.death_round``).
        threshold: Fraction of the initial coverage, in (0, 1].
        pairs: Precomputed ``cover_pairs(grid, sensors, r_s)``.

    Returns:
        Coverage lifetime in rounds, over the union and per zone (NaN for a zone without lattice points).
    """
    thr = float(threshold)
    if not (0.0 < thr <= 1.0):
        raise ValueError(f"threshold must be in (0, 1], got {threshold!r}")
    point_idx, sensor_idx = cover_pairs(grid, sensors, r_s) if pairs is None else pairs
    until = np.zeros(grid.points.shape[0], dtype=np.int64)
    np.maximum.at(until, point_idx, np.asarray(death_round, dtype=np.int64)[sensor_idx])
    overall = _first_drop(until, thr)
    per_zone = np.array([_first_drop(until[grid.member[:, k]], thr) for k in range(grid.member.shape[1])])
    return CoverageResult(overall, per_zone)


def _first_drop(until: NDArray[np.int64], thr: float) -> float:
    """First candidate round where ``mean(until > t)`` < ``thr * mean(until > 0)``."""
    if until.size == 0:
        return math.nan
    srt = np.sort(until)
    c0 = srt.size - np.searchsorted(srt, 0, side="right")
    if c0 == 0:
        return 0.0
    cand = np.unique(srt)
    alive_after = srt.size - np.searchsorted(srt, cand, side="right")
    below = np.flatnonzero(alive_after < thr * c0)
    return float(cand[below[0]])
