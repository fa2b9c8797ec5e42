"""Tests of the message bus, the channel model and the inboxes."""

from __future__ import annotations

import pickle
from collections import defaultdict

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.comms import (
    AGENT,
    DROP_BANDWIDTH,
    DROP_LOSS,
    DROP_OFFLINE,
    DROP_RANGE,
    ENV,
    ENV_COLLISION_AGENT,
    ENV_COLLISION_OBJECT,
    FEATURES_PER_MESSAGE,
    GROUP,
    HEARTBEAT,
    OVERLAY,
    ChannelConfig,
    Inbox,
    MessageBus,
    env_collision_payload,
)


def make_bus(b=1, n=4, d=3, m=4, seed=0, group=None, **channel) -> MessageBus:  # type: ignore[no-untyped-def]
    return MessageBus(b, n, d, ChannelConfig(**channel), m, np.random.default_rng(seed), group=group)


def world_state(s: int):  # type: ignore[no-untyped-def]
    return np.zeros((s, 3)), np.ones(s, dtype=bool), np.zeros(s, dtype=np.int32)


# ---------------------------------------------------------------------------------------------- unit cases
def test_agent_unicast_fields_and_events() -> None:
    bus = make_bus()
    pos, on, grp = world_state(4)
    acc = bus.send(AGENT, np.array([0]), np.array([2]), np.array([[1.0, 2.0, 3.0]]), 0)
    assert acc.tolist() == [True]
    ev = bus.deliver(0, pos, on, grp)
    ib = bus.inbox
    assert ib.valid[2].tolist() == [True, False, False, False]
    assert (ib.kind[2, 0], ib.sender[2, 0], ib.hops[2, 0], ib.created[2, 0]) == (AGENT, 0, 0, 0)
    np.testing.assert_array_equal(ib.payload[2, 0], [1, 2, 3])
    assert not ib.valid[[0, 1, 3]].any()
    assert ib.received.tolist() == [0, 0, 1, 0] and ib.dropped.sum() == 0
    assert len(ev.sent) == 1 and ev.sent.target[0] == 2
    assert ev.delivered.receiver.tolist() == [2] and len(ev.dropped) == 0


def test_group_fanout_excludes_sender_offline_and_other_worlds() -> None:
    grp = np.array([0, 0, 1, 0, 0, 0, 0, 0, 0, 0], dtype=np.int32)  # 2 worlds x 5 agents
    bus = make_bus(b=2, n=5, group=grp)
    pos = np.zeros((10, 3))
    on = np.ones(10, dtype=bool)
    on[3] = False
    bus.send(GROUP, np.array([0]), np.array([0]), np.ones((1, 3)), 0)
    ev = bus.deliver(0, pos, on, grp)
    assert sorted(ev.delivered.receiver.tolist()) == [1, 4]
    assert len(ev.dropped) == 0  # offline members are not receivers
    assert bus.inbox.valid[:, 0].nonzero()[0].tolist() == [1, 4]
    # The controller (sender -1) names the world; it reaches every online member there.
    bus.send(GROUP, np.array([-1]), np.array([0]), np.ones((1, 3)), 1, world=np.array([1]))
    ev = bus.deliver(1, pos, on, grp)
    assert sorted(ev.delivered.receiver.tolist()) == [5, 6, 7, 8, 9]
    assert (ev.delivered.sender == -1).all() and (ev.delivered.kind == GROUP).all()


