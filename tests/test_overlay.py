"""Overlay flooding: differential tests against networkx breadth-first search, plus edge cases."""

from __future__ import annotations

import pickle

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.comms.overlay import Deliveries, Overlay
from agentsim_env.comms.rangegraph import RangeGraph, _links_from_pairs
from agentsim_env.core.spatial import Grid, GridSpec, build_grid, neighbor_pairs

D = 3


def _scene(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | float]:
    """Random positions, online flags, worlds and ranges (scalar or per slot)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 201))
    n_worlds = int(rng.integers(1, 4))
    side = float(rng.uniform(30.0, 120.0))
    pos = np.column_stack([rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(0, 10, n)])
    online = rng.random(n) >= rng.uniform(0.0, 0.3)
    world = rng.integers(0, n_worlds, n)
    comm_range: np.ndarray | float
    if seed % 2:
        comm_range = rng.uniform(5.0, 25.0, n)
    else:
        comm_range = float(rng.uniform(8.0, 20.0))
    return pos, online, world, comm_range


def _pairs(pos: np.ndarray, world: np.ndarray, max_dist: float) -> tuple[np.ndarray, ...]:
    spec = GridSpec.for_bounds((0.0, 120.0, 0.0, 120.0), max_dist, int(world.max()) + 1)
    grid = build_grid(spec, pos, world, np.ones(len(pos), dtype=bool))
    return neighbor_pairs(grid, pos, world, max_dist)


def _oracle_graph(pos: np.ndarray, online: np.ndarray, world: np.ndarray, comm_range) -> nx.Graph:
    """Range graph by brute force, restricted to online nodes (independent of the grid)."""
    n = len(pos)
    r = np.broadcast_to(np.asarray(comm_range, dtype=float), (n,))
    dist = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
    ok = (dist <= np.minimum(r[:, None], r[None, :])) & (world[:, None] == world[None, :])
    ok &= online[:, None] & online[None, :]
    g = nx.Graph()
    g.add_nodes_from(np.flatnonzero(online).tolist())
    i, j = np.nonzero(np.triu(ok, 1))
    g.add_edges_from(zip(i.tolist(), j.tolist(), strict=True))
    return g


def _collect(seen: dict[int, dict[int, int]], d: Deliveries, floods: dict[int, tuple]) -> None:
    """Accumulate readers per flood and check every row against its flood; a duplicate fails."""
    for r, f, o, h, c, p in zip(d.receiver, d.flood, d.origin, d.hops, d.created, d.payload, strict=True):
        origin, _, created, payload = floods[int(f)]
        assert (o, c) == (origin, created)
        np.testing.assert_array_equal(p, payload)
        assert int(r) not in seen[int(f)], "a slot read the same flood twice"
        seen[int(f)][int(r)] = int(h)


def _start_random(ov: Overlay, rng: np.random.Generator, online: np.ndarray, k: int, step: int) -> dict:
    origin = rng.choice(np.flatnonzero(online), size=k)  # repeated origins are allowed
    limit = rng.integers(1, 7, k)
    payload = rng.normal(size=(k, D)).astype(np.float32)
    ids = ov.start(origin, limit, payload, step)
    assert len(set(ids.tolist())) == k
    return {
        int(f): (int(o), int(h), step, payload[q]) for q, (f, o, h) in enumerate(zip(ids, origin, limit, strict=True))
    }


@pytest.mark.parametrize("seed", range(8))
def test_stepwise_flooding_matches_bfs(seed: int) -> None:
    pos, online, world, comm_range = _scene(seed)
    rng = np.random.default_rng(1000 + seed)
    graph = _oracle_graph(pos, online, world, comm_range)
    pairs = _pairs(pos, world, float(np.max(comm_range)))
    ov = Overlay(len(pos), D, comm_range, capacity=4)
    floods = _start_random(ov, rng, online, int(rng.integers(1, 40)), step=7)
    seen: dict[int, dict[int, int]] = {f: {} for f in floods}
    bfs = {f: nx.single_source_shortest_path_length(graph, o) for f, (o, *_) in floods.items()}
    for h in range(1, 9):
        _collect(seen, ov.advance(pos, online, world, pairs, 7 + h), floods)
        for f, (origin, limit, *_) in floods.items():
            want = {v: d for v, d in bfs[f].items() if 0 < d <= min(h, limit)}
            assert seen[f] == want
            alive = h < limit and any(d == h for d in bfs[f].values())
            assert ov.is_active(f) == alive
            if alive:
                assert ov.readers(f).tolist() == sorted([origin, *want])
    assert ov.active_count == 0
    assert ov.totals.delivered == sum(len(s) for s in seen.values())
    assert ov.totals.started == ov.totals.finished == len(floods)


@pytest.mark.parametrize("seed", range(8, 14))
def test_full_propagation_matches_bfs_in_one_call(seed: int) -> None:
    pos, online, world, comm_range = _scene(seed)
    rng = np.random.default_rng(seed)
    graph = _oracle_graph(pos, online, world, comm_range)
    pairs = _pairs(pos, world, float(np.max(comm_range)))
    ov = Overlay(len(pos), D, comm_range, full_propagation=True)
    floods = _start_random(ov, rng, online, int(rng.integers(1, 40)), step=0)
    seen: dict[int, dict[int, int]] = {f: {} for f in floods}
    _collect(seen, ov.advance(pos, online, world, pairs, 0), floods)
    for f, (origin, limit, *_) in floods.items():
        want = nx.single_source_shortest_path_length(graph, origin, cutoff=limit)
        want.pop(origin)
        assert seen[f] == want
    assert ov.active_count == 0
    assert len(ov.advance(pos, online, world, pairs, 1)) == 0


def _line(n: int, gap: float = 5.0) -> np.ndarray:
    return np.column_stack([np.arange(n) * gap, np.zeros(n), np.zeros(n)])


def _run(ov: Overlay, pos, online, world=None, calls: int = 1, pairs=None) -> list[Deliveries]:
    world = np.zeros(len(pos), dtype=np.int64) if world is None else world
    pairs = _pairs(pos, world, float(np.max(ov.comm_range))) if pairs is None else pairs
    return [ov.advance(pos, online, world, pairs, t) for t in range(calls)]


def test_hop_limit_respected_on_a_line() -> None:
    pos = _line(10)
    ov = Overlay(10, 1, 6.0)
    (f,) = ov.start(np.array([0]), 3, np.array([[2.5]]), step=4)
    out = _run(ov, pos, np.ones(10, dtype=bool), calls=6)
    assert [d.receiver.tolist() for d in out] == [[1], [2], [3], [], [], []]
    assert [d.hops.tolist() for d in out[:3]] == [[1], [2], [3]]
    assert all(d.flood.tolist() == [f] and d.created.tolist() == [4] for d in out[:3])
    assert not ov.is_active(f) and ov.stats.finished == 0 and ov.totals.finished == 1


def test_isolated_agent_hears_nothing_and_sends_to_no_one() -> None:
    pos = np.vstack([_line(5), [[500.0, 0.0, 0.0]]])
    online = np.ones(6, dtype=bool)
    ov = Overlay(6, 0, 6.0, full_propagation=True)
    ov.start(np.array([0, 5]), np.array([10, 10]), None, step=0)
    (d,) = _run(ov, pos, online)
    assert 5 not in d.receiver.tolist()
    assert sorted(d.receiver.tolist()) == [1, 2, 3, 4]
    assert (d.origin == 0).all() and ov.stats.finished == 2 and ov.active_count == 0


def test_offline_slot_neither_reads_nor_relays() -> None:
    pos = _line(4)
    online = np.ones(4, dtype=bool)
    ov = Overlay(4, 0, 6.0)
    ov.start(np.array([0]), 5, None, step=0)
    (d,) = _run(ov, pos, online)
    assert d.receiver.tolist() == [1]
    online[1] = False  # 1 read the flood, then went offline before relaying it
    out = _run(ov, pos, online, calls=3)
    assert all(len(x) == 0 for x in out) and ov.active_count == 0
    ov.reset()
    ov.start(np.array([0]), 5, None, step=0)
    online[:] = [True, True, False, True]
    out = _run(ov, pos, online, calls=4)
    assert [x.receiver.tolist() for x in out] == [[1], [], [], []]


def test_per_slot_range_uses_the_smaller_radius() -> None:
    pos = np.array([[0.0, 0.0, 0.0], [8.0, 0.0, 0.0]])
    online = np.ones(2, dtype=bool)
    ov = Overlay(2, 0, np.array([10.0, 5.0]))
    ov.start(np.array([0]), 1, None, step=0)
    assert len(_run(ov, pos, online)[0]) == 0
    ov.set_range(np.array([10.0, 8.0]))  # dist == min range: the link exists
    ov.start(np.array([1]), 1, None, step=1)
    assert _run(ov, pos, online)[0].receiver.tolist() == [0]


def test_no_edge_across_worlds_even_if_pairs_say_so() -> None:
    pos = np.zeros((3, 3))
    world = np.array([0, 1, 0])
    pairs = (np.array([0, 0, 1]), np.array([1, 2, 2]))
    ov = Overlay(3, 0, 1.0)
    ov.start(np.array([0]), 4, None, step=0)
    (d,) = _run(ov, pos, np.ones(3, dtype=bool), world=world, pairs=pairs)
    assert d.receiver.tolist() == [2]


def test_duplicates_counted_and_dropped_in_a_triangle() -> None:
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    ov = Overlay(3, 0, 2.0)
    ov.start(np.array([0]), 5, None, step=0)
    (first,) = _run(ov, pos, np.ones(3, dtype=bool))
    assert sorted(first.receiver.tolist()) == [1, 2] and ov.stats.duplicates == 0
    (second,) = _run(ov, pos, np.ones(3, dtype=bool))
    assert len(second) == 0 and ov.stats.duplicates == 4 and ov.stats.finished == 1


def test_concurrent_floods_do_not_interfere() -> None:
    pos, online, world, comm_range = _scene(3)
    pairs = _pairs(pos, world, float(np.max(comm_range)))
    rng = np.random.default_rng(5)
    origin = rng.choice(np.flatnonzero(online), size=30)
    limit = rng.integers(1, 6, 30)

    def rows(o: np.ndarray, lim: np.ndarray) -> list[set]:
        ov = Overlay(len(pos), 0, comm_range)
        ids = ov.start(o, lim, None, step=0)
        out: list[set] = [set() for _ in ids]
        slot = {int(f): q for q, f in enumerate(ids)}
        for d in _run(ov, pos, online, world, calls=6, pairs=pairs):
            for r, f, h in zip(d.receiver, d.flood, d.hops, strict=True):
                out[slot[int(f)]].add((int(r), int(h)))
        return out

    together = rows(origin, limit)
    alone = [rows(origin[q : q + 1], limit[q : q + 1])[0] for q in range(30)]
    assert together == alone


def test_capacity_grows_and_ids_recycle() -> None:
    pos = _line(6)
    ov = Overlay(6, 2, 6.0, capacity=1)
    ids = ov.start(np.arange(6), 1, np.ones(2), step=0)
    assert sorted(ids.tolist()) == list(range(6)) and ov.capacity == 8 and ov.active_count == 6
    (d,) = _run(ov, pos, np.ones(6, dtype=bool))
    assert len(d) == 10 and (d.payload == 1).all() and ov.active_count == 0
    again = ov.start(np.arange(8) % 6, 2, None, step=1)
    assert sorted(again.tolist()) == list(range(8)) and ov.capacity == 8
    # Recycled rows must not remember the readers of their previous floods.
    got: dict[int, set[int]] = {int(f): set() for f in again}
    for d in _run(ov, pos, np.ones(6, dtype=bool), calls=3):
        for r, f in zip(d.receiver.tolist(), d.flood.tolist(), strict=True):
            got[f].add(r)
    for f, o in zip(again.tolist(), (np.arange(8) % 6).tolist(), strict=True):
        assert got[f] == {v for v in range(6) if 0 < abs(v - o) <= 2}


def test_recycled_row_forgets_its_readers() -> None:
    n = 130  # three bitset words: the stale-reader bug only shows beyond the origin's word
    on = np.ones(n, dtype=bool)
    ov = Overlay(n, 0, 6.0, full_propagation=True, capacity=1)
    (f,) = ov.start(np.array([0]), 200, None, step=0)
    assert len(_run(ov, _line(n), on)[0]) == n - 1
    (g,) = ov.start(np.array([64]), 1, None, step=1)
    assert g == f and ov.readers(g).tolist() == [64]
    assert sorted(_run(ov, _line(n), on)[0].receiver.tolist()) == [63, 65]


def test_pickle_mid_flood_continues_identically() -> None:
    pos, online, world, comm_range = _scene(4)
    pairs = _pairs(pos, world, float(np.max(comm_range)))
    ov = Overlay(len(pos), D, comm_range)
    _start_random(ov, np.random.default_rng(0), online, 20, step=0)
    ov.advance(pos, online, world, pairs, 0)
    twin = pickle.loads(pickle.dumps(ov))
    for t in range(1, 5):
        a = ov.advance(pos, online, world, pairs, t)
        b = twin.advance(pos, online, world, pairs, t)
        for name in ("receiver", "flood", "origin", "hops", "created", "payload"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert ov.totals == twin.totals


def test_reset_and_stats() -> None:
    ov = Overlay(4, 0, 6.0)
    ov.start(np.array([0, 1]), 3, None, step=0)
    _run(ov, _line(4), np.ones(4, dtype=bool))
    assert ov.stats.started == 2 and ov.stats.delivered == 3 and ov.active_count == 2
    ov.reset()
    assert ov.active_count == 0 and ov.totals.delivered == 0
    assert len(_run(ov, _line(4), np.ones(4, dtype=bool))[0]) == 0


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"n_slots": 0}, "n_slots"),
        ({"payload_dim": -1}, "payload_dim"),
        ({"comm_range": -1.0}, "comm_range"),
        ({"comm_range": np.ones(3)}, "comm_range"),
        ({"capacity": 0}, "capacity"),
    ],
)
def test_constructor_validation(kwargs: dict, field: str) -> None:
    args = {"n_slots": 4, "payload_dim": 2, "comm_range": 1.0} | kwargs
    with pytest.raises(ValueError, match=field):
        Overlay(**args)


def test_call_validation() -> None:
    ov = Overlay(4, 2, 1.0)
    with pytest.raises(ValueError, match="origin"):
        ov.start(np.array([4]), 1, None, step=0)
    with pytest.raises(ValueError, match="hop_limit"):
        ov.start(np.array([0]), 0, None, step=0)
    with pytest.raises(ValueError, match="payload"):
        ov.start(np.array([0]), 1, np.ones((1, 3)), step=0)
    with pytest.raises(ValueError, match="pos"):
        ov.advance(np.zeros((3, 3)), np.ones(4, bool), np.zeros(4, int), (np.empty(0), np.empty(0)), 0)
    with pytest.raises(ValueError, match="pairs"):
        ov.advance(np.zeros((4, 3)), np.ones(4, bool), np.zeros(4, int), (np.array([0]), np.array([9])), 0)
    with pytest.raises(ValueError, match="flood"):
        ov.readers(0)


# --------------------------------------------------------------- ranges above the configured one
# The comms stack builds its RangeGraph for the configured overlay range (max(overlay_range, nearest_range))
# and a neighbour grid of a fixed cell; set_range may later raise some slots' ranges above it.

CONFIGURED = 30.0


def _stack_graph(n: int) -> RangeGraph:
    return RangeGraph(n, CONFIGURED, CONFIGURED)  # as CommsStack: max(overlay_range, nearest_range)


def _grid(pos: np.ndarray, world: np.ndarray, online: np.ndarray, cell: float = 5.0) -> Grid:
    return build_grid(GridSpec.for_bounds((0.0, 200.0, 0.0, 200.0), cell, int(world.max()) + 1), pos, world, online)


def _flood_over_graph(ov: Overlay, graph: RangeGraph, pos, online, world, grid: Grid, calls: int) -> list[Deliveries]:
    """``calls`` steps of the comms stack's overlay path: grid scan, then one hop over its links."""
    out = []
    for _ in range(calls):
        graph.set_grid(grid, pos, online, world, ov.link_range, ov.frontier_size > 0)
        out.append(ov.advance_graph(*graph.links(ov.link_range)))
    return out


