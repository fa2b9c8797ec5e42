"""Communication through the env: comm actions, ENV collision messages, heartbeats, the code API, events."""

from __future__ import annotations

import numpy as np
import pytest

import agentsim_env
from agentsim_env.comms.messages import AGENT, ENV, ENV_COLLISION_OBJECT, FEATURES_PER_MESSAGE, GROUP, OVERLAY

KIND_COL = {AGENT: 1, GROUP: 2, ENV: 3, OVERLAY: 4}  # one-hot column of each kind in an inbox row


def _env(**comms):  # type: ignore[no-untyped-def]
    env = agentsim_env.make("navigation", n_agents=6, n_groups=2, obstacle_density=0.0, comms=comms)
    env.reset(seed=1)
    return env


def _idle(env, **over):  # type: ignore[no-untyped-def]
    d = env.scenario.config.comms.action_dim
    acts = {a: {"motion": np.zeros(3, np.float32), "comm": np.full(d, -1.0, np.float32)} for a in env.agents}
    acts.update(over)
    return acts


def _comm(env, channel: int, receiver: int = 0, hops: int = 1, payload=(0.5, -0.5, 0.25, 0.0)):  # type: ignore[no-untyped-def]
    n, cfg = env.scenario.n_agents, env.scenario.config.comms
    a = np.zeros(cfg.action_dim, np.float32)
    a[0] = -1.0 + (channel + 0.5) * 2.0 / 5.0
    a[1] = receiver / (n - 1) * 2.0 - 1.0
    a[2] = (hops - 1) / (cfg.max_hops - 1) * 2.0 - 1.0
    a[3:] = payload
    return {"motion": np.zeros(3, np.float32), "comm": a}


def _rows(obs, agent):  # type: ignore[no-untyped-def]
    inbox = obs[agent]["inbox"]
    return inbox[inbox[:, 0] > 0]


def test_named_unicast_arrives_with_payload_and_kind() -> None:
    env = _env()
    obs, *_ = env.step(_idle(env, agent_0=_comm(env, 3, receiver=4)))
    rows = _rows(obs, "agent_4")
    assert len(rows) == 1 and rows[0, KIND_COL[AGENT]] == 1.0
    np.testing.assert_allclose(rows[0, FEATURES_PER_MESSAGE:], [0.5, -0.5, 0.25, 0.0])
    assert all(len(_rows(obs, a)) == 0 for a in env.agents if a != "agent_4")
    assert obs["agent_4"]["comms"][0] > 0  # received counter


def test_group_message_reaches_group_only() -> None:
    env = _env()
    obs, *_ = env.step(_idle(env, agent_0=_comm(env, 1)))
    group = env.world.state.group
    for i, a in enumerate(env.possible_agents):
        got = len(_rows(obs, a))
        assert got == (1 if (group[i] == group[0] and i != 0) else 0), a


def test_overlay_flood_relays_beyond_range() -> None:
    env = _env(overlay_range=12.0, max_hops=6)
    st = env.world.state
    st.pos[:, :2] = np.column_stack([10.0 + 10.0 * np.arange(6), np.full(6, 30.0)])  # a line, 10 m apart
    st.pos[:, 2] = 5.0
    env.world.refresh()
    seen = set()
    acts = _idle(env, agent_0=_comm(env, 4, hops=6))
    for k in range(6):
        obs, *_ = env.step(acts)
        acts = _idle(env)
        for a in env.possible_agents:
            rows = _rows(obs, a)
            if len(rows) and (rows[:, KIND_COL[OVERLAY]] == 1).any():
                seen.add(a)
        if k == 0:
            assert seen == {"agent_1"}  # one hop per step
    assert seen == {f"agent_{i}" for i in range(1, 6)}


