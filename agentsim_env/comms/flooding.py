"""The overlay's flooding kernel (numba): one call spreads every flood of the frontier by one hop (or fully).

Reader sets are lists, not bitsets: flood ``f`` has read by ``pool[rd_start[f]:rd_start[f] + rd_len[f]]``.
To spread a flood, the kernel stamps its readers into a per-slot ``stamp`` array with a fresh token, so
"already read" is one look-up in an array of S int32 (cache resident at any S), instead of a bit in a row of
``S / 64`` words per flood (a cold row per flood at large S). The lists are rewritten into a second pool each
call (double buffering), which drops the lists of floods that ended.

Floods are processed one at a time, every hop of a flood in turn; the outputs are then put in the order the
hop-by-hop formulation gives them (hop round first, then the frontier's flood order), so deliveries, ended
floods and the next frontier are the same as spreading all floods hop by hop.
"""

from __future__ import annotations

import numba as nb
import numpy as np

_TOKEN_MAX = np.iinfo(np.int32).max


@nb.njit(cache=True)
def next_token(stamp, token):  # type: ignore[no-untyped-def]
    """The next stamp token (a flood's "already read" mark); past the int32 range the stamps start over."""
    token += 1
    if token == _TOKEN_MAX:
        stamp[:] = 0
        token = 1
    return token


@nb.njit(cache=True)
def _room(a, need, keep):  # type: ignore[no-untyped-def]
    # ``a`` with room for ``need`` entries (doubling), its first ``keep`` entries kept.
    if need <= a.shape[0]:
        return a
    b = np.empty(max(need, 2 * a.shape[0], 64), dtype=a.dtype)
    b[:keep] = a[:keep]
    return b


@nb.njit(cache=True, nogil=True)
def take_readers(f, rd_start, rd_len, pool, new_pool, npool, stamp, tok):  # type: ignore[no-untyped-def]
    """Copy flood ``f``'s reader list into ``new_pool`` at ``npool`` and stamp its readers with ``tok`` (they
    have read it: the hop skips them); the new ``npool``."""
    s0 = rd_start[f]
    for k in range(rd_len[f]):
        x = pool[s0 + k]
        new_pool[npool] = x
        npool += 1
        stamp[x] = tok
    return npool


@nb.njit(cache=True, nogil=True)
def keep_rest(active, seen, rd_start, rd_len, pool, new_pool, npool):  # type: ignore[no-untyped-def]
    """The active floods without a frontier entry (not ``seen``) keep their readers, behind the spread floods'
    in ``new_pool[:npool]``; ``(new_pool, npool)``."""
    rest = 0
    for f in range(active.shape[0]):
        if active[f] and not seen[f]:
            rest += rd_len[f]
    new_pool = _room(new_pool, npool + rest, npool)
    for f in range(active.shape[0]):
        if active[f] and not seen[f]:
            s0 = rd_start[f]
            rd_start[f] = npool
            for k in range(rd_len[f]):
                new_pool[npool] = pool[s0 + k]
                npool += 1
    return new_pool, npool


@nb.njit(cache=True)
def _hop(start, end, indices, src, q_lo, q_hi, f, h, stamp, token, out_r, out_f, out_h, nd, pool, npool, keep):  # type: ignore[no-untyped-def]  # noqa: E501
    # One hop of flood f from the frontier slots src[q_lo:q_hi]. Branch free: every neighbour is written at the
    # end of the output and kept only if it had not read the flood (about 4 in 5 have at hop 2, so a branch
    # would mispredict often). Its own function, so the buffers are not rebound inside the loop.
    first = nd
    n_edges = 0
    for q in range(q_lo, q_hi):
        u = src[q]
        n_edges += end[u] - start[u]
        for p in range(start[u], end[u]):
            v = indices[p]
            fresh = stamp[v] != token
            stamp[v] = token
            out_r[nd] = v
            nd += fresh
    for k in range(first, nd):
        out_f[k] = f
        out_h[k] = h
    if keep:  # the flood goes on: its new readers join its reader list
        for k in range(first, nd):
            pool[npool] = out_r[k]
            npool += 1
    return nd, npool, n_edges - (nd - first)


