"""Peer-to-peer overlay network: range-limited multi-hop flooding (no bus).

A *flood* is one overlay message: its origin slot, a hop limit, the step it was created, a payload of ``D``
floats and the set of slots that already read it (a list per flood; see ``comms.flooding``). As in AgentSimJS, an agent
that receives a message checks whether its id is in the list of
readers: if not, it adds itself, keeps the message and re-sends it to the agents in range; if it is, the copy
is discarded (counted as a duplicate).

Each call of ``Overlay.advance`` moves every active flood ONE hop: every online slot joined by an edge of the
range graph to a slot of the flood's frontier (the slots that read it at the previous hop), and that has
not read it yet, reads it now with ``hops = frontier hops + 1`` and forms the next frontier. A flood stops
when its frontier is empty or its hop count reaches its hop limit, and its table row is recycled at once
(so a flood id is only meaningful while the flood is active, and in the deliveries of the call that ends
it). With ``full_propagation=True`` a flood runs to its hop limit within one call.

The range graph of a call has an edge ``(i, j)`` when both slots are online, in the same world, and
``dist(i, j) <= min(range_i, range_j)`` (a link needs both radios to reach). The candidate pairs come from
``core.spatial.neighbor_pairs`` built with ``max_dist`` at least the largest range; the exact test is redone
here, so pairs from a larger radius (e.g. the grid pairs shared with collisions) are fine. Offline slots have
no edges, so they neither read nor relay.

Cost per call: O(S + E) to build a CSR adjacency of the range graph (``advance``; the comms stack passes its
own, see ``advance_graph``), then work proportional to the edges touched by the frontiers and the readers of
the floods that spread (never a scan over floods x slots). Memory: the readers of the active floods, and a
table of floods that doubles when full.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from agentsim_env.comms.flood_threads import flood_ranges, hop_cost, spread_threads
from agentsim_env.comms.flooding import spread, spread_hop
from agentsim_env.comms.rangegraph import _links_from_pairs
from agentsim_env.core.threads import RowThreads

_NO_ROWS = np.zeros(0, dtype=np.int64)  # Inbox.push_rows: delivery j takes payload row j


class Deliveries:
    """Overlay messages read during one ``advance`` call, one row per (receiver, flood). Read-only.

    Attributes:
        receiver: Slot that read the message ``(k,)`` int64.
        flood: Flood id (table row) ``(k,)`` int64; recycled once the flood ends.
        origin: Slot that started the flood ``(k,)`` int64.
        hops: Hops from the origin to the receiver ``(k,)`` int32 (>= 1).
        created: Step the flood was started ``(k,)`` int64.
        payload: Message payload ``(k, D)`` float32 (a fresh array).

    The overlay hands out ``origin``, ``created`` and ``payload`` as its flood table's rows, looked up by
    ``flood`` when first read (a step's deliveries are mostly counted and pushed, not read: 1.4M rows and
    ~45 MB a step at 100,000 agents). Before its table changes (the next floods started) the overlay hands the
    deliveries it has not yet read a copy of the rows they need, so the values never change.
    """

    __slots__ = (
        "receiver",
        "flood",
        "hops",
        "_origin",
        "_created",
        "_payload",
        "_table",
        "_rows",
        "__weakref__",
    )
    receiver: np.ndarray
    flood: np.ndarray
    hops: np.ndarray
    _origin: np.ndarray | None
    _created: np.ndarray | None
    _payload: np.ndarray | None
    _table: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    _rows: np.ndarray | None

    def __init__(
        self,
        receiver: np.ndarray,
        flood: np.ndarray,
        origin: np.ndarray,
        hops: np.ndarray,
        created: np.ndarray,
        payload: np.ndarray,
    ) -> None:
        for name, value in (
            ("receiver", receiver),
            ("flood", flood),
            ("hops", hops),
            ("_origin", origin),
            ("_created", created),
            ("_payload", payload),
            ("_table", None),
            ("_rows", None),
        ):
            object.__setattr__(self, name, value)

    @classmethod
    def by_flood(
        cls,
        receiver: np.ndarray,
        flood: np.ndarray,
        hops: np.ndarray,
        table: tuple[np.ndarray, np.ndarray, np.ndarray],
        rows: np.ndarray | None = None,
    ) -> Deliveries:
        """Deliveries whose ``origin``, ``created`` and ``payload`` are ``table``'s rows (``(origin, created,
        payload)`` columns of a flood table), looked up when read: rows ``rows``, or ``flood`` when None. The
        caller keeps the table's rows unchanged, or calls :meth:`keep_rows` before it changes them."""
        out = cls(receiver, flood, None, hops, None, None)  # type: ignore[arg-type]
        object.__setattr__(out, "_table", table)
        object.__setattr__(out, "_rows", flood if rows is None else rows)
        return out

    def _column(self, name: str, i: int) -> np.ndarray:
        value = getattr(self, name)
        if value is None:
            assert self._table is not None and self._rows is not None
            value = np.take(self._table[i], self._rows, axis=0)  # rows: much faster than fancy indexing
            object.__setattr__(self, name, value)
        return value  # type: ignore[no-any-return]

    def push_columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
        """``(sender, created, payload, rows, by_rows)`` for an ``Inbox.push_batches`` batch: the table's columns
        and the rows (read by the push from a few cache-resident rows) while they are looked up on reading, else
        the columns themselves."""
        if self._table is not None and self._rows is not None:
            return self._table[0], self._table[1], self._table[2], self._rows, True
        return self.origin, self.created, self.payload, _NO_ROWS, False

    @property
    def origin(self) -> np.ndarray:
        """Slot that started the flood ``(k,)`` int64."""
        return self._column("_origin", 0)

    @property
    def created(self) -> np.ndarray:
        """Step the flood was started ``(k,)`` int64."""
        return self._column("_created", 1)

    @property
    def payload(self) -> np.ndarray:
        """Message payload ``(k, D)`` float32."""
        return self._column("_payload", 2)

    def keep_rows(self) -> None:
        """Take what is still to be looked up out of the flood table, which is about to change: the rows
        themselves for a few deliveries, else a copy of the table."""
        t = self._table
        if t is None or (self._origin is not None and self._created is not None and self._payload is not None):
            return
        if 2 * len(self) < t[0].shape[0]:
            self.origin, self.created, self.payload  # noqa: B018  (looked up now)
        else:
            object.__setattr__(self, "_table", tuple(a.copy() for a in t))

    def __len__(self) -> int:
        """Number of deliveries."""
        return int(self.receiver.shape[0])

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"Deliveries is read-only (cannot set {name!r})")

    def __getstate__(self) -> dict[str, np.ndarray]:
        """Pickle every column (looked up now)."""
        return {
            "receiver": self.receiver,
            "flood": self.flood,
            "origin": self.origin,
            "hops": self.hops,
            "created": self.created,
            "payload": self.payload,
        }

    def __setstate__(self, state: dict[str, np.ndarray]) -> None:
        """Restore a pickled state."""
        self.__init__(**state)  # type: ignore[misc]

    def __repr__(self) -> str:
        return f"Deliveries({len(self)} rows)"


