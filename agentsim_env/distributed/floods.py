"""Overlay floods over parts with no central flood table: each part keeps only what its own slots hold.

A *part* owns some slots and knows the positions of its own slots and of its ghosts (slots of other parts within
a halo at least the overlay's link range). ``PartFloods`` keeps, for the part's own slots only, which floods they
read and which of them relay at the next hop (the frontier), with the floods' origin, hop limit, created step and
payload. It spreads floods exactly as the single-process ``comms.overlay.Overlay`` does (one hop per call).

Flood identity: the key ``(created, origin, seq)``: the step the flood was started, the slot that started it, and
the number of floods that slot had already started in that step (0 for the first; the comms stack starts at most
one flood per slot and step, so ``seq`` is 0 there). The key does not depend on which process holds the flood.

Order: the single-process overlay spreads floods in the order they were started (a flood keeps its place in the
frontier until it ends) and pushes a hop's deliveries grouped by flood in that order. The comms stack starts a
step's floods in one call with ascending origins, so that order is the key order; ``hop`` returns deliveries
grouped by flood in key order. A slot reads a flood at most once, so each receiver's deliveries of a hop come in
key order: the order its inbox gets them in one process. (Within a flood the receivers' order may differ from
one process's, which no inbox observes.)

Why a part computes exactly the deliveries into its own slots: slot ``v`` reads flood ``f`` at a hop when it has
not read ``f`` and a frontier slot of ``f`` links to it. Such a frontier slot lies within ``v``'s link range, so
it is an own slot or a ghost of ``v``'s part; whether ``v`` read ``f`` is kept by ``v``'s part (the reads go with
an agent handed over to another part).

What the caller exchanges, each step:

1. Stage 1: ``start`` on the part owning each origin.
2. Hand-overs (any time between hops): ``take_leaving(slots)`` on the old part, ``add(entries)`` on the new one.
3. Before the hop: each part sends ``frontier_of(slots)`` for its own slots that are ghosts of a neighbour part
   to that neighbour; a part hops with the concatenation (``FloodEntries.concat``) of what it received.
4. ``hop(links, own, ghost_frontier)`` on every part, every step (also with nothing to spread: a part counts
   hops to forget floods that can no longer spread).
5. Statistics: ``combine_stats`` of every part's ``stats`` (three integer sums and a union of flood keys). The
   parts' ``frontier_size`` add up to ``Overlay.frontier_size`` (a frontier entry is held by its slot's part).

A slot's floods of one step must start on one part (the key's ``seq`` is counted there). Only the one-hop-per-step
mode exists here (``Overlay``'s ``full_propagation`` spreads a flood to its hop limit in one call, which would
need an exchange per hop).

Memory: a part forgets a flood once no own slot relays it and it has used its hop limit (or once no own slot
has read it): at most the floods of the last ``max hop limit`` steps, with their own readers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np

from agentsim_env.comms.overlay import OverlayStats, check_flood_starts
from agentsim_env.distributed.flood_kernels import (
    hop_kernel,
    leaving_reads,
    next_frontier,
    order_entries,
    split_reads,
)

_I64 = np.int64


def _e(dtype: type = np.int64) -> np.ndarray:
    return np.zeros(0, dtype=dtype)


@dataclass(slots=True, frozen=True)
class FloodEntries:
    """Reads of floods by slots, as they travel between parts: ghost frontier entries or handed-over reads.

    Attributes:
        slot: The slot that read the flood ``(k,)`` int64.
        created: The flood's created step ``(k,)`` int64 (key, with ``origin`` and ``seq``).
        origin: The slot that started it ``(k,)`` int64.
        seq: Floods the origin started before it in the same step ``(k,)`` int64.
        hops: The hop count at which ``slot`` relays the flood at the next hop, or -1 when it does not relay
            ``(k,)`` int32.
        limit: The flood's hop limit ``(k,)`` int32.
        left: Hops the flood can still take from now (hop limit minus its current hop count) ``(k,)`` int32.
        payload: The flood's payload ``(k, D)`` float32.
    """

    slot: np.ndarray
    created: np.ndarray
    origin: np.ndarray
    seq: np.ndarray
    hops: np.ndarray
    limit: np.ndarray
    left: np.ndarray
    payload: np.ndarray

    def __len__(self) -> int:
        """Number of entries."""
        return int(self.slot.shape[0])

    @classmethod
    def empty(cls, payload_dim: int) -> FloodEntries:
        """No entries, with payload width ``payload_dim``."""
        i32 = np.zeros(0, dtype=np.int32)
        return cls(_e(), _e(), _e(), _e(), i32, i32.copy(), i32.copy(), np.zeros((0, payload_dim), np.float32))

    @classmethod
    def concat(cls, parts: Sequence[FloodEntries], payload_dim: int) -> FloodEntries:
        """All entries of ``parts`` in order (what a part received from its neighbours)."""
        if not parts:
            return cls.empty(payload_dim)
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))


class FloodDeliveries:
    """Flood messages read by own slots during one ``hop``, grouped by flood in key order.

    Attributes:
        receiver: Slot that read the message ``(k,)`` int64.
        origin: Slot that started the flood ``(k,)`` int64.
        created: Step the flood was started ``(k,)`` int64.
        seq: The flood's sequence number in its key ``(k,)`` int64.
        hops: Hops from the origin to the receiver ``(k,)`` int32 (>= 1).
        payload: Message payload ``(k, D)`` float32.
        rows: Each delivery's row in ``table``.
        table: The part's flood columns ``(origin, created, payload, seq)`` at the hop (replaced, never written,
            afterwards), from which ``origin``, ``created``, ``seq`` and ``payload`` are looked up when read.
    """

    __slots__ = ("receiver", "hops", "rows", "table", "_cols")

    def __init__(
        self,
        receiver: np.ndarray,
        hops: np.ndarray,
        rows: np.ndarray,
        table: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    ) -> None:
        self.receiver, self.hops, self.rows, self.table = receiver, hops, rows, table
        self._cols: dict[int, np.ndarray] = {}

    def _col(self, i: int) -> np.ndarray:
        if i not in self._cols:
            self._cols[i] = np.take(self.table[i], self.rows, axis=0)
        return self._cols[i]

    @property
    def origin(self) -> np.ndarray:
        """Slot that started the flood ``(k,)`` int64."""
        return self._col(0)

    @property
    def created(self) -> np.ndarray:
        """Step the flood was started ``(k,)`` int64."""
        return self._col(1)

    @property
    def payload(self) -> np.ndarray:
        """Message payload ``(k, D)`` float32."""
        return self._col(2)

    @property
    def seq(self) -> np.ndarray:
        """The flood's sequence number in its key ``(k,)`` int64."""
        return self._col(3)

    def __len__(self) -> int:
        """Number of deliveries."""
        return int(self.receiver.shape[0])