@nb.njit(cache=True)
def spread(
    start,
    end,
    indices,
    hops,
    limit,
    active,
    rd_start,
    rd_len,
    pool,
    cur_f,
    cur_n,
    full,
    stamp,
    token,  # type: ignore[no-untyped-def]  # noqa: E501
    new_pool,
    out_r,
    out_f,
    out_h,
):
    """Spread the floods of the frontier ``(cur_f, cur_n)`` (grouped by flood) over the links.

    Returns:
        ``(nxt_f, nxt_n, nd, fin, dups, token, n_pool, new_pool, out_r, out_f, out_h)``: the next frontier,
        the number of deliveries (the first ``nd`` entries of ``out_*``), the floods that ended (in order),
        duplicate copies, the last token used, the live length of ``new_pool`` (which now holds every
        active flood's readers; ``rd_start`` / ``rd_len`` point into it), and the (possibly grown) buffers.
    """
    ncur = cur_f.shape[0]
    cap = active.shape[0]
    seen = np.zeros(cap, dtype=np.bool_)
    fin = np.empty(max(1, ncur), dtype=np.int64)
    fin_round = np.empty(max(1, ncur), dtype=np.int64)
    # (round, first delivery, count, relays) of every hop of every flood: the order of full mode and the
    # next frontier of one-hop mode are put together from them at the end
    seg = np.empty((max(1, ncur), 4), dtype=np.int64)
    n_seg = 0
    max_round = 0
    nd = 0
    nfin = 0
    dups = 0
    npool = 0
    # room for the first hop of every flood (new readers <= edges leaving the frontier) and every reader list
    # (enough in one-hop mode; full mode checks again before each flood, whose later hops take room too)
    bound = 0
    for q in range(ncur):
        bound += end[cur_n[q]] - start[cur_n[q]]
    live = 0
    for f in range(cap):
        if active[f]:
            live += rd_len[f]
    if bound > out_r.shape[0]:
        out_r, out_f, out_h = _room(out_r, bound, 0), _room(out_f, bound, 0), _room(out_h, bound, 0)
    if live + bound > new_pool.shape[0]:
        new_pool = _room(new_pool, live + bound, 0)
    a = 0
    while a < ncur:
        f = cur_f[a]
        b = a
        while b < ncur and cur_f[b] == f:
            b += 1
        seen[f] = True
        token = next_token(stamp, token)
        tok = np.int32(token)
        if full:  # earlier floods' later hops may have used the room reserved above: check this one's
            b0 = 0
            for q in range(a, b):
                b0 += end[cur_n[q]] - start[cur_n[q]]
            if nd + b0 > out_r.shape[0]:
                out_r, out_f, out_h = (
                    _room(out_r, nd + b0, nd),
                    _room(out_f, nd + b0, nd),
                    _room(out_h, nd + b0, nd),
                )
            if npool + rd_len[f] + b0 + live > new_pool.shape[0]:
                new_pool = _room(new_pool, npool + rd_len[f] + b0 + live, npool)
        p0 = npool
        npool = take_readers(f, rd_start, rd_len, pool, new_pool, npool, stamp, tok)
        rnd = 0
        lo = hi = 0
        while True:
            h = hops[f] + 1
            first = nd
            if rnd == 0:
                nd, npool, d = _hop(
                    start,
                    end,
                    indices,
                    cur_n,
                    a,
                    b,
                    f,
                    h,
                    stamp,
                    tok,
                    out_r,
                    out_f,
                    out_h,
                    nd,
                    new_pool,
                    npool,
                    h < limit[f],
                )
            else:
                nd, npool, d = _hop(
                    start,
                    end,
                    indices,
                    out_r,
                    lo,
                    hi,
                    f,
                    h,
                    stamp,
                    tok,
                    out_r,
                    out_f,
                    out_h,
                    nd,
                    new_pool,
                    npool,
                    h < limit[f],
                )
            dups += d
            hops[f] = h
            if n_seg == seg.shape[0]:
                grown = np.empty((2 * n_seg, 4), dtype=np.int64)
                grown[:n_seg] = seg
                seg = grown
            ends = nd == first or h >= limit[f]
            seg[n_seg, 0], seg[n_seg, 1], seg[n_seg, 2], seg[n_seg, 3] = rnd, first, nd - first, not ends
            n_seg += 1
            max_round = max(max_round, rnd)
            if ends:
                # the flood ends here: its new readers keep the message but do not relay it
                fin[nfin] = f
                fin_round[nfin] = rnd
                nfin += 1
                npool = p0  # its reader list is no longer needed
                break
            if not full:
                break
            # full mode: room for the next hop (new readers <= edges leaving this hop's readers)
            lo, hi = first, nd
            more = 0
            for q in range(lo, hi):
                more += end[out_r[q]] - start[out_r[q]]
            if nd + more > out_r.shape[0]:
                out_r, out_f, out_h = (
                    _room(out_r, nd + more, nd),
                    _room(out_f, nd + more, nd),
                    _room(out_h, nd + more, nd),
                )
            if npool + more + live > new_pool.shape[0]:
                new_pool = _room(new_pool, npool + more + live, npool)
            rnd += 1
        rd_start[f] = p0
        rd_len[f] = npool - p0
        a = b
    new_pool, npool = keep_rest(active, seen, rd_start, rd_len, pool, new_pool, npool)
    # one-hop mode: the new readers of the floods that go on relay at the next call
    nn = 0
    if not full:
        for k in range(n_seg):
            nn += seg[k, 2] * seg[k, 3]
    nxt_f = np.empty(nn, dtype=np.int64)
    nxt_n = np.empty(nn, dtype=np.int64)
    if not full:
        nn = 0
        for k in range(n_seg):
            if seg[k, 3]:
                for q in range(seg[k, 1], seg[k, 1] + seg[k, 2]):
                    nxt_f[nn] = out_f[q]
                    nxt_n[nn] = out_r[q]
                    nn += 1
    if max_round > 0:  # full mode: hop-major order (a stable counting sort by round)
        cnt = np.zeros(max_round + 2, dtype=np.int64)
        for k in range(n_seg):
            cnt[seg[k, 0] + 1] += seg[k, 2]
        for r in range(max_round + 1):
            cnt[r + 1] += cnt[r]
        r2 = np.empty(nd, dtype=out_r.dtype)
        f2 = np.empty(nd, dtype=out_f.dtype)
        h2 = np.empty(nd, dtype=out_h.dtype)
        for k in range(n_seg):
            r = seg[k, 0]
            for q in range(seg[k, 1], seg[k, 1] + seg[k, 2]):
                r2[cnt[r]] = out_r[q]
                f2[cnt[r]] = out_f[q]
                h2[cnt[r]] = out_h[q]
                cnt[r] += 1
        out_r[:nd] = r2
        out_f[:nd] = f2
        out_h[:nd] = h2
        order = np.argsort(fin_round[:nfin], kind="mergesort")
        fin[:nfin] = fin[:nfin][order]
    return nxt_f, nxt_n, nd, fin[:nfin].copy(), dups, token, npool, new_pool, out_r, out_f, out_h