@dataclass(slots=True, frozen=True)
class OverlayStats:
    """Counters of one ``advance`` call (or running totals).

    Attributes:
        started: Floods started since the previous ``advance``.
        delivered: Messages read (new readers).
        duplicates: Copies that reached a slot which had already read the flood, and were dropped.
        finished: Floods that ended (empty frontier or hop limit) and were recycled.
    """

    started: int = 0
    delivered: int = 0
    duplicates: int = 0
    finished: int = 0

    def __add__(self, other: OverlayStats) -> OverlayStats:
        """Field-wise sum."""
        return OverlayStats(
            self.started + other.started,
            self.delivered + other.delivered,
            self.duplicates + other.duplicates,
            self.finished + other.finished,
        )


def _new_scratch(n_slots: int) -> tuple:
    # Kernel state reused across calls: the stamp array and its last token, the spare reader pool, and the
    # delivery buffers (receiver, flood, hops); fresh multi-megabyte buffers each step would cost more in
    # page faults than the flooding itself.
    e = np.empty(0, dtype=np.int64)
    return np.zeros(n_slots, dtype=np.int32), 0, e, e.copy(), e.copy(), np.empty(0, dtype=np.int32)


def check_flood_starts(
    origin: np.ndarray,
    hop_limit: np.ndarray | int,
    payload: np.ndarray | None,
    n_slots: int,
    payload_dim: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arguments of a flood start checked and in kernel form: origins ``(k,)`` int64, hop limits ``(k,)``
    int64, payloads ``(k, D)`` float32 (zeros for ``None``; one ``(D,)`` row for all).

    Raises:
        ValueError: An origin outside ``[0, n_slots)``, a hop limit < 1, or a payload of another shape.
    """
    origin = np.asarray(origin, dtype=np.int64).reshape(-1)
    k = origin.shape[0]
    if k and (origin.min() < 0 or origin.max() >= n_slots):
        raise ValueError(f"origin must be slots in [0, {n_slots}), got {origin.min()}..{origin.max()}")
    lim = np.broadcast_to(np.asarray(hop_limit, dtype=np.int64), (k,))
    if k and lim.min() < 1:
        raise ValueError(f"hop_limit must be >= 1, got min {lim.min()}")
    if payload is None:
        return origin, lim, np.zeros((k, payload_dim), dtype=np.float32)
    pl = np.asarray(payload, dtype=np.float32)
    if pl.ndim == 1 and pl.shape == (payload_dim,):
        pl = np.broadcast_to(pl, (k, payload_dim))
    if pl.shape != (k, payload_dim):
        raise ValueError(f"payload must have shape ({k}, {payload_dim}), got {pl.shape}")
    return origin, lim, pl


class Overlay:
    """Flooding over the range graph of online agents, one hop per step.

    Args:
        n_slots: Number of agent slots S (>= 1).
        payload_dim: Payload width D (>= 0).
        comm_range: Transmission range in metres, a scalar or one per slot ``(S,)`` (finite, >= 0). An edge
            ``(i, j)`` exists when ``dist <= min(range_i, range_j)``.
        full_propagation: If True, every flood spreads up to its hop limit within one ``advance`` call.
        capacity: Initial number of flood rows (>= 1); doubles when full.

    The object holds plain numpy arrays only, so it pickles and deep-copies.
    """

    __slots__ = (
        "n_slots",
        "payload_dim",
        "full_propagation",
        "_range",
        "_rd_start",
        "_rd_len",
        "_pool",
        "_n_pool",
        "_origin",
        "_limit",
        "_hops",
        "_created",
        "_payload",
        "_active",
        "_free",
        "_n_free",
        "_front_f",
        "_front_n",
        "_pending_started",
        "_last",
        "_totals",
        "_scratch",
        "_tscratch",
        "threads",
        "_unread",
    )

    def __init__(
        self,
        n_slots: int,
        payload_dim: int,
        comm_range: float | np.ndarray,
        full_propagation: bool = False,
        capacity: int = 1024,
    ) -> None:
        if int(n_slots) < 1:
            raise ValueError(f"n_slots must be >= 1, got {n_slots}")
        if int(payload_dim) < 0:
            raise ValueError(f"payload_dim must be >= 0, got {payload_dim}")
        if int(capacity) < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.n_slots = int(n_slots)
        self.payload_dim = int(payload_dim)
        self.full_propagation = bool(full_propagation)
        self._range = np.zeros(self.n_slots)
        self.set_range(comm_range)
        self._alloc(int(capacity))
        self._scratch = _new_scratch(self.n_slots)
        self._tscratch: list[list[Any]] = []  # per range of a hop on threads (``comms.flood_threads``)
        # deliveries still alive that read the flood table when asked (the caller's, or the stack's events)
        self._unread: weakref.WeakSet[Deliveries] = weakref.WeakSet()
        self.threads = RowThreads(1)
        """Threads of a one-hop spread (whole floods per thread); results do not depend on them."""

    def __getstate__(self) -> dict:
        """Pickle the state without the kernel scratch buffers."""
        return {k: getattr(self, k) for k in self.__slots__ if k not in ("_scratch", "_tscratch", "_unread")}

    def __setstate__(self, state: dict) -> None:
        """Restore a pickled state."""
        for k, v in state.items():
            setattr(self, k, v)
        self._scratch = _new_scratch(self.n_slots)
        self._tscratch = []
        self._unread = weakref.WeakSet()
        if "threads" not in state:
            self.threads = RowThreads(1)

    # ------------------------------------------------------------------ state
    def _alloc(self, cap: int) -> None:
        # flood f has been read by _pool[_rd_start[f] : _rd_start[f] + _rd_len[f]]
        self._rd_start = np.zeros(cap, dtype=np.int64)
        self._rd_len = np.zeros(cap, dtype=np.int64)
        self._pool = np.empty(0, dtype=np.int64)
        self._n_pool = 0
        self._origin = np.full(cap, -1, dtype=np.int64)
        self._limit = np.zeros(cap, dtype=np.int32)
        self._hops = np.zeros(cap, dtype=np.int32)
        self._created = np.zeros(cap, dtype=np.int64)
        self._payload = np.zeros((cap, self.payload_dim), dtype=np.float32)
        self._active = np.zeros(cap, dtype=bool)
        # LIFO free list; reversed so that a fresh table hands out ids 0, 1, 2, ...
        self._free = np.arange(cap - 1, -1, -1, dtype=np.int64)
        self._n_free = cap
        self._front_f = np.empty(0, dtype=np.int64)
        self._front_n = np.empty(0, dtype=np.int64)
        self._pending_started = 0
        self._last = OverlayStats()
        self._totals = OverlayStats()

    def _grow(self, need: int) -> None:
        old = self.capacity
        cap = old
        while cap - old + self._n_free < need:
            cap *= 2
        for name in ("_rd_start", "_rd_len", "_origin", "_limit", "_hops", "_created", "_payload", "_active"):
            a = getattr(self, name)
            pad = np.full((cap - old,) + a.shape[1:], -1 if name == "_origin" else 0, dtype=a.dtype)
            setattr(self, name, np.concatenate([a, pad]))
        # The free stack always has room for every row; new rows sit below the old free ids (popped after
        # them) in descending order, so they are handed out lowest id first.
        free = np.empty(cap, dtype=np.int64)
        free[: cap - old] = np.arange(cap - 1, old - 1, -1, dtype=np.int64)
        free[cap - old : cap - old + self._n_free] = self._free[: self._n_free]
        self._free = free
        self._n_free += cap - old

    @property
    def capacity(self) -> int:
        """Number of flood rows currently allocated."""
        return int(self._active.shape[0])

    @property
    def active_count(self) -> int:
        """Number of floods still spreading."""
        return self.capacity - self._n_free

    @property
    def stats(self) -> OverlayStats:
        """Counters of the last ``advance`` call (``started`` counts floods started since the one before)."""
        return self._last

    @property
    def totals(self) -> OverlayStats:
        """Counters summed over every ``advance`` since construction or ``reset``."""
        return self._totals

    @property
    def frontier_size(self) -> int:
        """(flood, slot) entries that relay at the next ``advance`` (0: that call has nothing to spread)."""
        return int(self._front_f.shape[0])

    @property
    def link_range(self) -> np.ndarray:
        """Per-slot transmission range ``(S,)``: the internal array, for building range graphs (do not write)."""
        return self._range

    @property
    def comm_range(self) -> np.ndarray:
        """Per-slot transmission range ``(S,)`` (a copy)."""
        return self._range.copy()

    @property
    def max_range(self) -> float:
        """The largest per-slot transmission range: how far the pairs given to ``advance`` must reach."""
        return float(self._range.max())

    def set_range(self, comm_range: float | np.ndarray) -> None:
        """Set the transmission range: a scalar for every slot or one per slot ``(S,)``, finite and >= 0.

        A range may exceed the one the overlay was created with. Links then need candidates from as far: the
        comms stack's ``RangeGraph`` scans the step's grid as far as the largest current range (``link_range``),
        and the pairs given to ``advance`` must come from ``neighbor_pairs`` with ``max_dist >= max_range``.
        """
        r = np.asarray(comm_range, dtype=np.float64)
        if r.ndim == 0:
            r = np.full(self.n_slots, float(r))
        if r.shape != (self.n_slots,):
            raise ValueError(f"comm_range must be a scalar or shape ({self.n_slots},), got shape {r.shape}")
        if not np.all(np.isfinite(r)) or np.any(r < 0):
            raise ValueError("comm_range must be finite and >= 0")
        self._range = r.copy()

    def reset(self) -> None:
        """Drop every flood and zero the counters (the grown capacity is kept)."""
        self._alloc(self.capacity)

    def drop_slots(self, slots: np.ndarray) -> None:
        """Stop relaying at ``slots`` (e.g. a world being reset): frontier entries there are removed.

        A flood's frontier lies in its origin's world, so dropping a whole world's slots ends its floods here
        (their rows go back to the free list, so resets never accumulate dead floods); readers elsewhere are
        untouched.
        """
        if self._front_n.size:
            keep = ~np.isin(self._front_n, np.asarray(slots, dtype=np.int64))
            if keep.all():
                return
            hit = np.unique(self._front_f[~keep])
            self._front_f, self._front_n = self._front_f[keep], self._front_n[keep]
            # a flood left without any frontier entry can never spread again: end it now (its row is reused)
            ended = hit[~np.isin(hit, self._front_f)]
            if ended.size:
                self._active[ended] = False
                self._free[self._n_free : self._n_free + ended.size] = ended[::-1]
                self._n_free += ended.size

    def is_active(self, flood: int) -> bool:
        """Whether flood id ``flood`` is still spreading."""
        return 0 <= int(flood) < self.capacity and bool(self._active[int(flood)])

    def readers(self, flood: int) -> np.ndarray:
        """Slots that have read an active flood (origin included), ascending.

        Raises:
            ValueError: If ``flood`` is not an active flood id.
        """
        if not self.is_active(flood):
            raise ValueError(f"flood must be an active flood id, got {flood}")
        f = int(flood)
        return np.sort(self._pool[self._rd_start[f] : self._rd_start[f] + self._rd_len[f]])

    # ------------------------------------------------------------------ API
    def start(
        self,
        origin: np.ndarray,
        hop_limit: np.ndarray | int,
        payload: np.ndarray | None,
        step: int,
    ) -> np.ndarray:
        """Start one flood per origin; the origin has read its own message (hops 0).

        Args:
            origin: Origin slots ``(k,)`` in ``[0, S)``.
            hop_limit: Hop limit per flood ``(k,)`` or a scalar, >= 1.
            payload: Payloads ``(k, D)`` (or ``(D,)`` for all); None means zeros.
            step: Current step, recorded as the floods' created step.

        Returns:
            The new flood ids ``(k,)`` int64.
        """
        origin, lim, pl = check_flood_starts(origin, hop_limit, payload, self.n_slots, self.payload_dim)
        k = origin.shape[0]
        if k == 0:
            return np.empty(0, dtype=np.int64)
        for d in list(self._unread):  # the table's rows are about to change: deliveries still alive keep theirs
            d.keep_rows()
        self._unread.clear()
        if self._n_free < k:
            self._grow(k)
        ids = self._free[self._n_free - k : self._n_free][::-1].copy()
        self._n_free -= k
        if self._n_pool + k > self._pool.shape[0]:
            pool = np.empty(max(2 * self._pool.shape[0], self._n_pool + k, 64), dtype=np.int64)
            pool[: self._n_pool] = self._pool[: self._n_pool]
            self._pool = pool
        self._pool[self._n_pool : self._n_pool + k] = origin
        self._rd_start[ids] = np.arange(self._n_pool, self._n_pool + k)
        self._rd_len[ids] = 1
        self._n_pool += k
        self._origin[ids] = origin
        self._limit[ids] = lim
        self._hops[ids] = 0
        self._created[ids] = int(step)
        self._payload[ids] = pl
        self._active[ids] = True
        # One frontier entry per new flood keeps the frontier grouped by flood.
        self._front_f = np.concatenate([self._front_f, ids])
        self._front_n = np.concatenate([self._front_n, origin])
        self._pending_started += k
        return ids

    def advance(
        self,
        pos: np.ndarray,
        online: np.ndarray,
        world: np.ndarray,
        pairs: tuple[np.ndarray, ...],
        step: int,
    ) -> Deliveries:
        """Spread every active flood one hop (to its hop limit with ``full_propagation``).

        Args:
            pos: Positions ``(S, 3)``.
            online: Online flags ``(S,)``; offline slots neither read nor relay.
            world: World id per slot ``(S,)``; no edge crosses worlds.
            pairs: ``(i, j)`` or ``(i, j, d)`` from ``neighbor_pairs`` with ``max_dist`` >= the largest range;
                distances are re-checked against ``min(range_i, range_j)``.
            step: Current step (deliveries carry each flood's created step; the age is ``step - created``).

        Returns:
            The messages read during this call.
        """
        s = self.n_slots
        pos = np.ascontiguousarray(pos)
        if pos.shape != (s, 3):
            raise ValueError(f"pos must have shape ({s}, 3), got {pos.shape}")
        online = np.ascontiguousarray(online, dtype=np.bool_)
        world = np.ascontiguousarray(world, dtype=np.int64)
        if online.shape != (s,) or world.shape != (s,):
            raise ValueError(f"online and world must have shape ({s},), got {online.shape} and {world.shape}")
        if len(pairs) < 2:
            raise ValueError("pairs must be (i, j) or (i, j, d)")
        pi = np.ascontiguousarray(pairs[0], dtype=np.int64)
        pj = np.ascontiguousarray(pairs[1], dtype=np.int64)
        if pi.shape != pj.shape or pi.ndim != 1:
            raise ValueError(f"pairs i and j must be 1-D of equal length, got {pi.shape} and {pj.shape}")
        if pi.size and (min(pi.min(), pj.min()) < 0 or max(pi.max(), pj.max()) >= s):
            raise ValueError(f"pairs must hold slots in [0, {s})")
        if self._front_f.shape[0]:
            indptr, indices = _links_from_pairs(pi, pj, pos, online, world, self._range, s)
        else:  # nothing to spread: skip the adjacency
            indptr, indices = np.zeros(s + 1, dtype=np.int64), np.empty(0, dtype=np.int64)
        return self.advance_graph(indptr[:-1], indptr[1:], indices)

    def advance_graph(self, start: np.ndarray, end: np.ndarray, indices: np.ndarray) -> Deliveries:
        """``advance`` over a prebuilt range graph (unchecked; the comms stack builds one per step).

        Args:
            start: ``(S,)`` int64 row starts: slot ``s`` links to ``indices[start[s]:end[s]]``.
            end: ``(S,)`` int64 row ends.
            indices: Linked slots, int64; the links must follow the rule of ``advance`` (online, same world,
                ``dist <= min(range_i, range_j)``), in the row order that ``advance`` would build.

        Returns:
            The messages read during this call.
        """
        started = self._pending_started
        self._pending_started = 0
        stamp, token, spare, out_r, out_f, out_h = self._scratch
        ranges: list[tuple[int, int]] = []
        if not self.full_propagation and len(self.threads.ranges(self._front_f.shape[0])) > 1:
            # whole floods per range, ranges of equal estimated work
            cost = hop_cost(self._front_f, self._front_n, start, end, self._hops, self._limit)
            ranges = flood_ranges(self._front_f, self.threads, cost)
        if len(ranges) > 1:  # whole floods per thread, joined in the one-thread order
            nf, nn, fin, dups, n_pool, pool, (r, fl, h) = spread_threads(
                start,
                end,
                indices,
                self._hops,
                self._limit,
                self._active,
                self._rd_start,
                self._rd_len,
                self._pool,
                self._front_f,
                self._front_n,
                self.threads,
                ranges,
                self._tscratch,
                spare,
            )
            self._scratch = (stamp, token, self._pool, *self._scratch[3:])
            out = Deliveries.by_flood(r, fl, h, (self._origin, self._created, self._payload))
        else:
            if self.full_propagation:
                nf, nn, nd, fin, dups, token, n_pool, pool, out_r, out_f, out_h = spread(
                    start,
                    end,
                    indices,
                    self._hops,
                    self._limit,
                    self._active,
                    self._rd_start,
                    self._rd_len,
                    self._pool,
                    self._front_f,
                    self._front_n,
                    True,
                    stamp,
                    token,
                    spare,
                    out_r,
                    out_f,
                    out_h,
                )
            else:
                nf, nn, nd, fin, dups, token, n_pool, pool, out_r, out_f, out_h = spread_hop(
                    start,
                    end,
                    indices,
                    self._hops,
                    self._limit,
                    self._active,
                    self._rd_start,
                    self._rd_len,
                    self._pool,
                    self._front_f,
                    self._front_n,
                    stamp,
                    token,
                    spare,
                    out_r,
                    out_f,
                    out_h,
                )
            self._scratch = (stamp, token, self._pool, out_r, out_f, out_h)  # the old pool is the next spare
            out = Deliveries.by_flood(
                out_r[:nd].copy(),
                out_f[:nd].copy(),
                out_h[:nd].copy(),
                (self._origin, self._created, self._payload),
            )
        self._unread.add(out)
        self._pool, self._n_pool = pool, n_pool
        self._front_f, self._front_n = nf, nn
        if fin.shape[0]:
            self._active[fin] = False
            self._free[self._n_free : self._n_free + fin.shape[0]] = fin[::-1]
            self._n_free += fin.shape[0]
        self._last = OverlayStats(started, len(out), int(dups), int(fin.shape[0]))
        self._totals = self._totals + self._last
        return out
