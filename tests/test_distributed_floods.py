"""Per-part overlay floods (``distributed.floods``) against the single-process overlay (hypothesis).

Parts are K strips with a halo of at least the link range; each part sees only its own slots and its ghosts
(its range graph has no other slot), slots move between hops and change part with their reads. Per hop the
union of the parts' deliveries equals ``Overlay``'s, each receiver gets them in the same order, and the parts'
counters combine to ``Overlay.stats`` and ``Overlay.active_count``.
"""

from __future__ import annotations

import pickle
from collections import defaultdict

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.comms.overlay import Overlay
from agentsim_env.comms.rangegraph import _links_from_pairs
from agentsim_env.distributed.floods import FloodDeliveries, FloodEntries, PartFloods, combine_stats
from agentsim_env.distributed.partition import Strips

D = 2
HALO = 12.0


def _links(pos: np.ndarray, online: np.ndarray, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The range graph over the slots flagged in ``online`` (a part's known slots: own and ghosts)."""
    s = pos.shape[0]
    i, j = np.triu_indices(s, 1)
    indptr, idx = _links_from_pairs(
        i.astype(np.int64), j.astype(np.int64), pos, online, np.zeros(s, dtype=np.int64), reach, s
    )
    return indptr[:-1], indptr[1:], idx


class _Run:
    """One process and K parts fed the same floods, positions and hand-overs."""

    def __init__(self, rng: np.random.Generator, n: int, k: int) -> None:
        self.rng, self.n, self.k = rng, n, k
        self.side = max(60.0, k * HALO)
        self.strips = Strips.build((0.0, self.side, 0.0, 60.0), k, HALO)
        self.pos = np.column_stack([rng.uniform(0, self.side, n), rng.uniform(0, 60, n), np.zeros(n)])
        self.reach = rng.uniform(4.0, HALO, n)  # the halo covers the largest link range
        self.ref = Overlay(n, D, self.reach)
        self.parts = [PartFloods(n, D) for _ in range(k)]
        self.owner = self.strips.owner_of(self.pos[:, 0])
        self.kept: list[tuple[FloodDeliveries, list[tuple]]] = []  # deliveries read later, and what they read
        self.keys: dict[int, tuple[int, int, int]] = {}  # the reference's flood id -> key

    def start(self, step: int, count: int) -> None:
        origins = np.sort(self.rng.integers(0, self.n, count))  # ascending, repeats allowed (seq > 0)
        limits = self.rng.integers(1, 5, count)
        payload = self.rng.uniform(-1, 1, (count, D)).astype(np.float32)
        ids = self.ref.start(origins, limits, payload, step)
        seq: dict[int, int] = defaultdict(int)
        for f, o in zip(ids.tolist(), origins.tolist(), strict=True):
            self.keys[f] = (step, o, seq[o])
            seq[o] += 1
        for p, part in enumerate(self.parts):
            mine = self.owner[origins] == p
            keys = part.start(origins[mine], limits[mine], payload[mine], step)
            assert [tuple(x) for x in keys.tolist()] == [self.keys[f] for f in ids[mine].tolist()], (
                "a flood's key does not depend on the part that starts it"
            )

    def move(self, sigma: float) -> None:
        """Slots move; those that cross into another strip are handed over with their reads."""
        self.pos[:, :2] += self.rng.normal(0.0, sigma, (self.n, 2))
        self.pos[:, 0] = np.clip(self.pos[:, 0], 0.0, self.side)
        new = self.strips.owner_of(self.pos[:, 0])
        moved = [part.take_leaving(np.flatnonzero((self.owner == p) & (new != p))) for p, part in enumerate(self.parts)]
        for p, part in enumerate(self.parts):
            part.add(FloodEntries.concat([_where(e, new[e.slot] == p) for e in moved], D))
        self.owner = new

    def hop(self, online: np.ndarray) -> None:
        """One hop everywhere; the parts' deliveries, order and counters against the reference."""
        slots = np.arange(self.n)
        a = self.ref.advance_graph(*_links(self.pos, online, self.reach))
        ghosts = [self.strips.ghosts(self.pos[:, 0], slots, p) for p in range(self.k)]
        # the exchange before the hop: each part's frontier entries at its neighbours' ghosts
        received = [
            FloodEntries.concat([q.frontier_of(g[self.owner[g] == i]) for i, q in enumerate(self.parts) if i != p], D)
            for p, g in enumerate(ghosts)
        ]
        got = []
        for p, part in enumerate(self.parts):
            own = self.owner == p
            known = own.copy()
            known[ghosts[p]] = True
            d = part.hop(_links(self.pos, online & known, self.reach), own, received[p])
            assert own[d.receiver].all()
            unread = FloodDeliveries(d.receiver, d.hops, d.rows, d.table)  # its columns read only at the end
            rows = _rows(d)
            got += rows
            self.kept.append((unread, rows))
        want = [
            (r, *self.keys[f], h, tuple(pl))
            for r, f, h, pl in zip(a.receiver.tolist(), a.flood.tolist(), a.hops.tolist(), a.payload.tolist())
        ]
        assert sorted(got) == sorted(want)
        per_got, per_want = defaultdict(list), defaultdict(list)
        for x in got:
            per_got[x[0]].append(x[1:4])
        for x in want:
            per_want[x[0]].append(x[1:4])
        assert per_got == per_want, "a receiver gets the floods in another order"
        stats, active = combine_stats([part.stats for part in self.parts])
        assert stats == self.ref.stats
        assert active == self.ref.active_count


def _rows(d) -> list[tuple]:  # type: ignore[no-untyped-def]
    return list(
        zip(
            d.receiver.tolist(),
            d.created.tolist(),
            d.origin.tolist(),
            d.seq.tolist(),
            d.hops.tolist(),
            map(tuple, d.payload.tolist()),
        )
    )


def _where(e: FloodEntries, sel: np.ndarray) -> FloodEntries:
    return FloodEntries(
        e.slot[sel],
        e.created[sel],
        e.origin[sel],
        e.seq[sel],
        e.hops[sel],
        e.limit[sel],
        e.left[sel],
        e.payload[sel],
    )


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(3, 60),
    k=st.integers(1, 4),
    steps=st.integers(1, 8),
    sigma=st.floats(0.0, 8.0),
)
def test_part_floods_hop_like_one_overlay(seed: int, n: int, k: int, steps: int, sigma: float) -> None:
    rng = np.random.default_rng(seed)
    run = _Run(rng, n, k)
    for step in range(steps + 4):  # a few hops without new floods: the old ones run out
        if step < steps:
            run.start(step, int(rng.integers(0, 5)))
        run.move(sigma)
        run.hop(rng.random(n) >= 0.1)
    # deliveries read after later starts, hand-overs and hops (which replace a part's columns) read the same
    for unread, rows in run.kept:
        assert _rows(unread) == rows


def test_part_forgets_floods_after_their_hop_limit() -> None:
    rng = np.random.default_rng(3)
    run = _Run(rng, 50, 3)
    for step in range(6):
        run.start(step, 6)  # hop limits <= 4
        run.move(3.0)
        run.hop(np.ones(50, dtype=bool))
    assert sum(p.n_floods for p in run.parts) > 0
    for _ in range(4):
        run.move(3.0)
        run.hop(np.ones(50, dtype=bool))
    assert [(p.n_floods, p.n_reads, p.frontier_size) for p in run.parts] == [(0, 0, 0)] * 3
    assert run.ref.active_count == 0


def test_pickled_part_continues_identically() -> None:
    rng = np.random.default_rng(5)
    run = _Run(rng, 40, 2)
    for step in range(3):
        run.start(step, 4)
        run.move(2.0)
        run.hop(np.ones(40, dtype=bool))
    run.parts = [pickle.loads(pickle.dumps(p)) for p in run.parts]
    for _ in range(3):
        run.move(2.0)
        run.hop(np.ones(40, dtype=bool))


def test_dropped_world_slots_start_afresh() -> None:
    links = _links(
        np.column_stack([np.arange(4) * 5.0, np.zeros(4), np.zeros(4)]),
        np.ones(4, dtype=bool),
        np.full(4, 6.0),
    )
    own = np.ones(4, dtype=bool)
    part = PartFloods(4, 0)
    part.start(np.array([0]), 3, None, 0)
    assert part.hop(links, own, FloodEntries.empty(0)).receiver.tolist() == [1]
    part.drop(np.arange(4))  # the world starts a new episode
    assert (part.frontier_size, part.n_reads) == (0, 0)
    assert len(part.hop(links, own, FloodEntries.empty(0))) == 0
    part.start(np.array([0]), 3, None, 0)  # the same key again: nobody has read it
    assert part.hop(links, own, FloodEntries.empty(0)).receiver.tolist() == [1]


def test_bad_arguments_name_the_field() -> None:
    part = PartFloods(4, 1)
    no_links = (np.zeros(0, np.int64),) * 3
    with pytest.raises(ValueError, match="origin"):
        part.start(np.array([4]), 1, None, 0)
    with pytest.raises(ValueError, match="hop_limit"):
        part.start(np.array([0]), 0, None, 0)
    with pytest.raises(ValueError, match="payload"):
        part.start(np.array([0]), 1, np.zeros((1, 2)), 0)
    with pytest.raises(ValueError, match="own"):
        part.hop(no_links, np.ones(3, bool), FloodEntries.empty(1))
    with pytest.raises(ValueError, match="n_slots"):
        PartFloods(0, 1)
    part.start(np.array([0]), 1, None, 0)
    with pytest.raises(ValueError, match="links"):  # a flood to spread needs the range graph
        part.hop(no_links, np.ones(4, bool), FloodEntries.empty(1))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rows=st.integers(0, 9), n_own=st.integers(0, 30), n_ghost=st.integers(0, 30))