def test_env_message_and_collision_encoding() -> None:
    bus = make_bus()
    pos, on, grp = world_state(4)
    bus.send_env(
        np.array([2, 1]),
        env_collision_payload(np.array([ENV_COLLISION_OBJECT, ENV_COLLISION_AGENT]), np.array([7, 3]), 3),
        0,
    )
    bus.deliver(0, pos, on, grp)
    ib = bus.inbox
    assert ib.kind[2, 0] == ENV and ib.sender[2, 0] == -1
    np.testing.assert_array_equal(ib.payload[2, 0], [ENV_COLLISION_OBJECT, 7, 0])
    np.testing.assert_array_equal(ib.payload[1, 0], [ENV_COLLISION_AGENT, 3, 0])
    pos[:] = 5.0
    obs = ib.observe(pos, 0)
    np.testing.assert_array_equal(obs[2, 0, 6:9], 0.0)  # the environment has no position
    with pytest.raises(ValueError, match="sender of ENV"):
        bus.send(ENV, np.array([0]), np.array([1]), np.zeros((1, 3)), 0)
    # narrower payloads keep what fits (what was hit, then nothing), never an error inside a step
    np.testing.assert_array_equal(env_collision_payload(ENV_COLLISION_AGENT, np.array([1]), 1), [[1]])
    assert env_collision_payload(ENV_COLLISION_AGENT, np.array([1]), 0).shape == (1, 0)
    with pytest.raises(ValueError, match="payload_dim"):
        env_collision_payload(ENV_COLLISION_AGENT, np.array([1]), -1)


@pytest.mark.parametrize("latency", [0, 1, 3])
def test_latency_exact(latency: int) -> None:
    bus = make_bus(latency=latency)
    pos, on, grp = world_state(4)
    bus.send(AGENT, np.array([0]), np.array([1]), np.zeros((1, 3)), 2)
    for step in range(2, 2 + latency):
        assert len(bus.deliver(step, pos, on, grp).delivered) == 0
        assert not bus.inbox.valid.any() and bus.n_pending == 1
    ev = bus.deliver(2 + latency, pos, on, grp)
    assert ev.delivered.receiver.tolist() == [1] and ev.delivered.created.tolist() == [2]
    assert bus.n_pending == 0


def test_inbox_order_newest_first_and_overflow() -> None:
    ib = Inbox(3, 4, 1)
    # Several messages to one receiver in one call keep their order: the last is the newest (row 0).
    ib.push(np.array([1, 0, 1, 1]), AGENT, 2, 0, np.array([0, 0, 1, 2]), np.array([[0.0], [9.0], [1.0], [2.0]]))
    assert ib.payload[1, :3, 0].tolist() == [2, 1, 0] and ib.valid[1].tolist() == [True, True, True, False]
    assert ib.payload[0, 0, 0] == 9 and ib.valid[0].sum() == 1
    ib.push(np.array([1, 1]), AGENT, 2, 0, 3, np.array([[3.0], [4.0]]))
    ib.push(np.array([1]), OVERLAY, 0, 5, 4, np.array([5.0]))
    assert ib.payload[1, :, 0].tolist() == [5, 4, 3, 2]  # the 4 newest survive, newest first
    assert ib.created[1].tolist() == [4, 3, 3, 2] and ib.kind[1, 0] == OVERLAY and ib.hops[1, 0] == 5
    # More new messages than rows in one call: only the newest M are kept.
    ib.push(np.full(6, 2), AGENT, 1, 0, 0, np.arange(6.0)[:, None])
    assert ib.payload[2, :, 0].tolist() == [5, 4, 3, 2]
    assert ib.received.tolist() == [1, 6, 6]
    ib.clear(np.array([1]))
    assert not ib.valid[1].any() and ib.received[1] == 0 and ib.valid[2].all()
    with pytest.raises(ValueError, match="receiver"):
        ib.push(np.array([3]), AGENT, 0, 0, 0, np.zeros((1, 1)))
    with pytest.raises(ValueError, match="payload"):
        ib.push(np.array([0]), AGENT, 0, 0, 0, np.zeros((1, 2)))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 30), k=st.integers(0, 80))
def test_mark_senders_equals_its_numpy_form(seed: int, n: int, k: int) -> None:
    # the senders in the inboxes of some rows (a shard's own agents), ENV messages (sender -1) skipped, old rows
    # pushed out of a full inbox not counted
    rng = np.random.default_rng(seed)
    ib = Inbox(n, 3, 1)
    snd = rng.integers(-1, n, k)
    ib.push(rng.integers(0, n, k), AGENT, snd, 0, 0, np.zeros((k, 1)))
    rows = np.flatnonzero(rng.uniform(size=n) < 0.5)
    want = np.zeros(n, dtype=bool)
    got = ib.sender[rows][ib.valid[rows]]
    want[got[got >= 0]] = True
    out = np.zeros(n, dtype=bool)
    ib.mark_senders(rows, out)
    np.testing.assert_array_equal(out, want)
    for bad in (np.zeros(n + 1, dtype=bool), np.zeros(n, dtype=np.int64)):
        with pytest.raises(ValueError, match="writable bool array"):
            ib.mark_senders(rows, bad)


