"""Stage 1's comm actions as bus rows and flood starts (``CommsStack.send_actions``): the kernels, on row ranges.

A step's ``comm`` actions ``(S, COMM_HEADER + D)`` are decoded per slot (channel, named receiver, hop limit) and
turned into the bus rows of three consecutive sends (GROUP rows, then "nearest" unicasts, then "named" unicasts,
slot order within each) plus one overlay flood per slot that chose the overlay. Each kernel takes a ``[lo, hi)``
slot range: on one range a kernel call does the whole step; over several ranges (``RowThreads``) every range
counts its rows, the counts give each range its first row in each block, and every range writes its own rows, so
the rows come out in the same order and with the same values for any thread count.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from agentsim_env.comms.messages import AGENT, GROUP
from agentsim_env.core.threads import RowThreads, light_min_rows

CHANNELS = ("none", "group", "nearest", "named", "overlay")
N_CHANNELS = len(CHANNELS)
COMM_HEADER = 3

SendRows = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""``kind, sender, target, world, payload`` of the bus rows, then ``origin, hop limit, payload`` of the floods."""


@nb.njit(cache=True, nogil=True, error_model="numpy")  # n_agents >= 1: no zero-division checks
def decode_range(lo, hi, comm, acting, n_agents, max_hops, sel, named, hops):  # type: ignore[no-untyped-def]
    # The header columns of float64 actions of slots [lo, hi), with the float64 operations of the numpy path in
    # ``send_actions`` (same order and rounding: the same bins, receivers and hop limits bit for bit). Returns
    # whether a slot of the range chose "nearest".
    any_near = False
    for s in range(lo, hi):
        if acting[s]:
            c = min(np.int64((comm[s, 0] + 1.0) * (N_CHANNELS / 2.0)), N_CHANNELS - 1)
            sel[s] = c
            any_near |= c == 2
        else:
            sel[s] = 0
        named[s] = (s // n_agents) * n_agents + np.int64(np.rint((comm[s, 1] + 1.0) * 0.5 * (n_agents - 1)))
        hops[s] = 1 + np.int64(np.rint((comm[s, 2] + 1.0) * 0.5 * (max_hops - 1)))
    return any_near


@nb.njit(cache=True, nogil=True)
def count_range(lo, hi, sel, group, near, named, counts):  # type: ignore[no-untyped-def]
    # Rows of slots [lo, hi) per block into ``counts``: GROUP rows, "nearest" rows, "named" rows, floods.
    n_g = n_n = n_m = n_o = 0
    for s in range(lo, hi):
        c = sel[s]
        if c == 1 and group[s] >= 0:
            n_g += 1
        elif c == 2 and near[s] >= 0:
            n_n += 1
        elif c == 3 and named[s] != s:
            n_m += 1
        elif c == 4:
            n_o += 1
    counts[0], counts[1], counts[2], counts[3] = n_g, n_n, n_m, n_o


@nb.njit(cache=True, nogil=True)
def fill_range(  # type: ignore[no-untyped-def]
    lo, hi, sel, group, near, named, hops, comm, n_agents, sent, nxt, o, kind, snd, tgt, wld, pay, o_org, o_hops, o_pay
):
    # The rows of slots [lo, hi): block b's next row is nxt[b] (the range's first row in it, advanced here), the
    # range's first flood is row o. Every slot that sends counts one message in ``sent``.
    d = comm.shape[1] - COMM_HEADER
    for s in range(lo, hi):
        c = sel[s]
        if c == 4:
            o_org[o] = s
            o_hops[o] = hops[s]
            for q in range(d):
                o_pay[o, q] = np.float32(comm[s, COMM_HEADER + q])
            o += 1
            sent[s] += 1
            continue
        if c == 1 and group[s] >= 0:
            b, kd, t = 0, GROUP, group[s]
        elif c == 2 and near[s] >= 0:
            b, kd, t = 1, AGENT, near[s]
        elif c == 3 and named[s] != s:
            b, kd, t = 2, AGENT, named[s]
        else:
            continue
        r = nxt[b]
        nxt[b] += 1
        kind[r] = kd
        snd[r] = s
        tgt[r] = t
        wld[r] = s // n_agents
        for q in range(d):
            pay[r, q] = np.float32(comm[s, COMM_HEADER + q])
        sent[s] += 1


@nb.njit(cache=True, nogil=True, error_model="numpy")
def _decode_one(comm, acting, n_agents, max_hops):  # type: ignore[no-untyped-def]
    # ``decode`` on one range, in one call
    n = comm.shape[0]
    sel, named, hops = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    any_near = decode_range(0, n, comm, acting, n_agents, max_hops, sel, named, hops)
    return sel, named, hops, any_near


@nb.njit(cache=True, nogil=True)
def _comm_rows_one(sel, group, near, named, hops, comm, n_agents, sent):  # type: ignore[no-untyped-def]
    # ``comm_rows`` on one range, in one call
    n, d = sel.shape[0], comm.shape[1] - COMM_HEADER
    counts = np.zeros(4, dtype=np.int64)
    count_range(0, n, sel, group, near, named, counts)
    k = counts[0] + counts[1] + counts[2]
    kind, snd, tgt, wld = np.empty(k, np.int8), np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k, np.int64)
    pay = np.empty((k, d), dtype=np.float32)
    n_o = counts[3]
    o_org, o_hops, o_pay = np.empty(n_o, np.int64), np.empty(n_o, np.int64), np.empty((n_o, d), np.float32)
    nxt = np.array([0, counts[0], counts[0] + counts[1]])
    out = (kind, snd, tgt, wld, pay, o_org, o_hops, o_pay)
    fill_range(0, n, sel, group, near, named, hops, comm, n_agents, sent, nxt, 0, *out)
    return out