@dataclass(slots=True, frozen=True)
class PartHopStats:
    """One part's share of a hop's counters (see ``combine_stats``).

    Attributes:
        started: Floods started by own slots since the previous hop (sum over parts).
        delivered: Deliveries into own slots (sum over parts).
        duplicates: Links walked out of own frontier entries minus ``delivered`` (sum over parts).
        relayed: Keys ``(k, 3)`` of the floods with an own frontier entry at this hop (union over parts).
        frontier: Keys ``(k, 3)`` of the floods with an own frontier entry after this hop (union over parts).
    """

    started: int
    delivered: int
    duplicates: int
    relayed: np.ndarray
    frontier: np.ndarray


def _n_keys(keys: Sequence[np.ndarray]) -> int:
    k = np.concatenate([np.asarray(x, dtype=np.int64).reshape(-1, 3) for x in keys]) if keys else _e().reshape(0, 3)
    return int(np.unique(k, axis=0).shape[0]) if k.shape[0] else 0


def combine_stats(parts: Sequence[PartHopStats]) -> tuple[OverlayStats, int]:
    """The single-process counters of one hop from every part's share.

    ``started``, ``delivered`` and ``duplicates`` are plain sums. ``finished`` (floods that ended at this hop)
    and the active flood count need a union of flood keys across parts, since a flood relays on several parts:
    the floods that relayed at the hop minus those that still relay after it.

    Returns:
        ``(stats, active)``: the ``OverlayStats`` of the hop (as ``Overlay.stats``) and the number of floods still
        spreading (as ``Overlay.active_count`` after the hop).
    """
    relayed = _n_keys([p.relayed for p in parts])
    active = _n_keys([p.frontier for p in parts])
    stats = OverlayStats(
        sum(p.started for p in parts),
        sum(p.delivered for p in parts),
        sum(p.duplicates for p in parts),
        relayed - active,
    )
    return stats, active


