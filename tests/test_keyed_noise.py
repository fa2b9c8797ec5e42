"""Keyed random numbers (``core.keyed``) and the GNSS noise drawn from them: a reading is a function of the
world's episode key, the tick and the slot, never of which slots or how many draws a process made before."""

from __future__ import annotations

import numpy as np
import pytest

import agentsim_env
from agentsim_env.core.keyed import keyed_bits, keyed_normal, keyed_uniform
from agentsim_env.scenarios.base import reset_worlds, run_step


def test_keyed_draws_are_pure_functions_of_their_words() -> None:
    slots = np.arange(1000)
    a = keyed_uniform(7, 3, slots)
    b = keyed_uniform(7, 3, slots[::-1])[::-1]  # another order, the same numbers
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a[250:300], keyed_uniform(7, 3, slots[250:300]))  # a subset draws its own rows
    assert keyed_uniform(7, 3, 5) == a[5]
    assert not np.array_equal(a, keyed_uniform(8, 3, slots))  # the key matters
    assert not np.array_equal(a, keyed_uniform(7, 4, slots))  # and every word
    assert len(np.unique(keyed_bits(7, 3, slots))) == slots.size
    # words broadcast: (key per row) x (axis per column)
    keys = np.array([1, 2], dtype=np.uint64)
    grid = keyed_normal(keys[:, None], 9, np.arange(3))
    assert grid.shape == (2, 3) and grid[1, 2] == keyed_normal(2, 9, 2)


def test_keyed_uniform_and_normal_have_their_distributions() -> None:
    u = keyed_uniform(123, np.arange(200_000))
    assert u.min() >= 0.0 and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 0.005 and abs(u.var() - 1 / 12) < 0.002
    z = keyed_normal(123, np.arange(200_000))
    assert np.isfinite(z).all() and abs(z.mean()) < 0.01 and abs(z.std() - 1.0) < 0.01
    assert abs(np.mean(np.abs(z) < 1.0) - 0.6827) < 0.005


def test_keyed_words_must_be_integers() -> None:
    with pytest.raises(TypeError, match="integer"):
        keyed_uniform(1, np.array([0.5]))


def _gnss_world(n_agents: int = 6):
    scenario = agentsim_env.make("navigation", n_agents=n_agents, gnss={"sigma_h": 2.0, "sigma_v": 1.0}).scenario
    world = scenario.build(1)
    reset_worlds(scenario, world, [0], [np.random.SeedSequence(11)])
    return scenario, world


def _steps(scenario, world, k: int, refresh_at: int | None = None) -> np.ndarray:
    acting = np.ones(world.state.n_slots, dtype=bool)
    parts = {"motion": np.full((world.state.n_slots, 3), 0.3)}
    for i in range(k):
        run_step(scenario, world, parts, acting & world.state.online)
        if i == refresh_at:
            world.refresh()
    return world.readings["gnss"]


def test_gnss_noise_does_not_depend_on_how_many_draws_came_before() -> None:
    """Re-reading the world between steps (a shard rebuilding its readings) leaves later readings unchanged."""
    sa, wa = _gnss_world()
    sb, wb = _gnss_world()
    np.testing.assert_array_equal(_steps(sa, wa, 4), _steps(sb, wb, 4, refresh_at=1))


def test_gnss_rereading_the_same_state_gives_the_same_reading() -> None:
    scenario, world = _gnss_world()
    before = _steps(scenario, world, 2).copy()
    world.refresh()
    np.testing.assert_array_equal(world.readings["gnss"], before)


def test_gnss_noise_of_a_slot_is_its_keyed_draw() -> None:
    """The error of agent i on axis a after the episode's step t is keyed_normal(episode key, t, i, a) x sigma,
    whichever other slots are online."""
    scenario, world = _gnss_world()
    sensor = next(s for s in world.sensors if s.name == "gnss")
    world.set_offline(np.array([1, 4]))
    reading = _steps(scenario, world, 3)
    live = np.flatnonzero(world.state.online)
    assert np.isnan(reading[[1, 4]]).all()
    key = sensor._keys[0]
    want = world.state.pos[live] + keyed_normal(key, 3, live[:, None], np.arange(3)) * [2.0, 2.0, 1.0]
    np.testing.assert_array_equal(reading[live], want)


def test_gnss_reset_after_steps_reads_like_a_fresh_world() -> None:
    """The noise is keyed by the step within the episode, not the world's global tick: an env reset after some
    steps replays a fresh env with the same seed (and a batch world reset late replays world 0)."""
    used = agentsim_env.make("navigation", n_agents=4, gnss={})
    used.reset(seed=2)
    for _ in range(5):
        used.step({a: used.action_space(a).sample() for a in used.agents})
    fresh = agentsim_env.make("navigation", n_agents=4, gnss={})
    obs_u, _ = used.reset(seed=9)
    obs_f, _ = fresh.reset(seed=9)
    for a in obs_f:
        np.testing.assert_array_equal(obs_u[a]["gnss"], obs_f[a]["gnss"])
    act = {a: {"motion": np.full(3, 0.2)} for a in fresh.agents}
    obs_u, *_ = used.step(act)
    obs_f, *_ = fresh.step(act)
    for a in obs_f:
        np.testing.assert_array_equal(obs_u[a]["gnss"], obs_f[a]["gnss"])