def _square() -> tuple[np.ndarray, np.ndarray]:
    """Four slots on a 60 m square; 0, 1 and 3 raised to 80 m, 2 left at the configured 30 m."""
    pos = np.array([[10.0, 10.0, 5.0], [70.0, 10.0, 5.0], [10.0, 70.0, 5.0], [70.0, 70.0, 5.0]])
    return pos, np.array([80.0, 80.0, CONFIGURED, 80.0])


def test_set_range_above_configured_range_links_agents_60m_apart() -> None:
    pos, ranges = _square()
    online, world = np.ones(4, dtype=bool), np.zeros(4, dtype=np.int64)
    grid = _grid(pos, world, online)
    ov = Overlay(4, 1, CONFIGURED)
    ov.start(np.array([0]), 3, np.array([[1.5]]), step=0)
    out = _flood_over_graph(ov, _stack_graph(4), pos, online, world, grid, calls=2)
    assert [len(d) for d in out] == [0, 0] and ov.active_count == 0  # 60 m > 30 m: nobody in range
    ov.set_range(ranges)
    assert ov.max_range == 80.0
    (f,) = ov.start(np.array([0]), 3, np.array([[1.5]]), step=1)
    out = _flood_over_graph(ov, _stack_graph(4), pos, online, world, grid, calls=3)
    assert [d.receiver.tolist() for d in out] == [[1], [3], []]  # 2 keeps 30 m; 0-3 is 85 m
    assert [d.hops.tolist() for d in out[:2]] == [[1], [2]] and out[0].payload[0, 0] == 1.5
    # the same as breadth-first search over the brute-force range graph
    want = nx.single_source_shortest_path_length(_oracle_graph(pos, online, world, ranges), 0, cutoff=3)
    assert {int(d.receiver[0]): int(d.hops[0]) for d in out[:2]} == {v: h for v, h in want.items() if v != 0}
    assert not ov.is_active(f)


