"""Properties of the pieces that make a sharded run equal one process (hypothesis).

- The halo: every agent within the halo (in x) of a shard's own agent, and owned elsewhere, is its ghost.
- The sharded flood hop (``distributed.flooding``) against the single-process overlay: the same deliveries (as a
  set per hop), the same counters and the same frontier, for any assignment of slots to shards, including slots that
  move to another shard between hops with their reads.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.comms.overlay import Overlay
from agentsim_env.comms.rangegraph import _links_from_pairs
from agentsim_env.distributed.flooding import ShardedOverlay, ShardReaders
from agentsim_env.distributed.partition import Strips


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(2, 80),
    k=st.integers(1, 6),
    halo=st.floats(0.5, 15.0),
)
def test_every_agent_within_the_halo_of_an_own_agent_is_a_ghost(seed: int, n: int, k: int, halo: float) -> None:
    side = max(100.0, k * halo)
    strips = Strips.build((0.0, side, 0.0, side), k, halo)
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, side, n)
    x[: n // 4] = strips.edges[rng.integers(0, k + 1, n // 4)]  # some exactly on an edge
    slots = np.arange(n)
    owner = strips.owner_of(x)
    for shard in range(k):
        ghosts = set(strips.ghosts(x, slots, shard).tolist())
        mine = slots[owner == shard]
        assert not ghosts & set(mine.tolist())
        for j in slots[owner != shard]:
            if mine.size and np.abs(x[mine] - x[j]).min() <= halo:
                assert j in ghosts, (shard, j)


def _csr(pos: np.ndarray, rng_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    s = pos.shape[0]
    i, j = np.triu_indices(s, 1)
    d = np.linalg.norm(pos[i] - pos[j], axis=1)
    keep = d <= rng_m
    indptr, idx = _links_from_pairs(i[keep].astype(np.int64), j[keep].astype(np.int64), pos, np.ones(s, dtype=bool),
                                    np.zeros(s, dtype=np.int64), np.full(s, rng_m), s)  # fmt: skip
    return indptr[:-1], indptr[1:], idx


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(3, 60),
    k=st.integers(1, 4),
    hops=st.integers(1, 5),
    moves=st.integers(0, 10),
)
def test_sharded_flood_hops_equal_one_overlay(seed: int, n: int, k: int, hops: int, moves: int) -> None:
    rng = np.random.default_rng(seed)
    pos = np.column_stack([rng.uniform(0, 60, n), rng.uniform(0, 60, n), np.zeros(n)])
    reach = 20.0
    ref = Overlay(n, 2, reach)
    sharded = ShardedOverlay(n, 2, reach)
    readers = [ShardReaders(n) for _ in range(k)]
    owner = rng.integers(0, k, n)
    for step in range(hops):
        origins = rng.choice(n, size=rng.integers(0, 4), replace=False)
        limits = rng.integers(1, 4, origins.size)
        payload = rng.uniform(-1, 1, (origins.size, 2)).astype(np.float32)
        ref.start(origins, limits, payload, step)
        sharded.start(origins, limits, payload, step)
        # agents move to other shards between hops, with what they read
        movers = rng.choice(n, size=min(moves, n), replace=False)
        new_owner = owner.copy()
        new_owner[movers] = rng.integers(0, k, movers.size)
        for src in range(k):
            leaving = (owner == src) & (new_owner != src)
            fl, sl = readers[src].take_leaving(leaving)
            for dst in range(k):
                sel = new_owner[sl] == dst
                readers[dst].add(fl[sel], sl[sel])
        owner = new_owner
        links = _csr(pos, reach)
        active, fr_f, fr_u, new = sharded.hop_plan()
        got_v, got_f, edges = [], [], 0
        for shard in range(k):  # every shard sees every slot here: its own ones are what matters
            v, f, e = readers[shard].hop(links, owner == shard, active.copy(), fr_f[new], fr_u[new], fr_f, fr_u)
            got_v.append(v)
            got_f.append(f)
            edges += e
        sharded.put(np.concatenate(got_v), np.concatenate(got_f), edges)
        a = ref.advance_graph(*links)
        b = sharded.advance_graph(*links)
        assert sorted(zip(a.receiver.tolist(), a.flood.tolist(), a.hops.tolist())) == sorted(
            zip(b.receiver.tolist(), b.flood.tolist(), b.hops.tolist())
        )
        # deliveries grouped by flood in the same flood order (what an inbox sees)
        assert [f for i, f in enumerate(a.flood.tolist()) if i == 0 or a.flood[i - 1] != f] == [
            f for i, f in enumerate(b.flood.tolist()) if i == 0 or b.flood[i - 1] != f
        ]
        assert ref.stats == sharded.stats
        assert sorted(zip(ref._front_f.tolist(), ref._front_n.tolist())) == sorted(
            zip(sharded._front_f.tolist(), sharded._front_n.tolist())
        )
