"""Properties of the pieces that make a sharded run equal one process (hypothesis).

- The halo: every agent within the halo (in x) of a shard's own agent, and owned elsewhere, is its ghost.

The flood hop per shard against the single-process overlay is in tests/test_distributed_floods.py, the bus split
by receiver in tests/test_bus_split.py.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.comms.rangegraph import _links_from_pairs
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
    indptr, idx = _links_from_pairs(
        i[keep].astype(np.int64),
        j[keep].astype(np.int64),
        pos,
        np.ones(s, dtype=bool),
        np.zeros(s, dtype=np.int64),
        np.full(s, rng_m),
        s,
    )
    return indptr[:-1], indptr[1:], idx
