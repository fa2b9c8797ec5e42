"""``Scenario.observation_rows`` and ``flat_observation_rows`` (what a shard computes for its own agents) give
exactly the rows of ``Scenario.observation`` and ``flat_observation`` (every slot), for every scenario and for the
inbox and sensor parts."""

from __future__ import annotations

import numpy as np
import pytest

import agentsim_env

CASES = [
    ("navigation", {"n_agents": 60}),
    ("navigation", {"n_agents": 60, "comms": {"loss": 0.2}, "gnss": {"sigma_h": 1.0}}),
    ("navigation", {"n_agents": 60, "comms": {"loss": 0.2}}),
    ("relay", {"n_groups": 3, "group_size": 4}),
    ("rendezvous", {}),
    ("uav_release", {}),
]


@pytest.mark.parametrize(("name", "config"), CASES, ids=[f"{n}-{i}" for i, (n, _) in enumerate(CASES)])
def test_observation_rows_equal_the_rows_of_every_slot(name: str, config: dict) -> None:
    env = agentsim_env.make(name, **config)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for a in env.agents:
        env.action_space(a).seed(int(rng.integers(1 << 30)))
    for _ in range(6):
        if not env.agents:
            break
        env.step({a: env.action_space(a).sample() for a in env.agents})
    sc, world = env.scenario, env.world
    full = sc.observation(world)
    for rows in (
        np.arange(world.state.n_slots),
        np.arange(1, world.state.n_slots, 3),
        np.zeros(0, dtype=np.int64),
    ):
        part = sc.observation_rows(world, rows)
        assert list(part) == list(full)  # the flat layout's order
        for k, v in full.items():
            assert part[k].shape == (rows.size, *v.shape[1:]), k
            np.testing.assert_array_equal(part[k], v[rows], err_msg=k)
        # the flat rows (a shard's step API writes them straight into its shared rows), fresh or into a wider
        # array's columns (any row stride)
        flat = sc.flat_observation(world)
        np.testing.assert_array_equal(sc.flat_observation_rows(world, rows), flat[rows])
        wide = np.full((rows.size, flat.shape[1] + 5), np.nan, dtype=np.float32)
        sc.flat_observation_rows(world, rows, wide[:, 2 : 2 + flat.shape[1]])
        np.testing.assert_array_equal(wide[:, 2 : 2 + flat.shape[1]], flat[rows])
        assert np.isnan(wide[:, :2]).all() and np.isnan(wide[:, 2 + flat.shape[1] :]).all()
        # at given rows of an array of every slot's row (the shared array a shard fills at its slots' rows); the
        # other rows untouched
        every = np.full((world.state.n_slots, flat.shape[1]), np.nan, dtype=np.float32)
        assert sc.flat_observation_rows(world, rows, every, at=rows) is every
        np.testing.assert_array_equal(every[rows], flat[rows])
        rest = np.setdiff1d(np.arange(world.state.n_slots), rows)
        assert np.isnan(every[rest]).all()
    if world.comms is not None:
        assert world.comms.bus.inbox.valid.any(), "no message arrived: the inbox rows would not be checked"


@pytest.mark.parametrize(
    ("out", "at", "match"),
    [
        (None, [0, 1], "at needs out"),
        (np.zeros((10, 3), dtype=np.float32), [0, 1], "out must be a writable float32 array"),
        ("f64", [0, 1], "out must be a writable float32 array"),
        ("frozen", [0, 1], "out must be a writable float32 array"),
        ("ok", [0], "at must give each of the 2 slots a row of out"),
        ("ok", [0, 10], "at must give each of the 2 slots a row of out in \\[0, 10\\)"),
        ("ok", [-1, 3], "at must give each"),
    ],
)
@pytest.mark.parametrize(("name", "config"), [CASES[0], CASES[2], CASES[3]], ids=["nav", "nav-comms", "relay"])
def test_flat_rows_at_bad_rows_are_refused_by_name(name: str, config: dict, out: object, at: list, match: str) -> None:
    env = agentsim_env.make(name, **config)
    env.reset(seed=0)
    sc, world = env.scenario, env.world
    width = sc.flat_observation(world).shape[1]
    arrays = {
        "ok": np.zeros((10, width), dtype=np.float32),
        "f64": np.zeros((10, width), dtype=np.float64),
        "frozen": np.zeros((10, width), dtype=np.float32),
    }
    arrays["frozen"].flags.writeable = False
    target = arrays.get(out, out) if isinstance(out, str) else out
    with pytest.raises(ValueError, match=match):
        sc.flat_observation_rows(world, np.array([1, 2]), target, at=np.array(at))