@nb.njit(cache=True, nogil=True)
def hop_range(
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
    stamp,
    token,  # type: ignore[no-untyped-def]  # noqa: E501
    seen,
    new_pool,
    out_r,
    out_f,
    out_h,
    nxt_f,
    nxt_n,
    fin,
):
    """One hop of the floods of the frontier entries ``[a0, b0)`` (whole floods, grouped by flood), one-hop mode.

    Per flood, in frontier order: its readers are copied to ``new_pool`` and stamped, the edges leaving its
    frontier entries are walked (branch free: every neighbour is written at the end of ``out_r`` and kept only if
    it had not read the flood; about 4 in 5 have at hop 2), and its new readers either join its reader list and
    the next frontier (it goes on) or it ends (``fin``; its new readers keep the message but do not relay it).
    Outputs go to the buffers from 0 (``rd_start`` of these floods relative to ``new_pool``); buffers too small
    are grown. ``spread_hop`` runs it over the whole frontier, ``flood_threads`` over ranges on threads.

    Returns:
        ``(nd, npool, nn, nfin, dups, token, new_pool, out_r, out_f, out_h, nxt_f, nxt_n, fin)``: deliveries,
        live pool entries, next-frontier entries and ended floods written, duplicate copies, the last token, and
        the (possibly grown) buffers.
    """
    bound = 0
    live = 0
    n_fl = 0
    for q in range(a0, b0):
        bound += end[cur_n[q]] - start[cur_n[q]]
        if q == a0 or cur_f[q] != cur_f[q - 1]:
            live += rd_len[cur_f[q]]
            n_fl += 1
    out_r, out_f, out_h = _room(out_r, bound, 0), _room(out_f, bound, 0), _room(out_h, bound, 0)
    nxt_f, nxt_n = _room(nxt_f, bound, 0), _room(nxt_n, bound, 0)
    new_pool = _room(new_pool, live + bound, 0)
    fin = _room(fin, n_fl, 0)
    nd = 0
    npool = 0
    nn = 0
    nfin = 0
    edges = 0
    a = a0
    while a < b0:
        f = cur_f[a]
        b = a
        while b < b0 and cur_f[b] == f:
            b += 1
        seen[f] = True
        token = next_token(stamp, token)
        tok = np.int32(token)
        p0 = npool
        npool = take_readers(f, rd_start, rd_len, pool, new_pool, npool, stamp, tok)
        h = hops[f] + 1
        hops[f] = h
        first = nd
        for q in range(a, b):
            u = cur_n[q]
            e0 = end[u]
            edges += e0 - start[u]
            for p in range(start[u], e0):
                v = indices[p]
                fresh = stamp[v] != tok
                stamp[v] = tok
                out_r[nd] = v
                nd += fresh
        for k in range(first, nd):
            out_f[k] = f
            out_h[k] = h
        if nd > first and h < limit[f]:  # it goes on: the new readers join its list and relay next time
            for k in range(first, nd):
                v = out_r[k]
                new_pool[npool] = v
                nxt_f[nn] = f
                nxt_n[nn] = v
                npool += 1
                nn += 1
        else:
            fin[nfin] = f
            nfin += 1
            npool = p0  # its reader list is no longer needed
        rd_start[f] = p0
        rd_len[f] = npool - p0
        a = b
    return nd, npool, nn, nfin, edges - nd, token, new_pool, out_r, out_f, out_h, nxt_f, nxt_n, fin


@nb.njit(cache=True)
def spread_hop(
    start,
    end,
    indices,
    hops,
    limit,
    active,
    rd_start,
    rd_len,
    pool,
    cur_f,
    cur_n,
    stamp,
    token,  # type: ignore[no-untyped-def]  # noqa: E501
    new_pool,
    out_r,
    out_f,
    out_h,
):
    """``spread`` in one-hop mode (the same results and return values) through ``hop_range``: the comms stack's
    hop on one thread."""
    ncur = cur_f.shape[0]
    seen = np.zeros(active.shape[0], dtype=np.bool_)
    e = np.empty(0, dtype=np.int64)
    nd, npool, nn, nfin, dups, token, new_pool, out_r, out_f, out_h, nxt_f, nxt_n, fin = hop_range(
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
        0,
        ncur,
        stamp,
        token,
        seen,
        new_pool,
        out_r,
        out_f,
        out_h,
        e,
        e.copy(),
        e.copy(),
    )
    new_pool, npool = keep_rest(active, seen, rd_start, rd_len, pool, new_pool, npool)
    return nxt_f[:nn], nxt_n[:nn], nd, fin[:nfin], dups, token, npool, new_pool, out_r, out_f, out_h