def test_collision_env_message_names_object() -> None:
    env = _env()
    p = env.world.state.pos[2].copy()
    oid = int(env.world.scene.add("cylinder", [p], [[1.0, 1.0, 2.0]])[0])
    obs, _, term, *_ = env.step(_idle(env))
    assert term["agent_2"]
    rows = _rows(obs, "agent_2")
    env_rows = rows[rows[:, KIND_COL[ENV]] == 1]
    assert len(env_rows) == 1
    assert env_rows[0, FEATURES_PER_MESSAGE] == ENV_COLLISION_OBJECT and env_rows[0, FEATURES_PER_MESSAGE + 1] == oid


def test_heartbeat_timeouts_on_dead_channel() -> None:
    env = _env(loss=1.0, heartbeat_period=2, heartbeat_timeout=4)
    ended = {}
    for t in range(12):
        _, _, term, *_ = env.step(_idle(env))
        for a, v in term.items():
            if v:
                ended[a] = t
    assert set(ended) == set(env.possible_agents) and max(ended.values()) <= 6


def test_heartbeats_keep_agents_on_clean_channel() -> None:
    env = _env(heartbeat_period=2, heartbeat_timeout=4)
    for _ in range(30):
        _, _, term, *_ = env.step(_idle(env))
        assert not any(term.values())


def test_message_cost_and_events() -> None:
    env = agentsim_env.make(
        "navigation",
        n_agents=4,
        obstacle_density=0.0,
        comms={},
        reward={"message_cost": 1.0, "group_share": 0.0},
    )
    env.reset(seed=0)
    d = env.scenario.config.comms.action_dim
    quiet = {a: {"motion": np.zeros(3, np.float32), "comm": np.full(d, -1.0, np.float32)} for a in env.agents}
    _, r0, *_ = env.step(quiet)
    loud = dict(quiet, agent_0=_comm(env, 3, receiver=1))
    _, r1, *_ = env.step(loud)
    assert r1["agent_0"] == pytest.approx(r0["agent_0"] - 1.0, abs=1e-6)
    ev = env.world.last_events.comms
    assert ev is not None and ev.sent[0] == 1 and len(ev.bus.delivered.msg) == 1


def test_code_api_and_bad_inputs() -> None:
    env = _env()
    assert env.send_message("agent_0", [0.1, 0.2, 0.3, 0.4], to="agent_3")
    assert env.send_message("agent_1", np.zeros(4), group=int(env.world.state.group[1]))
    for kwargs, match in [
        ({"to": "agent_99"}, "agent_99"),
        ({"group": 42}, "group"),
        ({}, "exactly one"),
    ]:
        with pytest.raises(ValueError, match=match):
            env.send_message("agent_0", np.zeros(4), **kwargs)
    with pytest.raises(ValueError, match="payload"):
        env.send_message("agent_0", np.zeros(3), to="agent_1")
    with pytest.raises(ValueError, match="finite"):
        env.send_message("agent_0", [np.nan, 0, 0, 0], to="agent_1")
    with pytest.raises(ValueError, match="uav_0"):
        env.send_message("uav_0", np.zeros(4), to="agent_1")
    env.assign_group("agent_0", 1)
    assert env.world.state.group[0] == 1
    with pytest.raises(ValueError, match="group"):
        env.assign_group("agent_0", -5)
    obs, *_ = env.step(_idle(env))
    assert len(_rows(obs, "agent_3")) >= 1
    groups = env.world.last_events.groups
    assert groups is not None and groups.slot.tolist() == [0] and groups.new.tolist() == [1]
    no_comms = agentsim_env.make("navigation")
    no_comms.reset(seed=0)
    with pytest.raises(ValueError, match="comms"):
        no_comms.send_message("agent_0", [0.0], to="agent_1")


def test_comms_config_errors_name_field() -> None:
    for bad, field in [
        ({"loss": 1.5}, "loss"),
        ({"latency": -1}, "latency"),
        ({"inbox_size": 0}, "inbox_size"),
        ({"heartbeat_period": 5, "heartbeat_timeout": 2}, "heartbeat_timeout"),
        ({"foo": 1}, "foo"),
    ]:
        with pytest.raises(ValueError, match=field):
            agentsim_env.make("navigation", comms=bad)