@pytest.mark.parametrize("seed", range(6))
def test_grid_links_follow_ranges_above_the_graph_radius(seed: int) -> None:
    """Per-slot ranges up to 2.5x the graph's radius: links as brute force (the pairs path's rows, in order),
    floods as BFS, nearest neighbours as with the configured ranges."""
    pos, online, world, _ = _scene(seed)
    rng = np.random.default_rng(seed)
    n = len(pos)
    ranges = rng.uniform(5.0, 2.5 * CONFIGURED, n)
    grid = _grid(pos, world, online, cell=float(rng.choice([3.0, 5.0, 12.0])))
    graph = _stack_graph(n)
    graph.set_grid(grid, pos, online, world, ranges, True)
    start, end, indices = (a.copy() for a in graph.links(ranges))
    near = graph.nearest().copy()
    pi, pj, _ = neighbor_pairs(grid, pos, world, float(ranges.max()))  # the same grid: the same order
    indptr, want_idx = _links_from_pairs(pi, pj, pos, online, world, ranges, n)
    for s in range(n):
        assert indices[start[s] : end[s]].tolist() == want_idx[indptr[s] : indptr[s + 1]].tolist(), s
    oracle = _oracle_graph(pos, online, world, ranges)
    assert sum(end - start) == 2 * oracle.number_of_edges()
    graph.set_grid(grid, pos, online, world, np.full(n, CONFIGURED), True)  # nearest: independent of ranges
    np.testing.assert_array_equal(graph.nearest(), near)
    ov = Overlay(n, D, ranges, full_propagation=True)
    floods = _start_random(ov, rng, online, 10, step=0)
    seen: dict[int, dict[int, int]] = {f: {} for f in floods}
    for d in _flood_over_graph(ov, graph, pos, online, world, grid, calls=1):
        _collect(seen, d, floods)
    for f, (origin, limit, *_) in floods.items():
        want = nx.single_source_shortest_path_length(oracle, origin, cutoff=limit)
        want.pop(origin)
        assert seen[f] == want