def test_observe_feature_layout() -> None:
    ib = Inbox(2, 3, 2, age_horizon=10, hop_horizon=4, pos_scale=2.0)
    ib.push(np.array([0]), OVERLAY, 1, 2, 5, np.array([[7.0, 8.0]]))
    ib.push(np.array([0]), HEARTBEAT, -1, 0, 0, np.array([[0.0, 0.0]]))
    pos = np.array([[1.0, 1.0, 1.0], [3.0, 5.0, 1.0]])
    out = np.full((2, 3, FEATURES_PER_MESSAGE + 2), 9.0, dtype=np.float32)
    assert ib.observe(pos, 8, out) is out
    hb, ov = out[0, 0], out[0, 1]
    np.testing.assert_allclose(ov, [1, 0, 0, 0, 1, 0, 1.0, 2.0, 0.0, 0.5, 0.3, 7, 8], rtol=1e-6)
    np.testing.assert_allclose(hb[:11], [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0.8], rtol=1e-6)
    assert (out[0, 2] == 0).all() and (out[1] == 0).all()  # empty rows are all zeros
    assert ib.observe(pos, 100)[0, 1, 10] == 1.0  # age is clipped at the horizon
    with pytest.raises(ValueError, match="out"):
        ib.observe(pos, 0, np.zeros((2, 3, 5), dtype=np.float32))


def test_bandwidth_per_sender_per_step_and_counters() -> None:
    bus = make_bus(bandwidth=2)
    pos, on, grp = world_state(4)
    z = np.zeros((3, 3))
    assert bus.send(AGENT, np.array([0, 1, 0]), np.array([1, 0, 2]), z, 0).tolist() == [True, True, True]
    assert bus.send(AGENT, np.array([0, 0, 1]), np.array([3, 1, 2]), z, 0).tolist() == [False, False, True]
    assert bus.send(AGENT, np.array([0]), np.array([3]), z[:1], 1).tolist() == [True]  # a new step
    ev = bus.deliver(0, pos, on, grp)
    assert (ev.dropped.reason == DROP_BANDWIDTH).sum() == 2 and set(ev.dropped.sender) == {0}
    assert bus.inbox.dropped.tolist() == [2, 0, 0, 0]
    assert len(ev.sent) == 7 and len(ev.delivered) == 4
    # The environment is never limited.
    assert bus.send_env(np.zeros(5, dtype=np.int64), np.zeros((5, 3)), 1).all()


def test_offline_receiver_dropped_and_counted() -> None:
    bus = make_bus(latency=1)
    pos, on, grp = world_state(4)
    bus.send(AGENT, np.array([0, 0]), np.array([1, 2]), np.zeros((2, 3)), 0)
    on[2] = False  # goes offline while the message is in flight
    ev = bus.deliver(1, pos, on, grp)
    assert ev.delivered.receiver.tolist() == [1]
    assert ev.dropped.receiver.tolist() == [2] and ev.dropped.reason.tolist() == [DROP_OFFLINE]
    assert bus.inbox.dropped.tolist() == [0, 0, 1, 0] and not bus.inbox.valid[2].any()


def test_max_range_from_current_sender_position() -> None:
    bus = make_bus(n=3, latency=1, max_range=10.0)
    pos = np.array([[0.0, 0, 0], [5.0, 0, 0], [20.0, 0, 0]])
    on, grp = np.ones(3, dtype=bool), np.zeros(3, dtype=np.int32)
    bus.send(AGENT, np.array([0, 0]), np.array([1, 2]), np.zeros((2, 3)), 0)
    ev = bus.deliver(1, pos, on, grp)
    assert ev.delivered.receiver.tolist() == [1]
    assert ev.dropped.receiver.tolist() == [2] and ev.dropped.reason.tolist() == [DROP_RANGE]
    assert bus.inbox.dropped.tolist() == [0, 0, 1]
    bus.send(AGENT, np.array([0]), np.array([2]), np.zeros((1, 3)), 1)
    pos[0, 0] = 15.0  # the sender moved into range before delivery
    assert bus.deliver(2, pos, on, grp).delivered.receiver.tolist() == [2]
    bus.send_env(np.array([2]), np.zeros((1, 3)), 2)  # the environment is not range-limited
    pos[2, 0] = 1e6
    assert bus.deliver(3, pos, on, grp).delivered.receiver.tolist() == [2]