def test_hop_entry_and_frontier_kernels_equal_their_numpy_forms(seed: int, rows: int, n_own: int, n_ghost: int) -> None:
    """``order_entries`` is the stable sort by row rank of the own entries followed by the ghosts' ones, and
    ``next_frontier`` keeps the deliveries below their row's hop limit (each against its plain numpy form)."""
    from agentsim_env.distributed.flood_kernels import next_frontier, order_entries

    rng = np.random.default_rng(seed)
    rows = max(rows, 1)
    rank = rng.permutation(rows).astype(np.int64)
    fr_row, g_row = rng.integers(0, rows, n_own), rng.integers(0, rows, n_ghost)
    fr_slot, g_slot = rng.integers(0, 50, n_own), rng.integers(0, 50, n_ghost)
    hops = rng.integers(0, 4, rows).astype(np.int32)
    g_hops = rng.integers(0, 4, n_ghost).astype(np.int32)
    e_row, e_slot, e_own, e_hops, relayed = order_entries(rank, rows, fr_row, fr_slot, hops, g_row, g_slot, g_hops)
    all_row = np.concatenate([fr_row, g_row])
    order = np.argsort(rank[all_row], kind="stable")
    np.testing.assert_array_equal(e_row, all_row[order])
    np.testing.assert_array_equal(e_slot, np.concatenate([fr_slot, g_slot])[order])
    np.testing.assert_array_equal(e_own, np.concatenate([np.ones(n_own, bool), np.zeros(n_ghost, bool)])[order])
    np.testing.assert_array_equal(e_hops, np.concatenate([hops[fr_row], g_hops])[order])
    np.testing.assert_array_equal(relayed, np.bincount(fr_row, minlength=rows) > 0)

    nd = int(rng.integers(0, 40))
    out_f = np.sort(rng.integers(0, rows, nd + 5))  # buffers longer than the deliveries, grouped by row
    out_v = rng.integers(0, 50, nd + 5)
    out_h = rng.integers(1, 5, nd + 5).astype(np.int32)
    limit = rng.integers(1, 5, rows).astype(np.int32)
    f_row, f_slot, has_fr = next_frontier(out_v, out_f, out_h, nd, limit)
    goes = out_h[:nd] < limit[out_f[:nd]]
    np.testing.assert_array_equal(f_row, out_f[:nd][goes])
    np.testing.assert_array_equal(f_slot, out_v[:nd][goes])
    np.testing.assert_array_equal(has_fr, np.bincount(out_f[:nd][goes], minlength=rows) > 0)