def test_grid_links_with_a_range_beyond_the_map() -> None:
    pos = np.array([[0.0, 0.0, 0.0], [200.0, 200.0, 0.0], [100.0, 100.0, 1e6]])
    online, world = np.ones(3, dtype=bool), np.zeros(3, dtype=np.int64)
    graph = _stack_graph(3)
    graph.set_grid(_grid(pos, world, online), pos, online, world, np.full(3, 1e300), True)
    start, end, indices = graph.links(np.full(3, 1e300))
    assert [sorted(indices[start[s] : end[s]].tolist()) for s in range(3)] == [[1, 2], [0, 2], [0, 1]]


def test_pair_links_refuse_ranges_beyond_the_pairs_radius() -> None:
    pos, ranges = _square()
    online, world = np.ones(4, dtype=bool), np.zeros(4, dtype=np.int64)
    graph = _stack_graph(4)
    graph.set_pairs(_pairs(pos, world, CONFIGURED), pos, online, world)
    with pytest.raises(ValueError, match=r"comm_range must be <= 30 m .*got 80 m"):
        graph.links(ranges)
    start, end, _ = graph.links(np.full(4, CONFIGURED))
    assert (start == end).all()


def test_set_range_above_configured_range_through_the_env() -> None:
    import agentsim_env

    env = agentsim_env.make(
        "navigation",
        n_agents=4,
        map_size=100.0,
        obstacle_density=0.0,
        comms={"overlay_range": CONFIGURED, "nearest_range": CONFIGURED},
    )
    env.reset(seed=0)
    pos, ranges = _square()
    env.world.state.pos[:] = pos
    env.world.refresh()
    d = env.action_space("agent_0")["comm"].shape[0]
    idle = {"motion": np.zeros(3, np.float32), "comm": np.full(d, -1.0, np.float32)}
    flood = {"motion": idle["motion"], "comm": idle["comm"].copy()}
    flood["comm"][[0, 2]] = 0.8, 1.0  # channel 4 (overlay), the largest hop limit

    def reached() -> list[list[int]]:
        acts = {a: idle for a in env.agents} | {"agent_0": flood}
        got = []
        for _ in range(3):
            env.step(acts)
            acts = {a: idle for a in env.agents}
            got.append(sorted(env.world.last_events.comms.overlay.receiver.tolist()))
        return got

    assert reached() == [[], [], []]  # 60 m apart, 30 m ranges
    env.world.comms.overlay.set_range(ranges)
    assert reached() == [[1], [3], []]  # 80 m on 0, 1 and 3; slot 2 keeps 30 m


