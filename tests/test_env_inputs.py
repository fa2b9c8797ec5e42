"""Bad inputs raise ValueError naming the agent or field, and the env keeps working afterwards."""

from __future__ import annotations

import numpy as np
import pytest

import agentsim_env


def _env(**kw):  # type: ignore[no-untyped-def]
    env = agentsim_env.make("navigation", **kw)
    env.reset(seed=0)
    return env


def _good(env):  # type: ignore[no-untyped-def]
    return {a: env.action_space(a).sample() for a in env.agents}


@pytest.mark.parametrize("fmt", ["dict", "flat"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_action_names_agent(fmt: str, bad: float) -> None:
    env = _env(action_format=fmt)
    before = env.world.state.pos.copy()
    acts = _good(env)
    if fmt == "dict":
        acts["agent_2"]["motion"][1] = bad
    else:
        acts["agent_2"][1] = bad
    with pytest.raises(ValueError, match="agent_2"):
        env.step(acts)
    np.testing.assert_array_equal(env.world.state.pos, before)  # nothing moved
    env.step(_good(env))  # still works


@pytest.mark.parametrize("fmt", ["dict", "flat"])
def test_wrong_shape_names_agent(fmt: str) -> None:
    env = _env(action_format=fmt)
    acts = _good(env)
    acts["agent_1"] = {"motion": np.zeros(5)} if fmt == "dict" else np.zeros(7)
    with pytest.raises(ValueError, match="agent_1.*shape|shape.*agent_1"):
        env.step(acts)
    env.step(_good(env))


def test_unknown_missing_and_dead_agents() -> None:
    env = _env()
    acts = _good(env)
    acts["uav_99"] = acts["agent_0"]
    with pytest.raises(ValueError, match="uav_99"):
        env.step(acts)
    acts = _good(env)
    del acts["agent_3"]
    with pytest.raises(ValueError, match="agent_3"):
        env.step(acts)
    # kill agent_0 by collision: place it inside agent_1
    env.world.state.pos[0] = env.world.state.pos[1]
    _, _, term, _, _ = env.step(_good(env))
    assert term["agent_0"] and "agent_0" not in env.agents
    assert term["agent_1"]  # both agents of an agent-agent collision end
    # actions for agents that ended earlier in the episode are accepted and ignored (TorchRL, BenchMARL)
    acts = _good(env)
    acts["agent_0"] = acts["agent_2"]
    acts["agent_1"] = acts["agent_2"]
    before = env.world.state.pos[:2].copy()
    obs, *_ = env.step(acts)
    assert "agent_0" not in obs and "agent_0" not in env.agents
    np.testing.assert_array_equal(env.world.state.pos[:2], before)  # the ended agents did not move
    acts = _good(env)
    acts["agent_9"] = acts["agent_2"]
    with pytest.raises(ValueError, match="agent_9"):  # an unknown id stays an error naming it
        env.step(acts)
    env.step(_good(env))


def test_dict_action_parts_checked() -> None:
    env = _env()
    acts = _good(env)
    acts["agent_0"] = {"move": np.zeros(3)}
    with pytest.raises(ValueError, match="agent_0.*motion|motion.*agent_0"):
        env.step(acts)


@pytest.mark.parametrize(
    ("key", "value", "field"),
    [
        ("n_agents", 0, "n_agents"),
        ("n_agents", 2.5, "n_agents"),
        ("n_groups", 9, "n_groups"),
        ("max_speed", -1.0, "max_speed"),
        ("dt", float("nan"), "dt"),
        ("action_mode", "teleport", "action_mode"),
        ("physics", "bullet", "physics"),
        ("altitude", (10.0, 2.0), "altitude"),
        ("reward", {"group_share": -1.0}, "group_share"),
        ("reward", {"bonus": 1.0}, "bonus"),
        ("obs_format", "image", "obs_format"),
        ("render_mode", "ascii", "render_mode"),
        ("colour", "red", "colour"),
    ],
)
def test_bad_config_names_field(key: str, value: object, field: str) -> None:
    with pytest.raises(ValueError, match=field):
        agentsim_env.make("navigation", **{key: value})


def test_unknown_scenario_lists_known() -> None:
    with pytest.raises(ValueError, match="navigation"):
        agentsim_env.make("nope")


def test_terminated_once_then_gone_and_truncation() -> None:
    env = _env(max_steps=5)
    seen_term: dict[str, int] = {}
    steps = 0
    while env.agents:
        _, _, term, trunc, _ = env.step(_good(env))
        steps += 1
        for a, t in term.items():
            seen_term[a] = seen_term.get(a, 0) + int(t)
        assert set(term) == set(trunc)
    assert steps <= 5 and all(v <= 1 for v in seen_term.values())
    assert env.step({}) == ({}, {}, {}, {}, {})


def test_observations_in_space_and_fresh() -> None:
    env = _env(obs_format="flat")
    obs, *_ = env.step(_good(env))
    for a, o in obs.items():
        assert env.observation_space(a).contains(o)
    o0 = obs["agent_0"].copy()
    env.step(_good(env))
    np.testing.assert_array_equal(obs["agent_0"], o0)  # returned arrays are not views of live state
