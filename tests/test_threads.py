"""``num_threads``: the row ranges, the bad values, and results that do not depend on the thread count."""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import agentsim_env
from agentsim_env.comms.flood_threads import flood_ranges
from agentsim_env.comms.inbox import Inbox
from agentsim_env.comms.inbox_kernels import SAME_ROWS
from agentsim_env.comms.overlay import Overlay
from agentsim_env.comms.rangegraph import RangeGraph
from agentsim_env.core import threads as threads_mod
from agentsim_env.core.collisions import find_collisions
from agentsim_env.core.scene import Scene
from agentsim_env.core.spatial import GridSpec, build_grid, build_object_grid
from agentsim_env.core.threads import RowThreads, check_num_threads
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.scenarios.registry import scenario_class
from agentsim_env.sensors.proximity import ProximityConfig, ProximitySensor


@given(n=st.integers(0, 100_000), k=st.integers(1, 16), min_rows=st.integers(1, 5000))
@settings(max_examples=200, deadline=None)
def test_ranges_cover_rows_once_in_order(n: int, k: int, min_rows: int) -> None:
    ranges = RowThreads(k).ranges(n, min_rows)
    assert 1 <= len(ranges) <= k
    assert ranges[0][0] == 0 and ranges[-1][1] == n
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))
    if len(ranges) > 1:
        assert min(hi - lo for lo, hi in ranges) >= min_rows


