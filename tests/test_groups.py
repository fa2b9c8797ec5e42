"""Tests of the group controller: assignment, broadcast, heartbeats and timeouts."""

from __future__ import annotations

import numpy as np
import pytest

from agentsim_env.comms import GROUP, HEARTBEAT, ChannelConfig, MessageBus
from agentsim_env.comms.stack import CommsConfig, CommsStack
from agentsim_env.core.state import AgentState
from agentsim_env.groups import GroupController


def make(b=1, n=4, period=1, timeout=3, seed=0, **channel):  # type: ignore[no-untyped-def]
    state = AgentState.create(b, n)
    ctrl = GroupController(b, n, period, timeout, group=state.group)
    bus = MessageBus(b, n, 2, ChannelConfig(**channel), 4, np.random.default_rng(seed), group=state.group)
    return state, ctrl, bus


def tick(ctrl, bus, step, online):  # type: ignore[no-untyped-def]
    """The groups stage, then what the comms stage does with its requests: heartbeats over the bus."""
    timed, ping = ctrl.tick(step, online, bus.take_answers())
    if ping.size:
        bus.send(HEARTBEAT, np.full(ping.size, -1), ping, np.zeros((ping.size, bus.payload_dim), np.float32), step)
    return timed


def run(state, ctrl, bus, steps, offline_at=None):  # type: ignore[no-untyped-def]
    """Step the groups + comms part of the pipeline; returns {step: timed-out slots}."""
    offline_at = offline_at or {}
    reported = {}
    for step in steps:
        for slot, t in offline_at.items():
            if step == t:
                state.online[slot] = False
        timed = tick(ctrl, bus, step, state.online)
        if timed.size:
            reported[step] = timed.tolist()
            state.online[timed] = False
        bus.deliver(step, state.pos, state.online, state.group)
    return reported


def test_validation() -> None:
    with pytest.raises(ValueError, match="heartbeat_period"):
        GroupController(1, 4, -1, 3)
    with pytest.raises(ValueError, match="timeout must be >= heartbeat_period"):
        GroupController(1, 4, 5, 3)
    with pytest.raises(ValueError, match="n_agents"):
        GroupController(1, 0, 1, 3)
    with pytest.raises(ValueError, match="group must be an int32"):
        GroupController(1, 4, 1, 3, group=np.zeros(4, dtype=np.int64))
    GroupController(1, 4, 0, 0)  # disabled: any timeout
    with pytest.raises(ValueError, match="heartbeat_timeout must be >= heartbeat_period \\+ 2 \\* latency"):
        CommsConfig(heartbeat_period=1, heartbeat_timeout=3, latency=2)


def test_assign_writes_state_and_logs_changes() -> None:
    state, ctrl, bus = make(b=2, n=3)
    ctrl.assign(np.arange(6), np.array([0, 0, 1, 0, 1, 1]), step=0)
    assert state.group.tolist() == [0, 0, 1, 0, 1, 1] and ctrl.group is state.group
    assert ctrl.members(0, 0).tolist() == [0, 1] and ctrl.members(1, 1).tolist() == [4, 5]
    assert ctrl.members(1, 7).size == 0
    ev = ctrl.take_events()
    assert len(ev) == 6 and (ev.old == -1).all() and ev.new.tolist() == [0, 0, 1, 0, 1, 1]
    tick(ctrl, bus, 7, state.online)
    ctrl.assign(np.array([1, 2, 3]), np.array([1, 1, -1]))  # slot 2 is unchanged: no row
    ev = ctrl.take_events()
    assert ev.step.tolist() == [7, 7] and ev.slot.tolist() == [1, 3]
    assert ev.old.tolist() == [0, 0] and ev.new.tolist() == [1, -1]
    assert len(ctrl.take_events()) == 0
    with pytest.raises(ValueError, match="distinct"):
        ctrl.assign(np.array([0, 0]), 1)
    with pytest.raises(ValueError, match="slots must be in"):
        ctrl.assign(np.array([6]), 1)
    with pytest.raises(ValueError, match="group ids must be integers in -1..2"):
        ctrl.assign(np.array([0]), -2)


