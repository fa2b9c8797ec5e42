"""One bus vs the same traffic split over K buses that each own some slots (``comms.split``), keyed loss draws
and the inbox order that makes the two agree."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.comms import AGENT, ENV, GROUP, HEARTBEAT, ChannelConfig, DeliveryEvents, MessageBus
from agentsim_env.comms.bus_kernels import keyed_draws
from agentsim_env.comms.split import route

INBOX_FIELDS = ("valid", "kind", "sender", "hops", "created", "payload", "received", "dropped")


def _bus(b: int, n: int, channel: ChannelConfig, seed: int) -> MessageBus:
    bus = MessageBus(b, n, 2, channel, 3, None)
    for w in range(b):  # every part gets the world's episode key from the same episode seed
        bus.reset_world(w, np.random.default_rng([seed, w]))
    return bus


def _events(evs: list[DeliveryEvents]) -> tuple[Counter, Counter, Counter]:
    """Multisets of the sent, delivered and dropped rows (ids are per bus, so left out)."""
    out = []
    for log in ("sent", "delivered", "dropped"):
        c: Counter = Counter()
        for ev in evs:
            g = getattr(ev, log)
            c.update(
                zip(
                    g.kind.tolist(),
                    g.sender.tolist(),
                    g.target.tolist(),
                    g.receiver.tolist(),
                    g.created.tolist(),
                    g.step.tolist(),
                    g.reason.tolist(),
                )
            )
        out.append(c)
    return out[0], out[1], out[2]


def _step_traffic(rng: np.random.Generator, b: int, n: int, grp: np.ndarray, step: int) -> list[tuple]:
    """One step's send calls ``(kind, sender, target, world, payload)``, mixed kinds, in call order."""
    s = b * n
    calls = []
    for _ in range(int(rng.integers(1, 5))):
        c = int(rng.integers(0, 5))
        k = int(rng.integers(1, 6))
        pay = rng.uniform(-1, 1, (k, 2)).astype(np.float32) + step
        if c == 0:  # agent unicasts (repeated senders: their sequence numbers count up)
            snd = rng.integers(0, s, k)
            tgt = (snd // n) * n + rng.integers(0, n, k)
            calls.append((AGENT, snd, tgt, None, pay))
        elif c == 1:  # agent group messages to the sender's own group
            snd = rng.integers(0, s, k)
            snd = snd[grp[snd] >= 0]
            if snd.size:
                calls.append((GROUP, snd, grp[snd].astype(np.int64), None, pay[: snd.size]))
        elif c == 2:
            calls.append((ENV, np.full(k, -1), rng.integers(0, s, k), None, pay))
        elif c == 3:  # controller heartbeats (each delivery answers back)
            calls.append((HEARTBEAT, np.full(k, -1), rng.integers(0, s, k), None, pay))
        else:  # controller broadcast to a group of a world
            w = int(rng.integers(0, b))
            g = grp[w * n : (w + 1) * n]
            if (g >= 0).any():
                calls.append((GROUP, np.array([-1]), np.array([int(rng.choice(g[g >= 0]))]), np.array([w]), pay[:1]))
    return calls


def _seen(pos: np.ndarray, mine: np.ndarray, r_max: float | None) -> np.ndarray | None:
    """Own slots and every sender within range of an own receiver (a little more: seeing more is allowed)."""
    if r_max is None:
        return None
    d = pos[:, None, :] - pos[None, mine, :]
    near = ((d[..., 0] ** 2 + d[..., 2] ** 2) + d[..., 1] ** 2 <= 1.01 * r_max * r_max).any(axis=1)
    return mine | near


def _handover(parts: list[MessageBus], old: np.ndarray, new: np.ndarray) -> None:
    """Move each slot that changes part to its new part with its inbox (what a hand-over carries)."""
    for s in np.flatnonzero(old != new):
        a, b = parts[old[s]].inbox, parts[new[s]].inbox
        for f in INBOX_FIELDS:
            getattr(b, f)[s] = getattr(a, f)[s]


def run_split(seed: int, b: int, n: int, k: int, channel: ChannelConfig, steps: int, moves: bool) -> None:
    """Drive one bus and K parts with the same traffic; check every step that they agree."""
    rng = np.random.default_rng(seed)
    s = b * n
    one = _bus(b, n, channel, seed)
    parts = [_bus(b, n, channel, seed) for _ in range(k)]
    owner = rng.integers(0, k, s)
    for step in range(steps):
        if moves and step:
            new = np.where(rng.random(s) < 0.3, rng.integers(0, k, s), owner)
            _handover(parts, owner, new)
            owner = new
        pos = rng.uniform(0, 60, (s, 3))
        online = rng.random(s) < 0.85
        grp = rng.integers(-1, 3, s).astype(np.int32)
        for kind, snd, tgt, wld, pay in _step_traffic(rng, b, n, grp, step):
            acc = one.send(kind, snd, tgt, pay, step, world=wld, group=grp)
            # the part that holds each row: its sender's, the receiver's for the environment / controller,
            # part 0 for a controller broadcast
            holder = np.where(snd >= 0, owner[np.maximum(snd, 0)], np.where(kind == GROUP, 0, owner[tgt]))
            got = np.zeros_like(acc)
            for p in range(k):
                sel = holder == p
                if sel.any():
                    w = None if wld is None else wld[sel]
                    got[sel] = parts[p].send(kind, snd[sel], tgt[sel], pay[sel], step, world=w, group=grp)
            np.testing.assert_array_equal(got, acc, err_msg=f"step {step}: bandwidth")
        ev_one = one.deliver(step, pos, online, grp)
        evs: list[DeliveryEvents] = []
        while True:  # latency-0 heartbeat answers come due within the step: another round
            due = [route(bus.take_due(step), owner, k) for bus in parts]
            if not any(len(r) for d in due for r in d.values()) and evs:
                break
            for q, bus in enumerate(parts):
                rows = due[0][q].concat([d[q] for d in due], 2)
                mine = owner == q
                evs.append(
                    bus.deliver_rows(rows, step, pos, online, grp, mine=mine, seen=_seen(pos, mine, channel.max_range))
                )
        for log, a, c in zip(("sent", "delivered", "dropped"), _events([ev_one]), _events(evs)):
            assert a == c, f"step {step}: {log} differs"
        ans = [bus.take_answers() for bus in parts]
        a1 = one.take_answers()
        assert Counter(zip(*[x.tolist() for x in a1])) == Counter(
            t for sl, stp in ans for t in zip(sl.tolist(), stp.tolist())
        ), f"step {step}: heartbeat answers differ"
        for q, bus in enumerate(parts):
            mine = owner == q
            for f in INBOX_FIELDS:
                np.testing.assert_array_equal(
                    getattr(bus.inbox, f)[mine],
                    getattr(one.inbox, f)[mine],
                    err_msg=f"step {step}: part {q} inbox {f}",
                )


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    b=st.integers(1, 2),
    n=st.integers(3, 8),
    k=st.integers(2, 4),
    latency=st.integers(0, 2),
    loss=st.sampled_from([0.0, 0.25, 0.5]),
    r_max=st.sampled_from([None, 25.0]),
    bandwidth=st.sampled_from([0, 2]),
    moves=st.booleans(),
)
def test_split_bus_matches_one_bus(seed, b, n, k, latency, loss, r_max, bandwidth, moves) -> None:  # type: ignore[no-untyped-def]
    ch = ChannelConfig(latency=latency, loss=loss, bandwidth=bandwidth, max_range=r_max)
    run_split(seed, b, n, k, ch, steps=6, moves=moves)


