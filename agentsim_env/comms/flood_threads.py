"""One overlay hop over several threads, with the same result as ``flooding.spread`` on one.

Floods do not interact within a hop: a flood's new readers depend only on its frontier entries, its reader list
and the links. The frontier (grouped by flood, in the frontier's flood order) is therefore cut into contiguous
ranges of whole floods of about equal work (``hop_cost``), and each range spreads on a thread of the env's pool
with a stamp array, delivery buffers and a reader pool of its own (``flooding.hop_range``, the one-thread hop's
kernel too). The ranges' outputs are then put behind one another in range order (each range copies its own part,
on its own thread), which is the order one thread writes them in: deliveries, the next frontier, the floods that
ended, and the reader lists of the new pool. The active floods
without a frontier entry keep their readers at the end, as in ``spread``.

One-hop mode only (the comms stack's); ``full_propagation`` spreads on one thread.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from agentsim_env.comms.flooding import _room, hop_range, keep_rest
from agentsim_env.core.threads import RowThreads


@nb.njit(cache=True, nogil=True)
def _place(
    cur_f,
    a0,
    b0,
    rd_start,
    pool_base,
    src_pool,
    n_pool,
    dst_pool,
    shift,
    out_base,
    n_out,
    src_r,
    src_f,  # type: ignore[no-untyped-def]  # noqa: E501
    src_h,
    r,
    f,
    h,
):
    # A range's part of the join: its reader lists behind the earlier ranges' (its floods' rd_start shifted with
    # them; range 0's are in place already), and its deliveries as rows [out_base, out_base + n_out) of the fresh
    # delivery arrays.
    if shift:
        for i in range(n_pool):
            dst_pool[pool_base + i] = src_pool[i]
        for q in range(a0, b0):
            if q == a0 or cur_f[q] != cur_f[q - 1]:
                rd_start[cur_f[q]] += pool_base
    for i in range(n_out):
        k = out_base + i
        r[k], f[k], h[k] = src_r[i], src_f[i], src_h[i]


@nb.njit(cache=True)
def hop_cost(cur_f, cur_n, start, end, hops, limit):  # type: ignore[no-untyped-def]
    """Cumulative estimated cost of the frontier entries ``(n,)`` int64, to cut a hop into ranges of equal work.

    An entry walks its slot's links; a flood at its first hop that goes on finds nearly every neighbour new and
    writes each as a delivery, a reader and a next-frontier entry, about 4x the cost per link of a later hop
    (which mostly meets readers: ~1.7 ns a link, ~14 ns a new reader, measured at 10,000 agents).
    """
    out = np.empty(cur_f.shape[0], dtype=np.int64)
    acc = 0
    for q in range(cur_f.shape[0]):
        f = cur_f[q]
        u = cur_n[q]
        acc += 1 + (end[u] - start[u]) * (4 if hops[f] == 0 and limit[f] > 1 else 1)
        out[q] = acc
    return out


def flood_ranges(cur_f: np.ndarray, threads: RowThreads, cost: np.ndarray | None = None) -> list[tuple[int, int]]:
    """The frontier entries ``[0, n)`` cut into the pool's row ranges, each boundary moved to a flood's start.

    With ``cost`` (``hop_cost``'s cumulative cost per entry) the ranges hold equal shares of it instead of equal
    numbers of entries (as many ranges either way).
    """
    n = int(cur_f.shape[0])
    rows = threads.ranges(n)
    if len(rows) == 1:
        return [(0, n)] if n else []
    heads = np.flatnonzero(np.r_[True, cur_f[1:] != cur_f[:-1]])
    if cost is None:
        ends = [hi for _, hi in rows[:-1]]
    else:
        k = len(rows)
        ends = [int(x) for x in np.searchsorted(cost, [cost[-1] * i / k for i in range(1, k)], side="right")]
    cuts = [0]
    for hi in ends:
        at = int(heads[np.searchsorted(heads, hi)]) if hi <= heads[-1] else n
        if at > cuts[-1]:
            cuts.append(at)
    if cuts[-1] < n:
        cuts.append(n)
    return list(zip(cuts[:-1], cuts[1:]))


def spread_threads(
    start: np.ndarray,
    end: np.ndarray,
    indices: np.ndarray,
    hops: np.ndarray,
    limit: np.ndarray,
    active: np.ndarray,
    rd_start: np.ndarray,
    rd_len: np.ndarray,
    pool: np.ndarray,
    cur_f: np.ndarray,
    cur_n: np.ndarray,
    threads: RowThreads,
    ranges: list[tuple[int, int]],
    scratch: list[list[Any]],
    new_pool: np.ndarray,
) -> tuple[Any, ...]:
    """``flooding.spread`` in one-hop mode over ``ranges`` (``flood_ranges``'s; same values as ``spread``), the
    deliveries as fresh arrays.

    ``scratch`` holds each range's ``[stamp, token, out_r, out_f, out_h, pool, nxt_f, nxt_n, fin]`` between calls
    (grown here); ``new_pool`` (the spare pool) becomes the returned pool.

    Returns:
        ``(nxt_f, nxt_n, fin, dups, npool, new_pool, (receiver, flood, hops))``.
    """
    if not ranges:
        raise ValueError("spread_threads needs a frontier entry")
    seen = np.zeros(active.shape[0], dtype=np.bool_)
    e = np.zeros(0, dtype=np.int64)
    while len(scratch) < len(ranges):
        scratch.append(
            [
                np.zeros(start.shape[0], dtype=np.int32),
                0,
                e,
                e.copy(),
                np.zeros(0, dtype=np.int32),
                e.copy(),
                e.copy(),
                e.copy(),
                e.copy(),
            ]
        )
    scratch[0][5] = new_pool
    got: list[tuple[int, ...]] = [(0, 0, 0, 0, 0)] * len(ranges)

    def run(_lo: int, _hi: int, part: int) -> None:
        sc = scratch[part]
        if sc[0].shape[0] != start.shape[0]:
            sc[0] = np.zeros(start.shape[0], dtype=np.int32)
        a0, b0 = ranges[part]
        nd, npool, nn, nfin, dups, sc[1], sc[5], sc[2], sc[3], sc[4], sc[6], sc[7], sc[8] = hop_range(
            start,
            end,
            indices,
            hops,
            limit,
            rd_start,
            rd_len,
            pool,
            cur_f,
            cur_n,
            a0,
            b0,
            sc[0],
            sc[1],
            seen,
            sc[5],
            sc[2],
            sc[3],
            sc[4],
            sc[6],
            sc[7],
            sc[8],
        )
        got[part] = (nd, npool, nn, nfin, dups)

    threads.run(run, len(ranges), 1)
    nds = np.array([g[0] for g in got], dtype=np.int64)
    pools = np.array([g[1] for g in got], dtype=np.int64)
    out_base, pool_base = np.r_[0, np.cumsum(nds)], np.r_[0, np.cumsum(pools)]
    nd, npool = int(out_base[-1]), int(pool_base[-1])
    # the active floods without a frontier entry keep their readers behind every range's (range 0's pool is the
    # one returned; the later ranges' lists are placed below, at offsets keep_rest does not touch)
    new_pool, npool = keep_rest(active, seen, rd_start, rd_len, pool, _room(scratch[0][5], npool, int(pools[0])), npool)
    scratch[0][5] = new_pool
    r, f = np.empty(nd, dtype=np.int64), np.empty(nd, dtype=np.int64)
    h = np.empty(nd, dtype=scratch[0][4].dtype)

    def place(lo: int, hi: int, _: int) -> None:  # each range on a thread: its pool part and its deliveries
        for p in range(lo, hi):
            sc = scratch[p]
            _place(
                cur_f,
                ranges[p][0],
                ranges[p][1],
                rd_start,
                int(pool_base[p]),
                sc[5],
                int(pools[p]),
                new_pool,
                p > 0,
                int(out_base[p]),
                int(nds[p]),
                sc[2],
                sc[3],
                sc[4],
                r,
                f,
                h,
            )

    threads.run(place, len(ranges), 1)
    # the next frontier and the floods that ended, in range order (fresh arrays: the frontier is kept)
    nxt_f = np.concatenate([scratch[p][6][: got[p][2]] for p in range(len(ranges))])
    nxt_n = np.concatenate([scratch[p][7][: got[p][2]] for p in range(len(ranges))])
    fin = np.concatenate([scratch[p][8][: got[p][3]] for p in range(len(ranges))])
    dups = sum(g[4] for g in got)
    return nxt_f, nxt_n, fin, dups, npool, new_pool, (r, f, h)