def test_run_uses_other_threads_and_raises_their_errors() -> None:
    seen: dict[int, str] = {}

    def rows(lo: int, hi: int, part: int) -> None:
        seen[part] = threading.current_thread().name

    RowThreads(3).run(rows, 30, min_rows=10)
    assert sorted(seen) == [0, 1, 2]
    assert seen[0] == threading.current_thread().name and seen[1] != seen[0]

    def fails(lo: int, hi: int, part: int) -> None:
        if part == 2:
            raise RuntimeError(f"rows {lo}..{hi}")

    with pytest.raises(RuntimeError, match="rows 20..30"):
        RowThreads(3).run(fails, 30, min_rows=10)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (0, "num_threads must be >= 1"),
        (257, "num_threads must be <= 256"),
        ("2", "num_threads must be an integer"),
        (2.5, "num_threads must be an integer"),
        (True, "num_threads must be an integer"),
        (None, "num_threads must be an integer"),
    ],
)
def test_bad_num_threads_is_refused_by_name(value: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        check_num_threads(value)
    with pytest.raises(ValueError, match=message):
        BatchedEnv("navigation", 1, n_agents=4, num_threads=value)
    with pytest.raises(ValueError, match=message):
        agentsim_env.make("navigation", n_agents=4, num_threads=value)


def _rollout(name: str, cfg: dict[str, Any], num_threads: int, steps: int = 25) -> list[np.ndarray]:
    env = BatchedEnv(name, 2, num_threads=num_threads, **cfg)
    out = [env.reset(seed=3)]
    rng = np.random.default_rng(0)
    for _ in range(steps):
        r = env.step(rng.uniform(-1, 1, (2, env.n_agents, env.act_dim)))
        out += [r.obs, r.rewards, r.terminated, r.truncated, r.alive, r.final_obs, env.world.state.pos.copy()]
        ev = env.world.last_events.collisions  # the events' order too, not only who went offline
        out += [ev.agent, ev.other_agent, ev.obj]
    return out


CASES = [(name, cfg) for name in agentsim_env.list_scenarios() for cfg in scenario_class(name).test_configs]


@pytest.mark.parametrize(("name", "cfg"), CASES, ids=[f"{n}-{i}" for i, (n, _) in enumerate(CASES)])
def test_results_do_not_depend_on_the_thread_count(
    name: str, cfg: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Tiny ranges so that these small worlds are really split over threads.
    monkeypatch.setattr(threads_mod, "MIN_ROWS", 2)
    one = _rollout(name, cfg, 1)
    for k in (2, 3, 4):
        other = _rollout(name, cfg, k)
        assert len(one) == len(other)
        for i, (a, b) in enumerate(zip(one, other)):
            np.testing.assert_array_equal(a, b, err_msg=f"{name} with {k} threads: array {i} differs")


@given(seed=st.integers(0, 10_000), k=st.integers(2, 5))
@settings(max_examples=40, deadline=None)
def test_collision_events_and_scans_do_not_depend_on_the_thread_count(seed: int, k: int) -> None:
    # Crowded random worlds with objects: events in every range of slots, joined in the one-range order.
    rng = np.random.default_rng(seed)
    s, n_worlds = 120, 2
    pos = np.column_stack([rng.uniform(0, 20, (s, 2)), rng.uniform(0, 4, s)])
    radius = rng.uniform(0.3, 1.2, s)
    online = rng.random(s) < 0.9
    world = rng.integers(0, n_worlds, s)
    scene = Scene()
    scene.add(
        rng.integers(0, 3, 12),
        np.column_stack([rng.uniform(0, 20, (12, 2)), rng.uniform(0, 4, 12)]),
        rng.uniform(0.5, 3.0, (12, 3)),
        rng.integers(0, n_worlds, 12),
    )
    spec = GridSpec.for_bounds((0, 20, 0, 20), 3.0, n_worlds)
    grid = build_grid(spec, pos, world, online)
    og = build_object_grid(spec, scene.centre, scene.footprint_radius(), scene.world)
    args = (pos, radius, online, world, grid, scene.kind, scene.centre, scene.half, scene.world, og, 0.1)
    one = find_collisions(*args, RowThreads(1))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(threads_mod, "MIN_ROWS", 8)
        many = find_collisions(*args, RowThreads(k))
    assert (one.other_agent >= 0).any() and (one.obj >= 0).any()
    for name in ("agent", "other_agent", "obj"):
        np.testing.assert_array_equal(getattr(one, name), getattr(many, name))
    sensor = ProximitySensor(ProximityConfig(n_azimuth=16, elevations_deg=(-20.0, 0.0)))
    heading, srange = rng.uniform(-3, 3, s), rng.uniform(2, 8, s)
    scan_args = (
        pos,
        heading,
        srange,
        radius,
        online,
        world,
        grid,
        scene.kind,
        scene.centre,
        scene.half,
        scene.world,
        og,
        True,
    )
    ref = sensor.scan(*scan_args)
    ref = (ref.distance.copy(), ref.hit_kind.copy(), ref.hit_id.copy())
    sensor.threads = RowThreads(k)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(threads_mod, "MIN_ROWS", 8)
        got = sensor.scan(*scan_args)
    for a, b in zip(ref, (got.distance, got.hit_kind, got.hit_id)):
        np.testing.assert_array_equal(a, b)


@given(seed=st.integers(0, 10_000), k=st.integers(2, 5), n_worlds=st.integers(1, 3))
@settings(max_examples=40, deadline=None)
def test_the_range_graph_does_not_depend_on_the_thread_count(seed: int, k: int, n_worlds: int) -> None:
    # Crowded worlds, ranges that differ per slot and some offline slots: the links (their rows and the one
    # output's layout, which the overlay reads in order) and the nearest neighbours of every thread count.
    rng = np.random.default_rng(seed)
    s = 150
    pos = np.column_stack([rng.uniform(0, 40, (s, 2)), rng.uniform(0, 6, s)])
    online = rng.random(s) < 0.9
    world = rng.integers(0, n_worlds, s)
    link_range = rng.uniform(2.0, 12.0, s)
    grid = build_grid(GridSpec.for_bounds((0, 40, 0, 40), 5.0, n_worlds), pos, world, online)

    def graph(threads: int) -> tuple[np.ndarray, ...]:
        g = RangeGraph(s, 8.0, 6.0)
        g.threads = RowThreads(threads)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(threads_mod, "MIN_ROWS", 4)
            g.set_grid(grid, pos, online, world, link_range, True)
            start, end, indices = g.links(link_range)
            return start.copy(), end.copy(), indices[: int(end.max(initial=0))].copy(), g.nearest().copy()

    one, many = graph(1), graph(k)
    assert one[2].size > 0
    for a, b in zip(one, many):
        np.testing.assert_array_equal(a, b)


@given(seed=st.integers(0, 10_000), k=st.integers(2, 5))
@settings(max_examples=30, deadline=None)
def test_overlay_hops_and_inbox_pushes_do_not_depend_on_the_thread_count(seed: int, k: int) -> None:
    # Floods started over several steps on a random graph (hop limits 1-4, some slots offline), each hop's
    # deliveries pushed into small inboxes: every delivery field in order, the counters, and the inboxes.
    rng = np.random.default_rng(seed)
    s, d = 120, 3
    pos = np.column_stack([rng.uniform(0, 30, (s, 2)), rng.uniform(0, 3, s)])
    online = rng.random(s) < 0.9
    world = np.zeros(s, dtype=np.int64)
    grid = build_grid(GridSpec.for_bounds((0, 30, 0, 30), 5.0, 1), pos, world, online)
    starts = [(rng.choice(np.flatnonzero(online), rng.integers(1, 30)), rng.integers(1, 5, 30)) for _ in range(6)]

    def run(threads: int) -> list[np.ndarray]:
        ov = Overlay(s, d, 7.0)
        inbox = Inbox(s, 3, d)
        graph = RangeGraph(s, 7.0, 7.0)
        ov.threads = inbox.threads = graph.threads = RowThreads(threads)
        out: list[np.ndarray] = []
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(threads_mod, "MIN_ROWS", 2)
            for step, (origin, limit) in enumerate(starts):
                origin = np.sort(origin)
                ov.start(origin, limit[: origin.size], np.full((origin.size, d), step, np.float32), step)
                graph.set_grid(grid, pos, online, world, ov.link_range, True)
                got = ov.advance_graph(*graph.links(ov.link_range))
                inbox.push_rows(
                    got.receiver,
                    np.full(len(got), 3, np.int8),
                    got.origin,
                    got.hops,
                    got.created,
                    got.payload,
                    np.zeros(0, dtype=np.int64),
                )
                st_ = ov.stats
                out += [
                    got.receiver,
                    got.flood,
                    got.origin,
                    got.hops,
                    got.created,
                    got.payload,
                    np.array([st_.started, st_.delivered, st_.duplicates, st_.finished, ov.frontier_size]),
                ]
            out += [
                inbox.valid,
                inbox.sender,
                inbox.hops,
                inbox.created,
                inbox.payload,
                inbox.received,
                inbox.observe(pos, len(starts)),
            ]
        return out

    one, many = run(1), run(k)
    assert sum(len(a) for a in one[::7]) > 0  # floods did reach someone
    for i, (a, b) in enumerate(zip(one, many)):
        np.testing.assert_array_equal(a, b, err_msg=f"array {i} differs with {k} threads")


@given(
    sizes=st.lists(st.integers(1, 40), min_size=0, max_size=60),
    k=st.integers(1, 6),
    min_rows=st.integers(1, 50),
    weights=st.one_of(st.none(), st.lists(st.integers(1, 100), min_size=2400, max_size=2400)),
)
@settings(max_examples=200, deadline=None)
def test_flood_ranges_cut_the_frontier_only_between_floods(
    sizes: list[int], k: int, min_rows: int, weights: list[int] | None
) -> None:
    # a frontier grouped by flood (runs of one flood id): contiguous ranges over every entry, at most one per
    # thread, each boundary at the first entry of a flood; by entries, or by a cumulative cost per entry
    cur_f = np.repeat(np.arange(len(sizes)) * 3 + 1, sizes).astype(np.int64)
    cost = None if weights is None else np.cumsum(weights[: cur_f.shape[0]]).astype(np.int64)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(threads_mod, "MIN_ROWS", min_rows)
        ranges = flood_ranges(cur_f, RowThreads(k), cost)
    n = cur_f.shape[0]
    assert ranges == [] if n == 0 else (ranges[0][0] == 0 and ranges[-1][1] == n)
    assert len(ranges) <= k and all(lo < hi for lo, hi in ranges)
    assert all(a[1] == b[0] for a, b in zip(ranges, ranges[1:]))
    assert all(cur_f[lo] != cur_f[lo - 1] for lo, _ in ranges[1:])


def test_make_and_batched_env_take_the_thread_count() -> None:
    env = agentsim_env.make("navigation", n_agents=4, num_threads=2)
    assert env.world.threads.num_threads == 2
    b = BatchedEnv("navigation", 1, n_agents=4, num_threads=3)
    assert b.world.threads.num_threads == 3
    scan = next(s for s in b.world.sensors if s.name == "proximity")
    assert scan.threads is b.world.threads  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--threads", "0"], "--threads must be an integer in [1, 256]"),
        (["--threads", "2", "--shards", "2"], "--threads applies to one process"),
    ],
)
def test_cli_run_threads_bad_options(argv: list[str], match: str, capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    assert main(["run", "navigation", "--episodes", "1", "--out", "", "--quiet", *argv]) == 2
    assert match in capsys.readouterr().err


def test_cli_run_with_threads_prints_what_one_thread_prints(capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    base = ["run", "navigation", "--episodes", "2", "--out", "", "--set", "n_agents=6"]
    outs = []
    for k in ("1", "2"):
        assert main([*base, "--threads", k]) == 0
        # every line but the timing rows (steps per second differ from run to run)
        outs.append([x for x in capsys.readouterr().out.splitlines() if "steps/s" not in x])
    assert outs[0] == outs[1] and any("mean return" in x for x in outs[0])


def _inbox_state(inbox: Inbox) -> list[np.ndarray]:
    return [inbox.valid, inbox.kind, inbox.sender, inbox.hops, inbox.created, inbox.payload, inbox.received]


@given(seed=st.integers(0, 10_000), k=st.integers(2, 7), steps=st.integers(1, 4))
@settings(max_examples=40, deadline=None)
def test_inbox_pushes_do_not_depend_on_the_thread_count(seed: int, k: int, steps: int) -> None:
    # Two or three batches a step in every form the producers hand (a table of flood rows with per-row sender and
    # created step, one kind or hop count for all as a stride-0 broadcast, int16/int32/int64 hops beyond the int16
    # range, receivers < 0 skipped); with 4 or more ranges every range counts its own receivers (the scan path).
    rng = np.random.default_rng(seed)
    s, m, d = 37, 3, 2
    one, many = Inbox(s, m, d), Inbox(s, m, d)
    many.threads = RowThreads(k)
    for step in range(steps):
        batches = []
        for form in range(int(rng.integers(1, 4))):
            n = int(rng.integers(0, 90))
            recv = rng.integers(-3, s, n)
            hops: np.ndarray = rng.integers(-5, 70_000, n)
            if form == 0:  # the bus: one hop count for all, as a broadcast
                hops = np.broadcast_to(np.zeros(1, np.int16), (n,))
            elif form == 1:
                hops = hops.astype(np.int32)
            if form == 2:  # the overlay: sender and created read from a table by row, one kind for all
                table = int(rng.integers(1, 6))
                batches.append(
                    (
                        recv,
                        np.broadcast_to(np.int8(5), (n,)),
                        rng.integers(0, s, table),
                        hops,
                        rng.integers(0, 9, table),
                        rng.random((table, d), dtype=np.float32),
                        rng.integers(0, table, n),
                        True,
                    )
                )
            else:
                batches.append(
                    (
                        recv,
                        rng.integers(1, 5, n).astype(np.int8),
                        rng.integers(-1, s, n),
                        hops,
                        np.full(n, step),
                        rng.random((n, d), dtype=np.float32),
                        SAME_ROWS,
                    )
                )
        one.push_batches(batches)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(threads_mod, "MIN_ROWS", 4)
            many.push_batches(batches)
        for i, (a, b) in enumerate(zip(_inbox_state(one), _inbox_state(many))):
            np.testing.assert_array_equal(a, b, err_msg=f"{k} threads, step {step}: inbox array {i} differs")
    assert one.hops.max() <= np.iinfo(np.int16).max and one.hops.min() >= 0


@given(seed=st.integers(0, 10_000), k=st.integers(2, 6))
@settings(max_examples=40, deadline=None)
def test_bus_fan_out_and_filters_do_not_depend_on_the_thread_count(seed: int, k: int) -> None:
    # A batch of unicasts, GROUP messages (members on and offline, the sender among them), heartbeat answers to the
    # controller (receiver -1), with a range limit, senders the caller has not seen and loss: pairs, their order,
    # delivered and dropped columns, tallies and drop counters equal the one-pass kernels'.
    from agentsim_env.comms.messages import AGENT, GROUP, HEARTBEAT
    from agentsim_env.comms.routing import expand, expand_on, filter_pairs, filter_pairs_on, group_members

    rng = np.random.default_rng(seed)
    s, q, n_g = 60, int(rng.integers(0, 70)), 4
    online = rng.random(s) < 0.85
    group = rng.integers(-1, n_g, s)
    world_of = np.zeros(s, dtype=np.int64)
    kind = rng.choice(np.array([AGENT, GROUP, HEARTBEAT], dtype=np.int8), q)
    snd = rng.integers(-1, s, q)
    tgt = np.where(kind == GROUP, rng.integers(0, n_g, q), rng.integers(-1, s, q))
    kid, offsets, slots = group_members(online, group, world_of, 1, n_g, np.where(kind == GROUP, tgt, -1))
    order = rng.permutation(q) if rng.random() < 0.5 else np.zeros(0, dtype=np.int64)
    one = expand(kind, snd, tgt, kid, offsets, slots, order)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(threads_mod, "MIN_ROWS", 2)
        many = expand_on(RowThreads(k), kind, snd, tgt, kid, offsets, slots, order)
        for a, b in zip(one, many):
            np.testing.assert_array_equal(a, b)
        rep, recv = one
        m = rep.shape[0]
        msg, created = np.arange(q, dtype=np.int64) + 100, rng.integers(0, 9, q)
        pos = rng.uniform(0, 30, (s, 3))
        seen = rng.random(s) < 0.9 if rng.random() < 0.5 else np.zeros(0, dtype=bool)
        u = rng.random(m) if m else np.zeros(0)
        args = (rep, recv, msg, kind, snd, tgt, created, online, seen, pos, 15.0**2, u, 0.2)
        d1, d2 = np.zeros(s, dtype=np.int64), np.zeros(s, dtype=np.int64)
        ok1, dr1, hb1, an1 = filter_pairs(*args, d1)
        ok2, dr2, hb2, an2 = filter_pairs_on(RowThreads(k), *args, d2)
    for a, b in zip(ok1 + dr1, ok2 + dr2):
        np.testing.assert_array_equal(a, b)
    assert (hb1, an1) == (hb2, an2)
    np.testing.assert_array_equal(d1, d2)
