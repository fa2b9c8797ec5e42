"""Numba kernels of the per-part overlay floods (``distributed.floods``).

A part keeps, per flood row, the list of its OWN slots that read the flood: ``pool[rd_start[f]:rd_start[f] +
rd_len[f]]``, plus reads added since the last rebuild (``add_v[add_start[f]:add_start[f] + add_len[f]]``). Every
kernel that changes the lists writes them into a fresh pool (double buffering, as ``comms.flooding`` does), which
drops the lists of rows that were forgotten.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from agentsim_env.comms.flooding import next_token


@nb.njit(cache=True)
def _copy_readers(f, rd_start, rd_len, pool, add_start, add_len, add_v, keep, new_pool, npool, stamp, tok):  # type: ignore[no-untyped-def]  # noqa: E501
    # Row f's readers with keep[x] into new_pool (stamped with tok when tok >= 0); returns the new pool length.
    for k in range(rd_start[f], rd_start[f] + rd_len[f]):
        x = pool[k]
        if keep[x]:
            new_pool[npool] = x
            npool += 1
            if tok >= 0:
                stamp[x] = tok
    for k in range(add_start[f], add_start[f] + add_len[f]):
        x = add_v[k]
        if keep[x]:
            new_pool[npool] = x
            npool += 1
            if tok >= 0:
                stamp[x] = tok
    return npool


@nb.njit(cache=True)
def leaving_reads(rd_start, rd_len, pool, leaving):  # type: ignore[no-untyped-def]
    """The reads ``(row, slot)`` of the pool's lists whose slot ``x`` has ``leaving[x]``, in row order, the
    lists left as they are (read only: the next hop drops the reads of slots no longer own).

    Returns:
        ``(out_row, out_slot)``.
    """
    n = 0
    for f in range(rd_start.shape[0]):
        for k in range(rd_start[f], rd_start[f] + rd_len[f]):
            if leaving[pool[k]]:
                n += 1
    out_row = np.empty(n, dtype=np.int64)
    out_slot = np.empty(n, dtype=np.int64)
    n = 0
    for f in range(rd_start.shape[0]):
        for k in range(rd_start[f], rd_start[f] + rd_len[f]):
            x = pool[k]
            if leaving[x]:
                out_row[n] = f
                out_slot[n] = x
                n += 1
    return out_row, out_slot


@nb.njit(cache=True)
def split_reads(rd_start, rd_len, pool, add_start, add_len, add_v, keep):  # type: ignore[no-untyped-def]
    """Rebuild the reader lists with the readers ``x`` where ``keep[x]``; the others come out.

    Returns:
        ``(new_pool, new_start, new_len, out_row, out_slot)``: the kept lists and the reads taken out.
    """
    n_rows = rd_start.shape[0]
    total = add_v.shape[0]
    for f in range(n_rows):
        total += rd_len[f]
    new_pool = np.empty(total, dtype=np.int64)
    out_row = np.empty(total, dtype=np.int64)
    out_slot = np.empty(total, dtype=np.int64)
    new_start = np.zeros(n_rows, dtype=np.int64)
    new_len = np.zeros(n_rows, dtype=np.int64)
    npool = 0
    nout = 0
    for f in range(n_rows):
        new_start[f] = npool
        for k in range(rd_start[f], rd_start[f] + rd_len[f]):
            x = pool[k]
            if keep[x]:
                new_pool[npool] = x
                npool += 1
            else:
                out_row[nout] = f
                out_slot[nout] = x
                nout += 1
        for k in range(add_start[f], add_start[f] + add_len[f]):
            x = add_v[k]
            if keep[x]:
                new_pool[npool] = x
                npool += 1
            else:
                out_row[nout] = f
                out_slot[nout] = x
                nout += 1
        new_len[f] = npool - new_start[f]
    return new_pool[:npool], new_start, new_len, out_row[:nout], out_slot[:nout]


@nb.njit(cache=True)
def _room(a, need):  # type: ignore[no-untyped-def]
    # ``a`` when it holds ``need`` entries, else a larger empty buffer (doubling).
    if need <= a.shape[0]:
        return a
    return np.empty(max(need, 2 * a.shape[0], 64), dtype=a.dtype)


@nb.njit(cache=True)
def hop_kernel(
    start,
    end,
    indices,
    own,
    e_row,
    e_slot,
    e_own,
    e_hops,
    rd_start,
    rd_len,
    pool,
    add_start,
    add_len,  # type: ignore[no-untyped-def]  # noqa: E501
    add_v,
    stamp,
    token,
    new_pool,
    out_v,
    out_f,
    out_h,
):
    """One hop of the frontier entries ``(e_row, e_slot)`` (grouped by row, rows in key order) into own slots.

    An own slot ``v`` reads row ``f`` when a frontier entry of ``f`` links to it and ``v`` is not among ``f``'s
    own readers (nor read it earlier in this hop). Links walked are counted for own entries only (``e_own``), so
    the parts' counts add up to the single process's.

    ``new_pool``, ``out_v``, ``out_f`` and ``out_h`` are buffers the caller keeps between hops (grown here when
    too small, returned either way; ``new_pool`` must not be ``pool``). The inner loop branches on "own and
    fresh": the branch-free form of the single process's kernel (write every neighbour, keep the fresh ones) was
    measured slower here (44-48 against 39-41 ms a hop at 100,000 agents over 2 shards), as a part's links often
    lead to ghosts.

    Returns:
        ``(new_pool, npool, new_start, new_len, out_v, out_f, out_h, nd, row_h, edges, token)``: the rebuilt
        reader lists in ``new_pool[:npool]`` (only readers still own, the added ones and the new ones), the
        deliveries ``out_*[:nd]`` (receiver, row, hops) grouped by row in entry order, each processed row's new
        hop count (-1: not processed), the links walked out of own entries and the last stamp token.
    """
    n_rows = rd_start.shape[0]
    ne = e_row.shape[0]
    n_old = add_v.shape[0]
    for f in range(n_rows):
        n_old += rd_len[f]
    bound = 0
    for q in range(ne):
        u = e_slot[q]
        bound += end[u] - start[u]
    new_pool = _room(new_pool, n_old + bound)
    out_v, out_f, out_h = _room(out_v, bound), _room(out_f, bound), _room(out_h, bound)
    new_start = np.zeros(n_rows, dtype=np.int64)
    new_len = np.zeros(n_rows, dtype=np.int64)
    row_h = np.full(n_rows, -1, dtype=np.int32)
    npool = 0
    nd = 0
    edges = 0
    a = 0
    while a < ne:
        f = e_row[a]
        b = a
        while b < ne and e_row[b] == f:
            b += 1
        token = next_token(stamp, token)
        tok = np.int32(token)
        p0 = npool
        npool = _copy_readers(f, rd_start, rd_len, pool, add_start, add_len, add_v, own, new_pool, npool, stamp, tok)
        # every frontier entry of a flood holds the same hop count (they all read it at the same hop)
        h = np.int32(e_hops[a] + 1)
        row_h[f] = h
        for q in range(a, b):
            u = e_slot[q]
            if e_own[q]:
                edges += end[u] - start[u]
            for p in range(start[u], end[u]):
                v = indices[p]
                if own[v] and stamp[v] != tok:
                    stamp[v] = tok
                    out_v[nd] = v
                    out_f[nd] = f
                    out_h[nd] = h
                    nd += 1
                    new_pool[npool] = v
                    npool += 1
        new_start[f] = p0
        new_len[f] = npool - p0
        a = b
    for f in range(n_rows):  # rows without a frontier entry here keep their own readers
        if row_h[f] < 0:
            p0 = npool
            npool = _copy_readers(
                f,
                rd_start,
                rd_len,
                pool,
                add_start,
                add_len,
                add_v,
                own,
                new_pool,
                npool,
                stamp,
                np.int32(-1),
            )
            new_start[f] = p0
            new_len[f] = npool - p0
    return new_pool, npool, new_start, new_len, out_v, out_f, out_h, nd, row_h, edges, token


@nb.njit(cache=True)
def _place(rank, count, row, slot, hops, per_row, own, e_row, e_slot, e_own, e_hops):  # type: ignore[no-untyped-def]
    # Entries (row, slot) at their row's next place (``count``: each rank's next position); hops per row or per entry.
    for q in range(row.shape[0]):
        f = row[q]
        r = rank[f]
        at = count[r]
        count[r] = at + 1
        e_row[at] = f
        e_slot[at] = slot[q]
        e_own[at] = own
        e_hops[at] = hops[f] if per_row else hops[q]


@nb.njit(cache=True)
def order_entries(rank, n_rows, fr_row, fr_slot, fr_hops, g_row, g_slot, g_hops):  # type: ignore[no-untyped-def]
    """The hop's frontier entries, own ones (``fr_*``) then the ghosts' (``g_*``), grouped by their row's rank.

    A stable counting sort (O(entries + rows)) that writes the sorted columns at once, without concatenating
    the two sources first. ``fr_hops`` is per row (an own entry relays at its row's hop count).

    Returns:
        ``(e_row, e_slot, e_own, e_hops, relayed)``: the sorted entries (``e_own``: an own entry) and, per row,
        whether an own entry relays it.
    """
    nf = fr_row.shape[0]
    ng = g_row.shape[0]
    count = np.zeros(n_rows + 1, dtype=np.int64)
    relayed = np.zeros(n_rows, dtype=np.bool_)
    for q in range(nf):
        count[rank[fr_row[q]] + 1] += 1
        relayed[fr_row[q]] = True
    for q in range(ng):
        count[rank[g_row[q]] + 1] += 1
    for r in range(n_rows):
        count[r + 1] += count[r]
    ne = nf + ng
    e_row = np.empty(ne, dtype=np.int64)
    e_slot = np.empty(ne, dtype=np.int64)
    e_own = np.empty(ne, dtype=np.bool_)
    e_hops = np.empty(ne, dtype=np.int32)
    _place(rank, count, fr_row, fr_slot, fr_hops, True, True, e_row, e_slot, e_own, e_hops)
    _place(rank, count, g_row, g_slot, g_hops, False, False, e_row, e_slot, e_own, e_hops)
    return e_row, e_slot, e_own, e_hops, relayed


@nb.njit(cache=True)
def next_frontier(out_v, out_f, out_h, nd, limit):  # type: ignore[no-untyped-def]
    """The own frontier after a hop: the deliveries ``out_*[:nd]`` (grouped by row) of rows still below their hop
    limit, as ``(fr_row, fr_slot, has_fr)`` (``has_fr``: per row of ``limit``, whether it has an entry)."""
    n = 0
    for k in range(nd):
        n += out_h[k] < limit[out_f[k]]
    fr_row = np.empty(n, dtype=np.int64)
    fr_slot = np.empty(n, dtype=np.int64)
    has_fr = np.zeros(limit.shape[0], dtype=np.bool_)
    j = 0
    for k in range(nd):
        f = out_f[k]
        if out_h[k] < limit[f]:
            fr_row[j] = f
            fr_slot[j] = out_v[k]
            has_fr[f] = True
            j += 1
    return fr_row, fr_slot, has_fr