def test_split_bus_long_run_with_moves() -> None:
    ch = ChannelConfig(latency=2, loss=0.3, bandwidth=3, max_range=30.0)
    run_split(7, 2, 12, 3, ch, steps=40, moves=True)


def test_message_in_flight_reaches_the_receivers_new_part() -> None:
    ch = ChannelConfig(latency=2)
    parts = [_bus(1, 4, ch, 0) for _ in range(2)]
    pos, on, grp = np.zeros((4, 3)), np.ones(4, dtype=bool), np.zeros(4, dtype=np.int32)
    owner = np.array([0, 0, 1, 1])
    parts[0].send(AGENT, np.array([0]), np.array([1]), np.ones((1, 2)), 0)
    owner = np.array([0, 1, 1, 1])  # slot 1 moves to part 1 while the message is in flight
    for step in range(3):
        due = [route(bus.take_due(step), owner, 2) for bus in parts]
        for q, bus in enumerate(parts):
            bus.deliver_rows(due[0][q].concat([d[q] for d in due], 2), step, pos, on, grp, mine=owner == q)
    assert parts[1].inbox.valid[1, 0] and parts[1].inbox.sender[1, 0] == 0
    assert not parts[0].inbox.valid.any()


def test_route_sends_each_row_to_the_owner() -> None:
    bus = _bus(1, 4, ChannelConfig(), 0)
    grp = np.array([0, 0, 1, 1], dtype=np.int32)
    bus.send(AGENT, np.array([0, 3]), np.array([2, 1]), np.zeros((2, 2)), 0)
    bus.send(GROUP, np.array([1]), np.array([1]), np.zeros((1, 2)), 0, group=grp)
    bus.send(HEARTBEAT, np.array([-1]), np.array([3]), np.zeros((1, 2)), 0)
    rows = bus.take_due(0)
    out = route(rows, np.array([0, 0, 1, -1]))
    assert sorted(out) == [0, 1]
    assert sorted(zip(out[0].kind.tolist(), out[0].target.tolist())) == [(AGENT, 1), (GROUP, 1)]
    assert sorted(zip(out[1].kind.tolist(), out[1].target.tolist())) == [(AGENT, 2), (GROUP, 1)]
    with pytest.raises(ValueError, match="owner"):
        route(rows, np.zeros((2, 2), dtype=np.int64))


