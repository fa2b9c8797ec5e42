"""World pipeline, batched stepping, scene placement and collisions (unit and property tests)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import agentsim_env
from agentsim_env.core.collisions import find_collisions
from agentsim_env.core.scene import BOX, CYLINDER, SPHERE, Scene
from agentsim_env.core.spatial import GridSpec, build_grid, build_object_grid, neighbor_pairs
from agentsim_env.env.vector import BatchedEnv


def _collide_brute(pos, radius, online, world, scene):  # type: ignore[no-untyped-def]
    """Plain reference: every pair and every (agent, object) checked directly."""
    out = set()
    n = len(pos)
    for i in range(n):
        for j in range(n):
            if i != j and online[i] and online[j] and world[i] == world[j]:
                if np.linalg.norm(pos[i] - pos[j]) < radius[i] + radius[j]:
                    out.add((i, j, -1))
        for o in range(scene.n_objects):
            if not online[i] or scene.world[o] != world[i]:
                continue
            c, h = scene.centre[o], scene.half[o]
            if scene.kind[o] == BOX:
                d = np.linalg.norm(np.maximum(np.abs(pos[i] - c) - h, 0))
            elif scene.kind[o] == CYLINDER:
                dr = max(np.hypot(*(pos[i, :2] - c[:2])) - h[0], 0)
                d = np.hypot(dr, max(abs(pos[i, 2] - c[2]) - h[2], 0))
            else:
                d = max(np.linalg.norm(pos[i] - c) - h[0], 0)
            if d < radius[i]:
                out.add((i, -1, o))
    return out


@given(st.integers(0, 10_000), st.integers(2, 40), st.integers(1, 3))
def test_collisions_match_brute_force(seed: int, n: int, n_worlds: int) -> None:
    rng = np.random.default_rng(seed)
    s = n * n_worlds
    pos = np.column_stack([rng.uniform(-5, 35, (s, 2)), rng.uniform(0, 6, s)])
    radius = rng.uniform(0.3, 2.0, s)
    online = rng.random(s) > 0.2
    world = np.repeat(np.arange(n_worlds, dtype=np.int32), n)
    scene = Scene()
    k = rng.integers(0, 3, 6)
    scene.add(
        k,
        np.column_stack([rng.uniform(0, 30, (6, 2)), rng.uniform(0, 4, 6)]),
        rng.uniform(0.5, 3.0, (6, 3)),
        rng.integers(0, n_worlds, 6),
    )
    spec = GridSpec.for_bounds((0, 30, 0, 30), 3.0, n_worlds)
    grid = build_grid(spec, pos, world, online)
    og = build_object_grid(spec, scene.centre, scene.footprint_radius(), scene.world)
    ev = find_collisions(pos, radius, online, world, grid, scene.kind, scene.centre, scene.half, scene.world, og)
    got = set(zip(ev.agent.tolist(), ev.other_agent.tolist(), ev.obj.tolist()))
    assert got == _collide_brute(pos, radius, online, world, scene)
    assert len(got) == len(ev)  # no duplicate rows


@given(st.integers(0, 10_000), st.floats(0.5, 20.0))
def test_neighbor_pairs_symmetric_and_complete(seed: int, r: float) -> None:
    rng = np.random.default_rng(seed)
    pos = np.column_stack([rng.uniform(0, 50, (60, 2)), rng.uniform(0, 3, 60)])
    world = np.zeros(60, dtype=np.int32)
    spec = GridSpec.for_bounds((0, 50, 0, 50), 4.0, 1)
    i, j, d = neighbor_pairs(build_grid(spec, pos, world, np.ones(60, bool)), pos, world, r)
    full = np.linalg.norm(pos[:, None] - pos[None], axis=2)
    exp = {(a, b) for a in range(60) for b in range(a + 1, 60) if full[a, b] <= r}
    assert set(zip(i.tolist(), j.tolist())) == exp
    np.testing.assert_allclose(d, full[i, j])


def test_scene_random_placement_no_overlap_and_runtime_add() -> None:
    sc = Scene()
    ids = sc.place_random(
        np.random.default_rng(0),
        15,
        (0, 100, 0, 100),
        keep_clear=np.array([[50.0, 50.0]]),
        keep_clear_radius=5.0,
    )
    assert len(ids) == 15
    fr = sc.footprint_radius()
    d = np.linalg.norm(sc.centre[:, None, :2] - sc.centre[None, :, :2], axis=2)
    np.fill_diagonal(d, np.inf)
    assert np.all(d >= fr[:, None] + fr[None, :])
    assert np.all(np.linalg.norm(sc.centre[:, :2] - 50.0, axis=1) >= fr + 5.0)
    again = Scene()
    again.place_random(
        np.random.default_rng(0),
        15,
        (0, 100, 0, 100),
        keep_clear=np.array([[50.0, 50.0]]),
        keep_clear_radius=5.0,
    )
    np.testing.assert_array_equal(sc.centre, again.centre)
    v = sc.version
    new = sc.add("sphere", [[10.0, 10.0, 3.0]], [[2.0, 1.0, 1.0]])
    assert sc.version == v + 1 and sc.kind[new[0]] == SPHERE and np.all(sc.half[new[0]] == 2.0)
    with pytest.raises(ValueError, match="kind"):
        sc.add("cone", [[0, 0, 0]], [[1, 1, 1]])
    with pytest.raises(ValueError, match="half"):
        sc.add("box", [[0, 0, 0]], [[1, -1, 1]])


@given(st.lists(st.integers(0, 4), min_size=1, max_size=30), st.data())
def test_object_index_in_world_counts_its_world_only(worlds: list[int], data: st.DataObject) -> None:
    sc = Scene()
    for w in worlds:  # interleaved worlds, as automatic resets of a batch leave them
        sc.add("box", [[0.0, 0.0, 1.0]], [[1.0, 1.0, 1.0]], world=w)
    ids = np.array(data.draw(st.lists(st.integers(-1, len(worlds) - 1), max_size=10)), dtype=np.int64)
    want = [-1 if i < 0 else worlds[:i].count(worlds[i]) for i in ids.tolist()]
    assert sc.index_in_world(ids).tolist() == want


def test_runtime_obstacle_ends_agent_with_object_id() -> None:
    env = agentsim_env.make("navigation", n_agents=2, obstacle_density=0.0)
    env.reset(seed=0)
    p = env.world.state.pos[0].copy()
    oid = env.world.scene.add("box", [p + [0.0, 0.0, 0.0]], [[1.0, 1.0, 1.0]])[0]
    acts = {a: {"motion": np.zeros(3, np.float32)} for a in env.agents}
    _, rew, term, _, _ = env.step(acts)
    assert term["agent_0"] and not term["agent_1"]
    ev = env.world.last_events.collisions
    assert ev.obj[ev.agent == 0].tolist() == [oid]
    assert rew["agent_0"] < -5


def test_collisions_switch_off() -> None:
    env = agentsim_env.make("navigation", n_agents=2, collisions=False)
    env.reset(seed=0)
    env.world.state.pos[0] = env.world.state.pos[1]
    _, _, term, _, _ = env.step({a: {"motion": np.zeros(3, np.float32)} for a in env.agents})
    assert not any(term.values())


def test_batched_env_matches_single_env_and_autoresets() -> None:
    b = BatchedEnv("navigation", 3, n_agents=4, max_steps=30)
    obs = b.reset(seed=5)
    assert obs.shape == (3, 4, b.obs_dim) and obs.dtype == np.float32
    rng = np.random.default_rng(0)
    resets = 0
    for _ in range(70):
        out = b.step(rng.uniform(-1, 1, (3, 4, b.act_dim)))
        assert out.rewards.shape == (3, 4) and np.isfinite(out.obs).all()
        resets += int(out.reset_worlds.sum())
    assert resets >= 3  # every world hit the 30-step limit at least once
    # world w of a batch reset with seed s starts like a single env reset with seed s (here s = 5 + w)
    single = BatchedEnv("navigation", 1, n_agents=4)
    b2 = BatchedEnv("navigation", 3, n_agents=4)
    o2 = b2.reset(seed=5)
    np.testing.assert_array_equal(o2[1], single.reset(seed=6)[0])
    with pytest.raises(ValueError, match="world 0, agent 1"):
        bad = np.zeros((3, 4, b.act_dim))
        bad[0, 1, 0] = np.nan
        b2.step(bad)
    with pytest.raises(ValueError, match="shape"):
        b2.step(np.zeros((3, 4)))