def _lossy_run(seed: int) -> np.ndarray:
    bus = make_bus(n=8, seed=seed, loss=0.5)
    pos, on, grp = world_state(8)
    drops = []
    for step in range(5):
        snd = np.repeat(np.arange(8), 8)
        tgt = np.tile(np.arange(8), 8)
        bus.send(AGENT, snd, tgt, np.zeros((64, 3)), step)
        drops.append(bus.deliver(step, pos, on, grp).dropped.msg)
    return np.concatenate(drops)


def test_loss_is_deterministic_per_seed() -> None:
    a, b, c = _lossy_run(3), _lossy_run(3), _lossy_run(4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert 100 < a.size < 220  # about half of 320


def test_loss_one_drops_everything() -> None:
    bus = make_bus(loss=1.0)
    pos, on, grp = world_state(4)
    bus.send(AGENT, np.array([0, 1]), np.array([1, 2]), np.zeros((2, 3)), 0)
    ev = bus.deliver(0, pos, on, grp)
    assert len(ev.delivered) == 0 and (ev.dropped.reason == DROP_LOSS).all() and len(ev.dropped) == 2


def test_bad_input_raises_naming_the_field() -> None:
    grp = np.array([0, 0, 1, 1, 0, 0, 0, 0], dtype=np.int32)
    bus = make_bus(b=2, n=4, group=grp)
    one = np.array([0])
    with pytest.raises(ValueError, match="payload"):
        bus.send(AGENT, one, np.array([1]), np.zeros((1, 2)), 0)
    with pytest.raises(ValueError, match="payload must be finite"):
        bus.send(AGENT, one, np.array([1]), np.array([[0.0, np.nan, 0.0]]), 0)
    with pytest.raises(ValueError, match="target receiver slot 8 out of range"):
        bus.send(AGENT, one, np.array([8]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match=r"target receiver slot 5 \(world 1\) is not in the world 0"):
        bus.send(AGENT, one, np.array([5]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="unknown group 1 in world 1"):
        bus.send(GROUP, np.array([4]), np.array([1]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="unknown group 7"):
        bus.send(GROUP, one, np.array([7]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="world is required"):
        bus.send(GROUP, np.array([-1]), np.array([0]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="sender must be"):
        bus.send(AGENT, np.array([9]), np.array([1]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="kind must be one of"):
        bus.send(OVERLAY, one, np.array([1]), np.zeros((1, 3)), 0)
    with pytest.raises(ValueError, match="step"):
        bus.send(AGENT, one, np.array([1]), np.zeros((1, 3)), -1)
    with pytest.raises(ValueError, match="target must have length"):
        bus.send(AGENT, np.array([0, 1]), np.array([1]), np.zeros((2, 3)), 0)
    with pytest.raises(ValueError, match="group: no group array"):
        make_bus().send(GROUP, one, np.array([0]), np.zeros((1, 3)), 0)
    assert bus.n_pending == 0  # nothing of a rejected batch is queued
    for field, kw in (
        ("latency", {"latency": -1}),
        ("loss", {"loss": 1.5}),
        ("bandwidth", {"bandwidth": -2}),
        ("max_range", {"max_range": 0.0}),
        ("latency", {"latency": 1.5}),
    ):
        with pytest.raises(ValueError, match=field):
            ChannelConfig(**kw)


def test_out_of_order_sends_and_queue_growth() -> None:
    bus = make_bus(n=4, latency=2, m=8)
    pos, on, grp = world_state(4)
    bus.send(AGENT, np.array([0]), np.array([1]), np.full((1, 3), 5.0), 5)
    bus.send(AGENT, np.array([0]), np.array([1]), np.full((1, 3), 3.0), 3)  # appended after a later due
    assert len(bus.deliver(4, pos, on, grp).delivered) == 0
    assert bus.deliver(5, pos, on, grp).delivered.created.tolist() == [3]
    assert len(bus.deliver(6, pos, on, grp).delivered) == 0 and bus.inbox.payload[1, 0, 0] == 3.0
    assert bus.deliver(7, pos, on, grp).delivered.created.tolist() == [5]
    for step in range(8, 30):  # many messages in flight force the queue to grow and compact
        bus.send(AGENT, np.zeros(50, dtype=np.int64), np.full(50, 2), np.full((50, 3), float(step)), step)
        ev = bus.deliver(step, pos, on, grp)
        if step >= 10:
            assert len(ev.delivered) == 50 and (ev.delivered.created == step - 2).all()
    assert bus.inbox.payload[2, 0, 0] == 27.0


def test_pickle_and_reset() -> None:
    grp = np.zeros(4, dtype=np.int32)
    bus = make_bus(latency=2, loss=0.3, group=grp)
    pos, on, _ = world_state(4)
    bus.send(GROUP, np.array([0, 1]), np.array([0, 0]), np.ones((2, 3)), 0)
    clone = pickle.loads(pickle.dumps(bus))
    a, b = bus.deliver(2, pos, on, grp), clone.deliver(2, pos, on, grp)
    np.testing.assert_array_equal(a.delivered.receiver, b.delivered.receiver)
    np.testing.assert_array_equal(bus.inbox.payload, clone.inbox.payload)
    bus.send(AGENT, np.array([0]), np.array([1]), np.ones((1, 3)), 3)
    bus.reset(np.random.default_rng(1))
    assert bus.n_pending == 0 and not bus.inbox.valid.any() and bus.inbox.received.sum() == 0
    assert len(bus.deliver(5, pos, on, grp).sent) == 0


def test_heartbeat_answer_crosses_the_channel() -> None:
    bus = make_bus(latency=1)
    pos, on, grp = world_state(4)
    bus.send(HEARTBEAT, np.full(2, -1), np.array([1, 2]), np.zeros((2, 3)), 0)
    on[2] = False
    bus.deliver(0, pos, on, grp)
    ev = bus.deliver(1, pos, on, grp)
    assert ev.delivered.receiver.tolist() == [1] and bus.inbox.kind[1, 0] == HEARTBEAT
    assert bus.take_answers()[0].size == 0
    ev = bus.deliver(2, pos, on, grp)  # the answer arrives one latency later, at the controller (-1)
    assert ev.delivered.sender.tolist() == [1] and ev.delivered.receiver.tolist() == [-1]
    slots, steps = bus.take_answers()
    assert slots.tolist() == [1] and steps.tolist() == [2]
    assert bus.inbox.received.tolist() == [0, 1, 0, 0]  # answers enter no inbox


def test_heartbeat_answers_are_lossy_too() -> None:
    bus = make_bus(n=8, seed=5, loss=0.5)
    pos, on, grp = world_state(8)
    heard = answered = lost_answers = 0
    for step in range(60):
        bus.send(HEARTBEAT, np.full(8, -1), np.arange(8), np.zeros((8, 3)), step)
        ev = bus.deliver(step, pos, on, grp)
        heard += int(((ev.delivered.kind == HEARTBEAT) & (ev.delivered.receiver >= 0)).sum())
        answered += bus.take_answers()[0].size
        lost_answers += int(((ev.dropped.receiver == -1) & (ev.dropped.reason == DROP_LOSS)).sum())
    assert answered + lost_answers == heard
    assert 0.35 < answered / heard < 0.65  # the answer crosses the lossy channel as well
    # a lost answer is charged to the answering slot, a lost heartbeat to the receiving slot
    assert bus.inbox.dropped.sum() == 8 * 60 - heard + lost_answers


# ---------------------------------------------------------------------------------------- property tests
@st.composite
def scenarios(draw):  # type: ignore[no-untyped-def]
    b = draw(st.integers(1, 2))
    n = draw(st.integers(2, 6))
    ch = ChannelConfig(
        latency=draw(st.integers(0, 3)),
        loss=draw(st.sampled_from([0.0, 0.3, 1.0])),
        bandwidth=draw(st.integers(0, 3)),
        max_range=draw(st.sampled_from([None, 6.0])),
    )
    seed = draw(st.integers(0, 2**16))
    return b, n, ch, seed


@settings(max_examples=50, deadline=None)
@given(scenarios())
def test_bus_invariants(sc) -> None:  # type: ignore[no-untyped-def]
    b, n, ch, seed = sc
    s = b * n
    rng = np.random.default_rng(seed)
    grp = rng.integers(-1, 3, s).astype(np.int32)
    bus = MessageBus(b, n, 2, ch, 3, np.random.default_rng(seed + 1), group=grp)
    world = np.arange(s) // n
    t_send, t_end = 6, 6 + ch.latency + 1
    online_at, pos_at, accepted = {}, {}, defaultdict(int)
    sent, delivered, dropped = [], [], []
    for step in range(t_end):
        if step < t_send:
            k = int(rng.integers(0, 3 * s))
            snd = rng.integers(0, s, k)
            tgt = world[snd] * n + rng.integers(0, n, k)
            acc = bus.send(AGENT, snd, tgt, rng.standard_normal((k, 2)), step)
            for q in snd[acc]:
                accepted[(int(q), step)] += 1
            gs = np.flatnonzero(grp >= 0)
            gs = gs[rng.random(gs.size) < 0.5]
            acc = bus.send(GROUP, gs, grp[gs], np.ones((gs.size, 2)), step)
            for q in gs[acc]:
                accepted[(int(q), step)] += 1
            bus.send_env(rng.integers(0, s, 2), np.zeros((2, 2)), step)
        online_at[step] = rng.random(s) < 0.7
        pos_at[step] = rng.uniform(0, 10, (s, 3))
        ev = bus.deliver(step, pos_at[step], online_at[step], grp)
        sent.append(ev.sent)
        delivered.append(ev.delivered)
        dropped.append(ev.dropped)
    assert bus.n_pending == 0
    dl = type(ev.sent).concat(delivered)
    dr = type(ev.sent).concat(dropped)
    se = type(ev.sent).concat(sent)
    # never to an offline slot, never before (or after) its due step
    for r, t in zip(dl.receiver, dl.step, strict=True):
        assert online_at[int(t)][r]
    assert (dl.step - dl.created == ch.latency).all()
    # bandwidth per agent sender per step
    if ch.bandwidth:
        assert max(accepted.values(), default=0) <= ch.bandwidth
    # every (message, receiver) pair ends in exactly one delivered or dropped row
    rows = defaultdict(list)
    for m, r in zip(np.concatenate([dl.msg, dr.msg]), np.concatenate([dl.receiver, dr.receiver]), strict=True):
        rows[int(m)].append(int(r))
    bw_dropped = set(dr.msg[dr.reason == DROP_BANDWIDTH].tolist())
    for i in range(len(se)):
        m, kind, snd, tgt, t = (int(x[i]) for x in (se.msg, se.kind, se.sender, se.target, se.created))
        if m in bw_dropped or kind != GROUP:
            assert rows[m] == [tgt if kind != GROUP else -1]
        else:
            on = online_at[t + ch.latency]
            expect = [q for q in range(s) if world[q] == world[snd] and grp[q] == tgt and on[q] and q != snd]
            assert sorted(rows[m]) == expect
    # filters are consistent with the channel (precedence: offline, then range, then loss)
    for r, snd, t, why in zip(dr.receiver, dr.sender, dr.step, dr.reason, strict=True):
        if why != DROP_BANDWIDTH and not online_at[int(t)][r]:
            assert why == DROP_OFFLINE
        if why == DROP_OFFLINE:
            assert not online_at[int(t)][r]
        elif why == DROP_RANGE:
            assert ch.max_range is not None and np.linalg.norm(pos_at[int(t)][snd] - pos_at[int(t)][r]) > ch.max_range
        elif why == DROP_LOSS:
            assert ch.loss > 0
    if ch.loss == 1.0:
        assert len(dl) == 0
    # counters: one received per delivery, one dropped per drop row
    assert bus.inbox.received.sum() == len(dl) and bus.inbox.dropped.sum() == len(dr)