def test_answers_route_to_the_senders_part() -> None:
    bus = _bus(1, 4, ChannelConfig(latency=1), 0)
    pos, on, grp = np.zeros((4, 3)), np.ones(4, dtype=bool), np.zeros(4, dtype=np.int32)
    bus.send(HEARTBEAT, np.array([-1]), np.array([2]), np.zeros((1, 2)), 0)
    bus.deliver(1, pos, on, grp)
    rows = bus.take_due(2)  # the answer of slot 2
    assert rows.kind.tolist() == [HEARTBEAT] and rows.target.tolist() == [-1] and rows.sender.tolist() == [2]
    out = route(rows, np.array([0, 0, 1, 0]), 3)
    assert [len(out[p]) for p in range(3)] == [0, 1, 0]


def test_deliver_rows_checks_its_masks() -> None:
    bus = _bus(1, 4, ChannelConfig(), 0)
    pos, on, grp = np.zeros((4, 3)), np.ones(4, dtype=bool), np.zeros(4, dtype=np.int32)
    with pytest.raises(ValueError, match="mine must be a bool array of shape"):
        bus.deliver_rows(bus.take_due(0), 0, pos, on, grp, mine=np.zeros(3, dtype=bool))
    with pytest.raises(ValueError, match="seen must be a bool array of shape"):
        bus.deliver_rows(bus.take_due(0), 0, pos, on, grp, seen=np.zeros(4, dtype=int))


# ------------------------------------------------------------------------------------- keyed loss draws
def _fates(extra: bool) -> dict[tuple[int, int, int], bool]:
    """Delivered or lost, per (sender, receiver, step) of a fixed set of unicasts, with or without other traffic."""
    bus = _bus(1, 16, ChannelConfig(loss=0.5), 3)
    pos, on = np.zeros((16, 3)), np.ones(16, dtype=bool)
    grp = np.zeros(16, dtype=np.int32)
    fates = {}
    for step in range(4):
        if extra:  # unrelated messages first: other senders, a group message, environment messages
            bus.send(AGENT, np.arange(8, 16), np.arange(7, -1, -1), np.ones((8, 2)), step)
            bus.send(GROUP, np.array([9]), np.array([0]), np.ones((1, 2)), step, group=grp)
            bus.send_env(np.arange(16), np.ones((16, 2)), step)
        bus.send(AGENT, np.repeat(np.arange(4), 4), np.tile(np.arange(4, 8), 4), np.zeros((16, 2)), step)
        ev = bus.deliver(step, pos, on, grp)
        for log, ok in ((ev.delivered, True), (ev.dropped, False)):
            for s, r, t in zip(log.sender.tolist(), log.receiver.tolist(), log.kind.tolist()):
                if s < 4 and t == AGENT:
                    fates[(s, r, step)] = ok
    return fates