def test_broadcast_reaches_exactly_the_online_members() -> None:
    state, ctrl, _ = make(b=2, n=6, period=0, timeout=0, latency=1)
    stack = CommsStack(CommsConfig(payload_dim=2, latency=1), 2, 6, state.group)
    bus = stack.bus
    ctrl.assign(np.arange(12), np.array([0, 1, 0, 1, 2, 1, 1, 1, 0, 0, 0, 0]), step=0)
    state.online[3] = False
    assert stack.broadcast(0, 1, np.array([4.0, 2.0]), 0)
    assert len(bus.deliver(0, state.pos, state.online, state.group).delivered) == 0  # latency 1
    ev = bus.deliver(1, state.pos, state.online, state.group)
    assert sorted(ev.delivered.receiver.tolist()) == [1, 5]  # not offline 3, not world 1's group 1
    assert (ev.delivered.kind == GROUP).all() and (ev.delivered.sender == -1).all()
    np.testing.assert_array_equal(bus.inbox.payload[[1, 5], 0], [[4, 2], [4, 2]])
    with pytest.raises(ValueError, match="unknown group 2 in world 1"):
        stack.broadcast(1, 2, np.zeros(2), 1)
    with pytest.raises(ValueError, match="world must be in"):
        stack.broadcast(2, 0, np.zeros(2), 1)


def test_offline_agent_times_out_after_timeout_steps() -> None:
    state, ctrl, bus = make(n=4, period=1, timeout=3)
    ctrl.assign(np.arange(3), 0, step=0)  # slot 3 has no group: never monitored
    reported = run(state, ctrl, bus, range(30), offline_at={2: 5})
    # slot 2's last answer arrived at step 4 (heartbeat and answer in the same step at latency 0)
    assert reported == {8: [2]}
    assert ctrl.last_answer[2] == 4 and ctrl.timed_out.tolist() == [False, False, True, False]
    assert ctrl.last_answer[0] == 28  # the tick of step 29 read the answer of step 28


def test_heartbeats_reach_inboxes_and_answers_update_last_answer() -> None:
    state, ctrl, bus = make(n=3, period=4, timeout=10, latency=2)
    ctrl.assign(np.array([0, 1]), 0, step=0)
    run(state, ctrl, bus, range(6))
    assert bus.inbox.kind[0, 0] == HEARTBEAT and bus.inbox.sender[0, 0] == -1 and bus.inbox.created[0, 0] == 0
    assert not bus.inbox.valid[2].any()
    # heartbeat of step 0 delivered at 2, answered, answer arrived at 4 and read by the tick of 5
    assert ctrl.last_answer.tolist() == [4, 4, 0]


def test_loss_one_times_out_every_member() -> None:
    state, ctrl, bus = make(n=5, period=2, timeout=6, loss=1.0)
    ctrl.assign(np.arange(4), np.array([0, 1, 1, 0]), step=0)
    reported = run(state, ctrl, bus, range(20))
    assert reported == {7: [0, 1, 2, 3]}  # never answered since step 0


@pytest.mark.parametrize(("latency", "period"), [(0, 1), (2, 3), (1, 5)])
def test_loss_zero_nobody_online_times_out(latency: int, period: int) -> None:
    timeout = period + 2 * latency
    state, ctrl, bus = make(b=2, n=5, period=period, timeout=timeout, latency=latency)
    ctrl.assign(np.arange(8), np.array([0, 0, 1, 1, 2, 0, 0, 1]), step=0)
    reported = run(state, ctrl, bus, range(0, 13))
    ctrl.assign(np.array([8, 9]), 1)  # join between two heartbeats (step 12)
    reported |= run(state, ctrl, bus, range(13, 60))
    assert reported == {}
    assert state.online.all()


def test_disabled_controller_sends_nothing() -> None:
    state, ctrl, bus = make(period=0, timeout=0)
    ctrl.assign(np.arange(4), 0, step=0)
    for step in range(10):
        assert tick(ctrl, bus, step, state.online).size == 0
        assert len(bus.deliver(step, state.pos, state.online, state.group).sent) == 0


def test_lossy_heartbeats_are_deterministic() -> None:
    def once(seed: int) -> dict:
        state, ctrl, bus = make(n=8, period=1, timeout=2, seed=seed, loss=0.5)
        ctrl.assign(np.arange(8), 0, step=0)
        return run(state, ctrl, bus, range(40))

    a = once(11)
    assert a == once(11) and a
    assert sum(len(v) for v in a.values()) <= 8  # each slot reported at most once