def _ranges(threads: RowThreads, n: int) -> list[tuple[int, int]]:
    """The slot ranges of these kernels: a few nanoseconds a slot, so a thread only from ``light_min_rows``."""
    return [(0, n)] if threads.num_threads == 1 else threads.ranges(n, light_min_rows())


def decode(
    comm: np.ndarray, acting: np.ndarray, n_agents: int, max_hops: int, threads: RowThreads
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """``(sel, named, hops, any_near)`` of float64 ``comm`` actions (C-contiguous): channel, named receiver and
    hop limit per slot (channel 0 for slots not acting), and whether any slot chose "nearest"."""
    n = comm.shape[0]
    if len(_ranges(threads, n)) == 1:
        sel, named, hops, one = _decode_one(comm, acting, n_agents, max_hops)
        return sel, named, hops, bool(one)
    sel, named, hops = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    near = threads.run(
        lambda lo, hi, _: decode_range(lo, hi, comm, acting, n_agents, max_hops, sel, named, hops),
        n,
        light_min_rows(),
    )
    return sel, named, hops, any(near)


def comm_rows(
    sel: np.ndarray,
    group: np.ndarray,
    near: np.ndarray,
    named: np.ndarray,
    hops: np.ndarray,
    comm: np.ndarray,
    n_agents: int,
    sent: np.ndarray,
    threads: RowThreads,
) -> SendRows:
    """Every bus row and flood start of a step's decoded comm actions (``comm`` C-contiguous), in the order of three
    consecutive sends (module docstring); ``sent`` counts one per sending slot."""
    n, d = sel.shape[0], comm.shape[1] - COMM_HEADER
    ranges = _ranges(threads, n)
    if len(ranges) == 1:
        return _comm_rows_one(sel, group, near, named, hops, comm, n_agents, sent)  # type: ignore[no-any-return]
    counts = np.zeros((len(ranges), 4), dtype=np.int64)
    threads.run(lambda lo, hi, p: count_range(lo, hi, sel, group, near, named, counts[p]), n, light_min_rows())
    total = counts.sum(axis=0)
    k = int(total[:3].sum())
    # each range's first row in each block: the block's start plus the rows of the ranges before it
    firsts = np.cumsum(counts, axis=0) - counts
    firsts[:, 1] += total[0]
    firsts[:, 2] += total[0] + total[1]
    kind, snd, tgt, wld = np.empty(k, np.int8), np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k, np.int64)
    pay = np.empty((k, d), dtype=np.float32)
    n_o = int(total[3])
    o_org, o_hops, o_pay = np.empty(n_o, np.int64), np.empty(n_o, np.int64), np.empty((n_o, d), np.float32)
    out = (kind, snd, tgt, wld, pay, o_org, o_hops, o_pay)
    threads.run(
        lambda lo, hi, p: fill_range(
            lo, hi, sel, group, near, named, hops, comm, n_agents, sent, firsts[p, :3].copy(), firsts[p, 3], *out
        ),
        n,
        light_min_rows(),
    )
    return out