def test_loss_draw_does_not_depend_on_other_messages() -> None:
    a, b = _fates(False), _fates(True)
    assert a == b
    assert 0 < sum(a.values()) < len(a)  # some lost, some delivered


def test_keyed_draws_are_a_function_of_the_pair() -> None:
    rng = np.random.default_rng(1)
    q, n = 1000, 50
    keys = rng.integers(0, 2**63, 3).astype(np.uint64)
    world, created = rng.integers(0, 3, q), rng.integers(0, 100, q)
    snd = np.where(rng.random(q) < 0.1, -1, world * n + rng.integers(0, n, q))
    recv = np.where(rng.random(q) < 0.1, -1, world * n + rng.integers(0, n, q))
    seq, kind = rng.integers(0, 4, q), rng.integers(1, 6, q).astype(np.int8)
    rep = np.arange(q)

    def draw(**change: np.ndarray) -> np.ndarray:
        a = {
            "recv": recv,
            "keys": keys,
            "world": world,
            "created": created,
            "snd": snd,
            "seq": seq,
            "kind": kind,
        }
        a.update(change)
        return keyed_draws(rep, a["recv"], a["keys"], a["world"], n, a["created"], a["snd"], a["seq"], a["kind"])

    u = draw()
    perm = rng.permutation(q)  # a pair's value does not depend on its place in the batch
    np.testing.assert_array_equal(keyed_draws(perm, recv[perm], keys, world, n, created, snd, seq, kind), u[perm])
    assert ((u >= 0) & (u < 1)).all() and abs(u.mean() - 0.5) < 0.03
    # the world's place in the batch does not matter (slots are indices within the world), its key does
    shifted = draw(
        world=world + 1,
        keys=np.concatenate([[np.uint64(7)], keys]),
        snd=np.where(snd >= 0, snd + n, -1),
        recv=np.where(recv >= 0, recv + n, -1),
    )
    np.testing.assert_array_equal(shifted, u)
    for name, changed in (
        ("keys", keys + np.uint64(1)),
        ("created", created + 1),
        ("seq", seq + 1),
        ("kind", (kind + 1).astype(np.int8)),
        ("snd", np.where(snd >= 0, snd ^ 1, 0)),
        ("recv", np.where(recv >= 0, recv ^ 1, 0)),
    ):
        assert (draw(**{name: changed}) != u).mean() > 0.99, name


def test_episode_key_comes_from_the_reset_generator() -> None:
    a, b, c = (_bus(2, 4, ChannelConfig(loss=0.5), s) for s in (5, 5, 6))
    assert a.keys.tolist() == b.keys.tolist() and a.keys.tolist() != c.keys.tolist()
    bus = MessageBus(1, 4, 2, ChannelConfig(loss=0.5), 3, None)
    bus.send(AGENT, np.array([0]), np.array([1]), np.zeros((1, 2)), 0)
    with pytest.raises(ValueError, match="world 0 has no loss key"):
        bus.deliver(0, np.zeros((4, 3)), np.ones(4, dtype=bool), np.zeros(4, dtype=np.int32))


# ------------------------------------------------------------------------------------------ inbox order
def test_inbox_order_is_created_sender_sequence_not_call_order() -> None:
    bus = _bus(1, 5, ChannelConfig(latency=1), 0)
    pos, on, grp = np.zeros((5, 3)), np.ones(5, dtype=bool), np.zeros(5, dtype=np.int32)
    bus.send(AGENT, np.array([3, 1]), np.array([0, 0]), np.array([[3.0, 0], [1.0, 0]]), 0)
    bus.send(AGENT, np.array([1]), np.array([0]), np.array([[1.5, 0]]), 0)  # sender 1's second message
    bus.send_env(np.array([0]), np.array([[9.0, 0]]), 0)
    bus.deliver(1, pos, on, grp)
    # pushed as (created, sender, seq): env (-1), 1 #0, 1 #1, 3 #0; the last pushed is the newest (row 0)
    ib = bus.inbox
    assert ib.sender[0].tolist() == [3, 1, 1] and ib.payload[0, :, 0].tolist() == [3.0, 1.5, 1.0]