class PartFloods:
    """The floods of one part's own slots (see the module docstring).

    Args:
        n_slots: Number of slots S of the whole run (slot ids are global).
        payload_dim: Payload width D (>= 0).

    The object holds plain numpy arrays only, so it pickles and deep-copies.
    """

    def __init__(self, n_slots: int, payload_dim: int) -> None:
        if int(n_slots) < 1:
            raise ValueError(f"n_slots must be >= 1, got {n_slots}")
        if int(payload_dim) < 0:
            raise ValueError(f"payload_dim must be >= 0, got {payload_dim}")
        self.n_slots = int(n_slots)
        self.payload_dim = int(payload_dim)
        self._stamp = np.zeros(self.n_slots, dtype=np.int32)
        self._token = 0
        # the hop kernel's buffers, kept between hops: (spare pool, out_v, out_f, out_h); ``_pool_buf`` is the
        # buffer ``_pool`` is a view of (never the spare)
        self._scratch: tuple[np.ndarray, ...] | None = None
        self._pool_buf: np.ndarray | None = None
        self.reset()

    def __getstate__(self) -> dict[str, object]:
        """The state without the hop kernel's buffers (new ones at the next hop)."""
        return {**self.__dict__, "_scratch": None, "_pool_buf": None}

    def _buffers(self) -> tuple[np.ndarray, ...]:
        if self._scratch is None:
            self._scratch = (_e(), _e(), _e(), _e(np.int32))
        spare = self._scratch[0]
        return (_e() if spare is self._pool_buf else spare, *self._scratch[1:])

    def reset(self) -> None:
        """Forget every flood and zero the hop counter."""
        # per flood row: key, hop limit, payload, the last hop count at which it can still spread (``_end``, on
        # this part's hop counter) and the hop count of its own frontier entries
        self._c, self._o, self._q = _e(), _e(), _e()
        self._limit = _e(np.int32)
        self._pay = np.zeros((0, self.payload_dim), dtype=np.float32)
        self._end = _e()
        self._hops = _e(np.int32)
        self._rd_start, self._rd_len, self._pool = _e(), _e(), _e()
        self._pool_buf = None
        self._add_row, self._add_slot = _e(), _e()  # reads added since the lists were last rebuilt
        self._fr_row, self._fr_slot = _e(), _e()  # own frontier entries
        self._clock = 0
        self._seq_step: int | None = None
        self._seq_seen = _e()
        self._started = 0
        self._stats = PartHopStats(0, 0, 0, _e().reshape(0, 3), _e().reshape(0, 3))

    # ------------------------------------------------------------------ views
    @property
    def n_floods(self) -> int:
        """Floods this part keeps (with an own reader or an own frontier entry)."""
        return int(self._c.shape[0])

    @property
    def n_reads(self) -> int:
        """Own (slot, flood) reads kept (those of slots handed over since the last hop counted until it)."""
        return int(self._rd_len.sum()) + int(self._add_row.shape[0])

    @property
    def frontier_size(self) -> int:
        """Own frontier entries (relaying at the next hop)."""
        return int(self._fr_row.shape[0])

    @property
    def stats(self) -> PartHopStats:
        """This part's share of the last hop's counters."""
        return self._stats

    def keys(self) -> np.ndarray:
        """Keys ``(n_floods, 3)`` of the kept floods (``created, origin, seq``)."""
        return np.column_stack([self._c, self._o, self._q])

    # ------------------------------------------------------------------ rows
    def _rows_for(
        self, c: np.ndarray, o: np.ndarray, q: np.ndarray, limit: np.ndarray, pay: np.ndarray, end: np.ndarray
    ) -> np.ndarray:
        # The row of each key, adding rows for keys not kept yet (vectorized: one stable sort of the keys).
        n = self._c.shape[0]
        if c.shape[0] == 0:
            return _e()
        ac, ao, aq = np.concatenate([self._c, c]), np.concatenate([self._o, o]), np.concatenate([self._q, q])
        order = np.lexsort((aq, ao, ac))  # stable: a kept row comes first among equal keys
        sc, so, sq = ac[order], ao[order], aq[order]
        head = np.ones(order.shape[0], dtype=bool)
        head[1:] = (sc[1:] != sc[:-1]) | (so[1:] != so[:-1]) | (sq[1:] != sq[:-1])
        first = order[head]
        new = first >= n
        grp_row = first.copy()
        grp_row[new] = n + np.arange(int(new.sum()))
        rows = np.empty(order.shape[0], dtype=np.int64)
        rows[order] = grp_row[np.cumsum(head) - 1]
        src = first[new] - n  # the entries that define the new rows
        if src.shape[0]:
            m = src.shape[0]
            self._c, self._o, self._q = (
                np.concatenate([self._c, c[src]]),
                np.concatenate([self._o, o[src]]),
                np.concatenate([self._q, q[src]]),
            )
            self._limit = np.concatenate([self._limit, limit[src].astype(np.int32)])
            self._pay = np.concatenate([self._pay, pay[src].astype(np.float32)])
            self._end = np.concatenate([self._end, end[src].astype(np.int64)])
            self._hops = np.concatenate([self._hops, np.zeros(m, dtype=np.int32)])
            self._rd_start = np.concatenate([self._rd_start, np.zeros(m, dtype=np.int64)])
            self._rd_len = np.concatenate([self._rd_len, np.zeros(m, dtype=np.int64)])
        return rows[n:]

    def _adds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # the added reads grouped by row: (add_start, add_len, slots)
        n = self._c.shape[0]
        order = np.argsort(self._add_row, kind="stable")
        add_len = np.bincount(self._add_row, minlength=n).astype(np.int64)
        add_start = np.zeros(n, dtype=np.int64)
        np.cumsum(add_len[:-1], out=add_start[1:])
        return add_start, add_len, np.ascontiguousarray(self._add_slot[order])

    def _entries(self, rows: np.ndarray, slots: np.ndarray, hops: np.ndarray) -> FloodEntries:
        return FloodEntries(
            slot=slots.astype(np.int64),
            created=self._c[rows],
            origin=self._o[rows],
            seq=self._q[rows],
            hops=hops.astype(np.int32),
            limit=self._limit[rows],
            left=(self._end[rows] - self._clock).astype(np.int32),
            payload=np.take(self._pay, rows, axis=0),
        )

    def _mask(self, slots: np.ndarray) -> np.ndarray:
        m = np.zeros(self.n_slots, dtype=bool)
        m[np.asarray(slots, dtype=np.int64)] = True
        return m

    # ------------------------------------------------------------------ API
    def start(
        self, origin: np.ndarray, hop_limit: np.ndarray | int, payload: np.ndarray | None, step: int
    ) -> np.ndarray:
        """Start one flood per origin (own slots); the origin has read its own flood (hops 0).

        Args:
            origin: Origin slots ``(k,)`` in ``[0, S)``, ascending within a step (as the comms stack starts them).
            hop_limit: Hop limit per flood ``(k,)`` or a scalar, >= 1.
            payload: Payloads ``(k, D)`` (or ``(D,)`` for all); None means zeros.
            step: Current step, the floods' created step.

        Returns:
            The new floods' keys ``(k, 3)`` int64 (``created, origin, seq``).
        """
        origin, lim, pl = check_flood_starts(origin, hop_limit, payload, self.n_slots, self.payload_dim)
        k = origin.shape[0]
        if k == 0:
            return _e().reshape(0, 3)
        if self._seq_step != int(step):
            self._seq_step, self._seq_seen = int(step), _e()
        # seq: how many floods the same origin started earlier in this step (stable: in call order)
        seen = np.concatenate([self._seq_seen, origin])
        order = np.argsort(seen, kind="stable")
        s = seen[order]
        head = np.ones(s.shape[0], dtype=bool)
        head[1:] = s[1:] != s[:-1]
        at = np.arange(s.shape[0])
        rank = np.empty(s.shape[0], dtype=np.int64)
        rank[order] = at - np.maximum.accumulate(np.where(head, at, 0))
        self._seq_seen = seen
        seq = rank[-k:]
        created = np.full(k, int(step), dtype=np.int64)
        rows = self._rows_for(created, origin, seq, lim, pl, self._clock + lim)
        self._add_row = np.concatenate([self._add_row, rows])
        self._add_slot = np.concatenate([self._add_slot, origin])
        self._fr_row = np.concatenate([self._fr_row, rows])
        self._fr_slot = np.concatenate([self._fr_slot, origin])
        self._hops[rows] = 0
        self._started += k
        return np.column_stack([created, origin, seq])

    def frontier_of(self, slots: np.ndarray) -> FloodEntries:
        """The own frontier entries held by ``slots``: what a neighbour part needs for its ghosts among them."""
        sel = self._mask(slots)[self._fr_slot]
        rows = self._fr_row[sel]
        return self._entries(rows, self._fr_slot[sel], self._hops[rows])

    def take_leaving(self, slots: np.ndarray) -> FloodEntries:
        """Return the reads (and remove the frontier entries) of ``slots``, which move to another part.

        The reader lists are not rebuilt: the next ``hop`` drops the reads of slots no longer own (it keeps own
        readers only), and until then a slot's reads are a fact about that slot that stays true. ``drop``
        removes them.
        """
        leaving = self._mask(slots)
        p_row, p_slot = leaving_reads(self._rd_start, self._rd_len, self._pool, leaving)
        a = leaving[self._add_slot]
        # per row: the pool's reads, then the added ones in the order they were added (``split_reads``'s order)
        rows = np.concatenate([p_row, self._add_row[a]])
        out = np.concatenate([p_slot, self._add_slot[a]])
        order = np.argsort(rows, kind="stable")
        rows, out = rows[order], out[order]
        return self._entries(rows, out, self._take_frontier(leaving, rows, out))

    def _take_frontier(self, leaving: np.ndarray, rows: np.ndarray, out: np.ndarray) -> np.ndarray:
        # remove the frontier entries of the leaving slots; each read's hop count when it relays, else -1
        go = leaving[self._fr_slot]
        s = self.n_slots
        relays = np.isin(rows * s + out, self._fr_row[go] * s + self._fr_slot[go])
        self._fr_row, self._fr_slot = self._fr_row[~go], self._fr_slot[~go]
        return np.where(relays, self._hops[rows], -1)

    def add(self, entries: FloodEntries) -> None:
        """Reads (and frontier entries: ``hops >= 0``) of slots that joined this part (``take_leaving``'s)."""
        if not len(entries):
            return
        rows = self._rows_for(
            entries.created,
            entries.origin,
            entries.seq,
            entries.limit,
            entries.payload,
            self._clock + entries.left.astype(np.int64),
        )
        self._add_row = np.concatenate([self._add_row, rows])
        self._add_slot = np.concatenate([self._add_slot, entries.slot.astype(np.int64)])
        fr = entries.hops >= 0
        self._fr_row = np.concatenate([self._fr_row, rows[fr]])
        self._fr_slot = np.concatenate([self._fr_slot, entries.slot[fr].astype(np.int64)])
        self._hops[rows[fr]] = entries.hops[fr]

    def drop(self, slots: np.ndarray) -> None:
        """Forget the frontier entries and reads of ``slots`` (a world starting a new episode: all its slots).

        For a whole world this equals ``Overlay.drop_slots`` (no link crosses worlds, so the world's floods end
        and their readers are all in it); a flood key reused after the reset then starts afresh.
        """
        gone = self._mask(slots)
        add_start, add_len, add_v = self._adds()
        self._pool, self._rd_start, self._rd_len, rows, out = split_reads(
            self._rd_start, self._rd_len, self._pool, add_start, add_len, add_v, ~gone
        )
        self._pool_buf = None  # a new buffer, which no spare is
        self._add_row, self._add_slot = _e(), _e()
        self._take_frontier(gone, rows, out)

    def hop(
        self, links: tuple[np.ndarray, np.ndarray, np.ndarray], own: np.ndarray, ghost_frontier: FloodEntries
    ) -> FloodDeliveries:
        """Spread every flood one hop into the own slots (call on every part, every step).

        Args:
            links: The part's range graph ``(start, end, indices)`` over global slot ids, with every link between
                two of its known slots (own and ghosts), as ``RangeGraph.links`` builds it.
            own: ``(S,)`` bool, the own slots now (reads of slots no longer own are dropped: hand them over with
                ``take_leaving`` first).
            ghost_frontier: Frontier entries of ghost slots received from the neighbour parts (entries at own
                slots are ignored).

        Returns:
            The deliveries into own slots, grouped by flood in key order (see the module docstring).
        """
        own = np.ascontiguousarray(own, dtype=np.bool_)
        if own.shape != (self.n_slots,):
            raise ValueError(f"own must have shape ({self.n_slots},), got {own.shape}")
        self._clock += 1
        g = ghost_frontier
        gk = ~own[g.slot] if len(g) else np.zeros(0, dtype=bool)
        # a ghost's entry relays hop h + 1 now; the flood can spread until hop (now - 1) + left
        g_rows = self._rows_for(
            g.created[gk],
            g.origin[gk],
            g.seq[gk],
            g.limit[gk],
            g.payload[gk],
            self._clock - 1 + g.left[gk].astype(np.int64),
        )
        n = self._c.shape[0]
        rank = np.empty(n, dtype=np.int64)
        rank[np.lexsort((self._q, self._o, self._c))] = np.arange(n)
        e_row, e_slot, e_own, e_hops, relayed = order_entries(
            rank,
            n,
            self._fr_row,
            self._fr_slot,
            self._hops,
            g_rows,
            g.slot[gk].astype(np.int64),
            g.hops[gk].astype(np.int32),
        )
        start, end, indices = (np.ascontiguousarray(a, dtype=np.int64) for a in links)
        if e_row.shape[0] and (start.shape != (self.n_slots,) or end.shape != (self.n_slots,)):
            raise ValueError(
                f"links must be (start, end, indices) with start and end of shape ({self.n_slots},) when a flood "
                f"spreads, got {start.shape} and {end.shape}"
            )
        add_start, add_len, add_v = self._adds()
        spare, out_v, out_f, out_h = self._buffers()
        spare, npool, rd_start, rd_len, out_v, out_f, out_h, nd, row_h, edges, self._token = hop_kernel(
            start,
            end,
            indices,
            own,
            e_row,
            e_slot,
            e_own,
            e_hops,
            self._rd_start,
            self._rd_len,
            self._pool,
            add_start,
            add_len,
            add_v,
            self._stamp,
            self._token,
            spare,
            out_v,
            out_f,
            out_h,
        )
        # the old pool's buffer is the next hop's spare; the deliveries are copied out of the reused buffers
        old = self._pool if self._pool_buf is None else self._pool_buf
        self._scratch = (old if old.flags.writeable else _e(), out_v, out_f, out_h)
        self._pool_buf, self._pool, self._rd_start, self._rd_len = spare, spare[:npool], rd_start, rd_len
        self._add_row, self._add_slot = _e(), _e()
        out_f, out_h = out_f[:nd], out_h[:nd]
        out = FloodDeliveries(out_v[:nd].copy(), out_h.copy(), out_f.copy(), (self._o, self._c, self._pay, self._q))
        out_v = out.receiver
        done = row_h >= 0
        self._end[done] = self._clock + self._limit[done] - row_h[done]
        self._hops[done] = row_h[done]
        fr_row, fr_slot, has_fr = next_frontier(out_v, out_f, out_h, nd, self._limit)
        keys = self.keys()
        self._stats = PartHopStats(
            self._started,
            len(out),
            int(edges) - len(out),
            keys[relayed],
            keys[has_fr],
        )
        self._started = 0
        # forget the floods that cannot spread any more, or that no own slot read
        keep = (self._end > self._clock) & ((self._rd_len > 0) | has_fr)
        new_id = np.cumsum(keep) - 1
        self._fr_row, self._fr_slot = new_id[fr_row], fr_slot
        for name in ("_c", "_o", "_q", "_limit", "_pay", "_end", "_hops", "_rd_start", "_rd_len"):
            setattr(self, name, getattr(self, name)[keep])
        return out
