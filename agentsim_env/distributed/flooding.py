"""Overlay floods over shards: each shard spreads floods into its own agents; the coordinator keeps the floods.

The single-process overlay (``comms.overlay``) keeps, per flood, the list of slots that read it, and one hop
walks every link out of the flood's frontier. Over shards that walk is split by receiver: a slot ``v`` reads
flood ``f`` at a hop when it has not read ``f`` and a frontier slot of ``f`` links to it. Every such frontier
slot lies within ``v``'s link range, so on ``v``'s shard it is an own agent or a ghost; and whether ``v`` read
``f`` is kept by ``v``'s shard (``ShardReaders``: per flood, the own slots that read it; the list travels with an
agent handed over to another shard). So each shard computes exactly the deliveries to its own agents.

The coordinator keeps the flood table (origins, hop limits, hop counts, payloads, the frontier) in a
``ShardedOverlay``: its ``advance_graph`` takes the deliveries the shards found instead of walking links, and
does the single-process bookkeeping (hop counts, floods that end, the next frontier, statistics; duplicates =
links walked - deliveries). Deliveries come out grouped by flood in frontier order, as in one process (within a
flood the order of the receivers may differ, which nothing observes): a receiver gets at most one copy of a
flood per hop, so its inbox gets the same messages in the same order for any split.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from agentsim_env.comms.flooding import next_token
from agentsim_env.comms.overlay import Deliveries, Overlay, OverlayStats


@nb.njit(cache=True)
def _keep_readers(f, rd_start, rd_len, pool, own, add_start, add_len, add_v, new_pool, npool, stamp, tok):  # type: ignore[no-untyped-def]  # noqa: E501
    # Flood f's own readers (the ones still own, then the added ones) into new_pool, stamped with tok (when
    # tok >= 0); returns the new pool length.
    for k in range(rd_start[f], rd_start[f] + rd_len[f]):
        x = pool[k]
        if own[x]:
            new_pool[npool] = x
            npool += 1
            if tok >= 0:
                stamp[x] = tok
    for k in range(add_start[f], add_start[f] + add_len[f]):
        x = add_v[k]
        new_pool[npool] = x
        npool += 1
        if tok >= 0:
            stamp[x] = tok
    return npool


@nb.njit(cache=True)
def _hop_kernel(start, end, indices, own, fr_f, fr_u, active, rd_start, rd_len, pool, add_start, add_len, add_v,  # type: ignore[no-untyped-def]  # noqa: E501
                stamp, token):  # fmt: skip
    # One hop of the relevant frontier entries (fr_f, fr_u), grouped by flood, into the own slots; rebuilds the
    # reader pool (own readers of every active flood, the added ones included) into a new array.
    cap = active.shape[0]
    n_old = 0
    for f in range(cap):
        if active[f]:
            n_old += rd_len[f] + add_len[f]
    bound = 0
    for q in range(fr_u.shape[0]):
        bound += end[fr_u[q]] - start[fr_u[q]]
    new_pool = np.empty(n_old + bound, dtype=np.int64)
    out_v = np.empty(bound, dtype=np.int64)
    out_f = np.empty(bound, dtype=np.int64)
    new_start = np.zeros(cap, dtype=np.int64)
    new_len = np.zeros(cap, dtype=np.int64)
    seen = np.zeros(cap, dtype=np.bool_)
    npool = 0
    nd = 0
    edges = 0
    a = 0
    n_fr = fr_f.shape[0]
    while a < n_fr:
        f = fr_f[a]
        b = a
        while b < n_fr and fr_f[b] == f:
            b += 1
        seen[f] = True
        token = next_token(stamp, token)
        tok = np.int32(token)
        p0 = npool
        npool = _keep_readers(
            f, rd_start, rd_len, pool, own, add_start, add_len, add_v, new_pool, npool, stamp, tok
        )
        for q in range(a, b):
            u = fr_u[q]
            if own[u]:
                edges += end[u] - start[u]
            for p in range(start[u], end[u]):
                v = indices[p]
                if own[v] and stamp[v] != tok:
                    stamp[v] = tok
                    out_v[nd] = v
                    out_f[nd] = f
                    nd += 1
                    new_pool[npool] = v
                    npool += 1
        new_start[f] = p0
        new_len[f] = npool - p0
        a = b
    for f in range(cap):  # active floods without a relevant frontier entry keep their own readers
        if active[f] and not seen[f]:
            p0 = npool
            npool = _keep_readers(f, rd_start, rd_len, pool, own, add_start, add_len, add_v, new_pool, npool, stamp,
                                  np.int32(-1))  # fmt: skip
            new_start[f] = p0
            new_len[f] = npool - p0
    return new_pool[:npool], new_start, new_len, out_v[:nd], out_f[:nd], edges, token


@nb.njit(cache=True)
def _reads_of(leaving, active, rd_start, rd_len, pool):  # type: ignore[no-untyped-def]
    # (flood, slot) of every reader entry whose slot is leaving the shard.
    n = 0
    for f in range(active.shape[0]):
        if active[f]:
            for k in range(rd_start[f], rd_start[f] + rd_len[f]):
                n += leaving[pool[k]]
    fl = np.empty(n, dtype=np.int64)
    sl = np.empty(n, dtype=np.int64)
    n = 0
    for f in range(active.shape[0]):
        if active[f]:
            for k in range(rd_start[f], rd_start[f] + rd_len[f]):
                x = pool[k]
                if leaving[x]:
                    fl[n] = f
                    sl[n] = x
                    n += 1
    return fl, sl


@nb.njit(cache=True)
def _by_rank(rank, slot, flood, n_ranks):  # type: ignore[no-untyped-def]
    # A stable counting sort of the deliveries by their flood's rank in the frontier: O(n + floods), where a
    # comparison sort of a million deliveries took longer than the hop itself.
    count = np.zeros(n_ranks + 1, dtype=np.int64)
    for q in range(flood.shape[0]):
        count[rank[flood[q]] + 1] += 1
    per = count[1:].copy()
    for r in range(n_ranks):
        count[r + 1] += count[r]
    out_s = np.empty_like(slot)
    out_f = np.empty_like(flood)
    for q in range(flood.shape[0]):
        r = rank[flood[q]]
        out_s[count[r]] = slot[q]
        out_f[count[r]] = flood[q]
        count[r] += 1
    return out_s, out_f, per


class ShardReaders:
    """A shard's share of the overlay: per flood id, the own slots that read it (see the module docstring).

    Args:
        n_slots: Number of slots S.
    """

    def __init__(self, n_slots: int) -> None:
        self.n_slots = int(n_slots)
        self._stamp = np.zeros(self.n_slots, dtype=np.int32)
        self._token = 0
        self.reset()

    def reset(self) -> None:
        """Forget every flood (a new episode)."""
        self.active = np.zeros(0, dtype=bool)
        self._start = np.zeros(0, dtype=np.int64)
        self._len = np.zeros(0, dtype=np.int64)
        self._pool = np.zeros(0, dtype=np.int64)
        self._add_f: list[np.ndarray] = []
        self._add_v: list[np.ndarray] = []

    def _fit(self, cap: int) -> None:
        old = self.active.shape[0]
        if cap > old:
            pad = cap - old
            self.active = np.concatenate([self.active, np.zeros(pad, dtype=bool)])
            self._start = np.concatenate([self._start, np.zeros(pad, dtype=np.int64)])
            self._len = np.concatenate([self._len, np.zeros(pad, dtype=np.int64)])

    def add(self, flood: np.ndarray, slot: np.ndarray) -> None:
        """Readers that joined this shard: ``slot[i]`` has read ``flood[i]`` (hand-overs, new origins)."""
        if len(flood):
            self._add_f.append(np.asarray(flood, dtype=np.int64))
            self._add_v.append(np.asarray(slot, dtype=np.int64))

    def take_leaving(self, leaving: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(flood, slot)`` of the reads of the slots in ``leaving`` (``(S,)`` bool): they go with the agents."""
        if not self.active.any() and not self._add_f:
            e = np.zeros(0, dtype=np.int64)
            return e, e.copy()
        fl, sl = _reads_of(leaving, self.active, self._start, self._len, self._pool)
        if self._add_f:  # reads added since the last hop
            af, av = np.concatenate(self._add_f), np.concatenate(self._add_v)
            go = leaving[av]
            fl, sl = np.concatenate([fl, af[go]]), np.concatenate([sl, av[go]])
            self._add_f, self._add_v = [af[~go]], [av[~go]]
        return fl, sl

    def hop(
        self,
        links: tuple[np.ndarray, np.ndarray, np.ndarray],
        own: np.ndarray,
        active: np.ndarray,
        started: np.ndarray,
        origin: np.ndarray,
        fr_f: np.ndarray,
        fr_u: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """One hop into the own slots.

        Args:
            links: The shard's range graph ``(start, end, indices)`` over its own agents and ghosts.
            own: ``(S,)`` bool, the own slots.
            active: ``(C,)`` the coordinator's active floods (after this step's starts).
            started: Flood ids started this step (their rows may have held an ended flood's readers).
            origin: Their origins (each has read its own flood).
            fr_f: Flood of each relevant frontier entry (own or ghost frontier slots), grouped by flood in
                frontier order.
            fr_u: Their slots.

        Returns:
            ``(slot, flood, links)``: the deliveries to own slots and the links walked out of own frontier slots.
        """
        cap = active.shape[0]
        self._fit(cap)
        self._len[started] = 0
        self.active = np.asarray(active, dtype=bool).copy()
        if self._add_f:
            af, av = np.concatenate(self._add_f), np.concatenate(self._add_v)
            fresh = ~np.isin(af, started)  # reads of an ended flood whose id was given to a new one
            af, av = af[fresh], av[fresh]
        else:
            af = av = np.zeros(0, dtype=np.int64)
        self._add_f, self._add_v = [], []
        mine = own[origin]
        af, av = np.concatenate([af, started[mine]]), np.concatenate([av, origin[mine]])
        order = np.argsort(af, kind="stable")
        af, av = af[order], av[order]
        add_len = np.bincount(af, minlength=cap).astype(np.int64)
        add_start = np.concatenate([[0], np.cumsum(add_len)[:-1]]).astype(np.int64)
        start, end, indices = links
        pool, self._start, self._len, out_v, out_f, edges, self._token = _hop_kernel(
            start, end, indices, own, fr_f, fr_u, self.active, self._start, self._len, self._pool, add_start, add_len,
            av, self._stamp, self._token,
        )  # fmt: skip
        self._pool = pool
        return out_v, out_f, int(edges)


class ShardedOverlay(Overlay):
    """The coordinator's overlay: the flood table and frontier, hops from the shards' deliveries.

    ``put(slot, flood, links)`` hands over the step's gathered deliveries before the comms stage runs; then
    ``advance_graph`` (called by the comms stack with a graph it ignores) does the bookkeeping of one hop.
    Reader lists live on the shards (``readers()`` here knows only the origins).
    """

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._put: tuple[np.ndarray, np.ndarray, int] | None = None

    @classmethod
    def like(cls, other: Overlay) -> ShardedOverlay:
        """A sharded overlay with the settings (slots, payload width, ranges) of ``other``."""
        return cls(
            other.n_slots, other.payload_dim, other.comm_range.copy(), full_propagation=other.full_propagation
        )

    def put(self, slot: np.ndarray, flood: np.ndarray, links: int) -> None:
        """The deliveries every shard found for the coming hop (any order) and the links they walked."""
        self._put = (slot, flood, links)

    def hop_plan(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What the shards need for the coming hop (read only).

        Returns:
            ``(active, flood, slot, new)``: the active flood ids ``(C,)`` bool; every frontier entry's flood and
            slot, grouped by flood in frontier order; whether the entry is its flood's origin (started this step).
        """
        return self._active, self._front_f, self._front_n, self._hops[self._front_f] == 0

    def advance_graph(self, start: np.ndarray, end: np.ndarray, indices: np.ndarray) -> Deliveries:
        """One hop from the gathered deliveries (the graph arguments are ignored)."""
        del start, end, indices
        started = self._pending_started
        self._pending_started = 0
        self._n_pool = 0  # readers are kept by the shards
        slot, flood, links = self._put if self._put is not None else (np.zeros(0, np.int64),) * 2 + (0,)
        self._put = None
        cur_f = self._front_f
        if cur_f.size == 0:
            empty = np.zeros(0, dtype=np.int64)
            out = Deliveries(empty, empty.copy(), empty.copy(), np.zeros(0, dtype=np.int32), empty.copy(),
                             np.zeros((0, self.payload_dim), dtype=np.float32))  # fmt: skip
            self._last = OverlayStats(started, 0, 0, 0)
            self._totals = self._totals + self._last
            return out
        first = np.unique(cur_f, return_index=True)[1]
        floods = cur_f[np.sort(first)]  # frontier order
        rank = np.zeros(self.capacity, dtype=np.int64)
        rank[floods] = np.arange(floods.shape[0])
        # grouped by the floods' frontier order (a receiver gets at most one copy of a flood, so its inbox order
        # is the floods' order; within a flood the shards' order is kept)
        slot, flood, n_new = _by_rank(rank, np.ascontiguousarray(slot, dtype=np.int64),
                                      np.ascontiguousarray(flood, dtype=np.int64), floods.shape[0])  # fmt: skip
        self._hops[floods] += 1
        ends = (n_new == 0) | (self._hops[floods] >= self._limit[floods])
        fin = floods[ends]
        goes = np.zeros(self.capacity, dtype=bool)
        goes[floods[~ends]] = True
        keep = goes[flood]
        self._front_f, self._front_n = flood[keep], slot[keep]
        if fin.shape[0]:
            self._active[fin] = False
            self._free[self._n_free : self._n_free + fin.shape[0]] = fin[::-1]
            self._n_free += fin.shape[0]
        out = Deliveries(
            receiver=slot,
            flood=flood,
            origin=self._origin[flood],
            hops=self._hops[flood].astype(np.int32),
            created=self._created[flood],
            payload=np.take(self._payload, flood, axis=0),
        )
        self._last = OverlayStats(started, len(out), int(links) - len(out), int(fin.shape[0]))
        self._totals = self._totals + self._last
        return out