@st.composite
def _small_graph(draw: st.DrawFn) -> tuple:
    n = draw(st.integers(1, 12))
    all_pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    edges = draw(st.lists(st.sampled_from(all_pairs), unique=True)) if all_pairs else []
    online = np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    origin = draw(st.integers(0, n - 1))
    limit = draw(st.integers(1, 6))
    return n, edges, online, origin, limit, draw(st.booleans())


@settings(max_examples=60, deadline=None, derandomize=True)
@given(_small_graph())
def test_property_small_graphs(case: tuple) -> None:
    n, edges, online, origin, limit, full = case
    # All agents at one point with range 1: the pairs passed in are exactly the graph's edges.
    pairs = (np.array([e[0] for e in edges], dtype=np.int64), np.array([e[1] for e in edges], dtype=np.int64))
    g = nx.Graph()
    g.add_nodes_from(range(n))
    g.add_edges_from(edges)
    sub = g.subgraph([v for v in range(n) if online[v]])
    want = nx.single_source_shortest_path_length(sub, origin, cutoff=limit) if online[origin] else {origin: 0}
    want.pop(origin)
    ov = Overlay(n, 0, 1.0, full_propagation=full)
    ov.start(np.array([origin]), limit, None, step=0)
    got: dict[int, int] = {}
    for t in range(limit + 1):
        d = ov.advance(np.zeros((n, 3)), online, np.zeros(n, dtype=np.int64), pairs, t)
        assert not set(d.receiver.tolist()) & set(got), "duplicate delivery"
        got.update(zip(d.receiver.tolist(), d.hops.tolist(), strict=True))
        assert origin not in got
    assert got == want
    assert ov.active_count == 0


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    lattice=st.sampled_from([0.0, 1.0, 2.5]),
    cell=st.sampled_from([1.0, 5.0, 40.0]),
    dense=st.booleans(),
)
def test_grid_scan_equals_pairs_path_with_ties(seed: int, lattice: float, cell: float, dense: bool) -> None:
    """The grid scan's links (rows in order) and nearest neighbours equal the pairs path's, on positions snapped
    to a lattice (many equal distances, so the nearest's tie rule decides) and in cells holding many slots
    (dense: windows whose columns hold more than the scan copies unconditionally)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 160))
    side = 15.0 if dense else 120.0
    pos = np.column_stack([rng.uniform(0, side, n), rng.uniform(0, side, n), rng.uniform(0, 4, n)])
    if lattice:
        pos = np.round(pos / lattice) * lattice
    online = rng.random(n) >= 0.15
    world = rng.integers(0, 2, n)
    ranges = np.where(rng.random(n) < 0.5, CONFIGURED, rng.uniform(1.0, CONFIGURED, n))
    grid = _grid(pos, world, online, cell=cell)
    graph = _stack_graph(n)
    graph.set_grid(grid, pos, online, world, ranges, True)
    start, end, indices = (a.copy() for a in graph.links(ranges))
    near = graph.nearest().copy()
    pi, pj, d = neighbor_pairs(grid, pos, world, CONFIGURED)  # the same grid: the same order
    indptr, want_idx = _links_from_pairs(pi, pj, pos, online, world, ranges, n)
    for s in range(n):
        assert indices[start[s] : end[s]].tolist() == want_idx[indptr[s] : indptr[s + 1]].tolist(), s
    by_pairs = RangeGraph(n, CONFIGURED, CONFIGURED)
    by_pairs.set_pairs((pi, pj, d), pos, online, world)
    np.testing.assert_array_equal(near, by_pairs.nearest())


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_one_hop_kernel_equals_the_general_spread(seed: int) -> None:
    """The comms stack's one-hop kernel (``spread_hop``) gives what the general ``spread`` gives in one-hop mode:
    deliveries in order, hops, ended floods, duplicates and the reader lists, over calls that start new floods
    while older ones spread and slots go offline."""
    import agentsim_env.comms.flooding as flooding
    import agentsim_env.comms.overlay as overlay_mod

    def general(*a):  # type: ignore[no-untyped-def]
        *head, stamp, token, new_pool, out_r, out_f, out_h = a
        return flooding.spread(*head, False, stamp, token, new_pool, out_r, out_f, out_h)

    def run(patch: bool) -> list:
        with pytest.MonkeyPatch.context() as mp:
            if patch:
                mp.setattr(overlay_mod, "spread_hop", general)
            rng = np.random.default_rng(seed)
            pos, online, world, comm_range = _scene(seed)
            n = len(pos)
            ov = Overlay(n, D, comm_range)
            out = []
            for step in range(6):
                _start_random(ov, rng, online, int(rng.integers(0, 8)), step)
                d = ov.advance(pos, online, world, _pairs(pos, world, 25.0), step)
                out.append(
                    (
                        d.receiver,
                        d.flood,
                        d.hops,
                        d.origin,
                        d.payload,
                        ov.stats.duplicates,
                        ov.active_count,
                        [ov.readers(f).tolist() for f in range(ov.capacity) if ov.is_active(f)],
                    )
                )
                online = online & (rng.random(n) > 0.05)
            return out

    for a, b in zip(run(False), run(True), strict=True):
        for x, y in zip(a, b, strict=True):
            if isinstance(x, np.ndarray):
                np.testing.assert_array_equal(x, y)
            else:
                assert x == y


@pytest.mark.parametrize("threads", [1, 3])
def test_deliveries_read_late_keep_their_values_after_flood_rows_are_reused(threads: int) -> None:
    """A hop's deliveries look their origin, created step and payload up in the flood table when read; reading
    them only after later steps started floods in the recycled rows (a tiny table: rows are reused at once) gives
    the values read at once, whole tables copied or rows looked up, and pickles alike."""
    from agentsim_env.core import threads as threads_mod
    from agentsim_env.core.threads import RowThreads

    def run(read_now: bool) -> list:
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(threads_mod, "MIN_ROWS", 2)
            rng = np.random.default_rng(5)
            pos, online, world, comm_range = _scene(3)
            ov = Overlay(len(pos), D, comm_range, capacity=4)
            ov.threads = RowThreads(threads)
            kept = []
            for step in range(12):
                if step % 3 != 1:  # some steps start no flood: older unread deliveries must keep their rows too
                    _start_random(ov, rng, online, int(rng.integers(1, 30)), step)
                d = ov.advance(pos, online, world, _pairs(pos, world, 25.0), step)
                kept.append((d, (d.origin.copy(), d.created.copy(), d.payload.copy()) if read_now else None))
            return [(d.receiver, d.flood, d.hops, *(now or (d.origin, d.created, d.payload))) for d, now in kept]

    now, late = run(True), run(False)
    assert sum(len(x[0]) for x in now) > 100 and any(len(set(x[1].tolist())) < len(x[1]) for x in now)
    for a, b in zip(now, late, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
    d = Overlay(3, D, 50.0)
    d.start(np.array([0]), 2, np.ones((1, D)), step=0)
    got = d.advance(
        np.zeros((3, 3)),
        np.ones(3, bool),
        np.zeros(3, int),
        _pairs(np.zeros((3, 3)), np.zeros(3, int), 25.0),
        0,
    )
    back = pickle.loads(pickle.dumps(got))
    np.testing.assert_array_equal(back.payload, np.ones((2, D), dtype=np.float32))
    assert back.origin.tolist() == [0, 0] and back.receiver.tolist() == [1, 2]
    with pytest.raises(AttributeError, match="read-only"):
        got.receiver = back.receiver  # type: ignore[misc]