def test_a_world_of_a_batch_loses_what_a_single_world_loses() -> None:
    def fates(b: int, w: int) -> list[tuple[int, int, int, int]]:
        bus = MessageBus(b, 6, 2, ChannelConfig(loss=0.5), 3, None)
        for x in range(b):
            bus.reset_world(x, np.random.default_rng(100 + x - w))  # world w gets the seed 100
        s = b * 6
        snd = np.repeat(np.arange(6), 6) + 6 * w
        bus.send(AGENT, snd, np.tile(np.arange(6), 6) + 6 * w, np.zeros((36, 2)), 0)
        ev = bus.deliver(0, np.zeros((s, 3)), np.ones(s, dtype=bool), np.zeros(s, dtype=np.int32))
        d = ev.dropped
        return sorted(
            zip(
                (d.sender - 6 * w).tolist(),
                (d.receiver - 6 * w).tolist(),
                d.reason.tolist(),
                d.created.tolist(),
            )
        )

    one = fates(1, 0)
    assert one and one == fates(3, 1) == fates(2, 1)


# ------------------------------------------------------------------------- episodes started at any tick
def _episode_losses(start: int) -> list[tuple[int, ...]]:
    """Dropped (kind, sender, receiver, created - start, reason) of one fixed episode whose first tick is ``start``."""
    b, n = 2, 6
    bus = _bus(b, n, ChannelConfig(latency=1, loss=0.5), 11)
    s = b * n
    pos, on, grp = np.zeros((s, 3)), np.ones(s, dtype=bool), np.zeros(s, dtype=np.int32)
    out = []
    # sent between the reset and the first step: created at the start tick, keyed as the episode's step 0
    bus.send(AGENT, np.arange(s), (np.arange(s) + 1) % n + (np.arange(s) // n) * n, np.zeros((s, 2)), start)
    for t in range(start, start + 6):
        bus.set_starts(np.full(b, start))
        snd = np.repeat(np.arange(s), 2)
        bus.send(AGENT, snd, (snd + np.tile([1, 2], s)) % n + (snd // n) * n, np.zeros((2 * s, 2)), t)
        bus.send(GROUP, np.array([0, n]), np.array([0, 0]), np.zeros((2, 2)), t, group=grp)
        bus.send(HEARTBEAT, np.full(s, -1), np.arange(s), np.zeros((s, 2)), t)
        bus.send_env(np.arange(s), np.zeros((s, 2)), t)
        d = bus.deliver(t, pos, on, grp).dropped
        out += zip(
            d.kind.tolist(),
            d.sender.tolist(),
            d.receiver.tolist(),
            (d.created - start).tolist(),
            d.reason.tolist(),
        )
    return sorted(out)


def test_an_episode_loses_the_same_messages_whatever_tick_it_starts_at() -> None:
    at0 = _episode_losses(0)
    assert len(at0) > 20  # lossy enough to tell two draws apart
    assert _episode_losses(37) == at0 == _episode_losses(5)


def test_set_starts_checks_its_input() -> None:
    bus = _bus(2, 4, ChannelConfig(loss=0.5), 0)
    with pytest.raises(ValueError, match="starts must be"):
        bus.set_starts(np.zeros(3, dtype=np.int64))
    with pytest.raises(ValueError, match="starts must be"):
        bus.set_starts(np.array([0.5, 1.0]))


def test_a_reset_world_keys_its_losses_from_its_own_first_step() -> None:
    """A world reset after other steps loses what the same episode loses in a fresh world (comms stack)."""
    import agentsim_env

    cfg = {
        "n_agents": 8,
        "comms": {"heartbeat_period": 2, "heartbeat_timeout": 50, "loss": 0.5, "latency": 1},
    }

    def losses(warm: int) -> list[tuple[int, ...]]:
        env = agentsim_env.make("navigation", **cfg)
        env.reset(seed=3)
        zero = {a: {k: np.zeros(sp.shape) for k, sp in env.action_space(a).items()} for a in env.agents}
        for _ in range(warm):
            env.step({a: zero[a] for a in env.agents})
        env.reset(seed=9)
        world = env.world
        start = world.tick
        out = []
        for _ in range(8):
            env.step({a: zero[a] for a in env.agents})
            d = world.comms.events.bus.dropped
            out += zip(
                d.kind.tolist(),
                d.sender.tolist(),
                d.receiver.tolist(),
                (d.created - start).tolist(),
                d.reason.tolist(),
            )
        return sorted(out)

    fresh = losses(0)
    assert len(fresh) > 5
    assert losses(37) == fresh
