"""The centralised message bus: agent, group, environment and heartbeat messages over a channel model.

``send`` validates a batch of messages, enforces the per-sender bandwidth of the step and queues the rest
with ``due = step + latency``; ``deliver(step, ...)`` takes everything due, expands GROUP messages to the
group's online members, filters (offline receiver, range, loss) and pushes the survivors into the
:class:`~agentsim_env.comms.inbox.Inbox`. Every step's traffic comes back as arrays (``DeliveryEvents``).

Rules (one line each, the tests check them):

- Slots never cross worlds: a unicast receiver must be in the sender's world; a GROUP message reaches the
  group's members in the sender's world only (the environment / controller, sender ``-1``, names the world).
- GROUP: every member of the group that is ONLINE at delivery time, in that world, except the sender.
  Offline members are not receivers (nothing is logged for them); an offline unicast receiver is a drop.
- Range (``max_range``): measured from the sender's position at delivery time, agent senders only; the
  environment and the controller have no position and are never range-limited.
- Loss: a (message, receiver) pair is lost when its keyed uniform ``u < loss`` (below). No draw at loss 0.
- Bandwidth: at most ``bandwidth`` accepted messages per agent sender per ``step`` (over all ``send`` calls
  of that step, in call order); the environment, the controller and heartbeat answers are not limited.
- Drop counters (``Inbox.dropped``): bandwidth drops and lost answers to the controller are charged to the
  sender; offline, range and loss drops to the receiver. Every (message, receiver) pair ends up in exactly
  one ``delivered`` or ``dropped`` row (a GROUP message dropped for bandwidth: one row, receiver -1).
- Heartbeats: a HEARTBEAT from the controller (sender -1) to a slot is delivered like a unicast; each
  delivery makes the receiver answer automatically with a HEARTBEAT to the controller (target -1), queued
  ``latency`` steps later (with latency 0 it arrives in the same ``deliver`` call), lost with probability
  ``loss`` and collected by ``take_answers`` (the group controller reads them). Answers enter no inbox.
- Bus messages have ``hops = 0`` (no relaying). Message ids are unique per bus until ``reset``; buses that
  share one world between them (below) number their messages independently, so ids may repeat across them.

Keyed loss draws: a pair's uniform is a hash of what the message is (``comms.delivery`` gives the key).

Inbox order: within one delivery call a receiver gets its rows in ``(created, sender, seq, kind)`` order
(the last one pushed is the newest, inbox row 0). The comms stack pushes the environment's collision notices
of the step before the bus's deliveries and the overlay's after them.

Split delivery (one world over several buses, each owning some receiver slots): ``take_due`` pops the due
rows, ``split.route`` says which bus must see each (by the owner of its receiver; GROUP rows go to all), and
``deliver_rows(rows, ..., mine=...)`` delivers the union of a bus's own and received rows into its own slots
only. ``deliver`` is ``take_due`` + ``deliver_rows`` over every slot, so both paths run the same code.

Event records, ``DueRows`` and the in-flight queue live in ``comms.events``, sequence numbers in
``comms.sequence``, input checks in ``comms.checks``, the channel model's settings in ``comms.channel``, which pairs
of a batch survive the channel in ``comms.delivery``, the numba kernels in ``comms.bus_kernels`` and
``comms.routing``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from agentsim_env.comms.bus_kernels import bandwidth_kernel
from agentsim_env.comms.channel import Bandwidth, ChannelConfig, Latency, Probability, Range
from agentsim_env.comms.checks import bool_mask, int_vector, validate_send, world_arrays
from agentsim_env.comms.delivery import channel_pairs
from agentsim_env.comms.events import DeliveryEvents, DueRows, MessageLog, _Queue
from agentsim_env.comms.inbox import Inbox
from agentsim_env.comms.messages import (
    AGENT,
    DROP_BANDWIDTH,
    ENV,
    GROUP,
    HEARTBEAT,
    KIND_NAMES,
)
from agentsim_env.comms.sequence import Sequencer

__all__ = [
    "BUS_KINDS",
    "Bandwidth",
    "ChannelConfig",
    "DeliveryEvents",
    "DueRows",
    "Latency",
    "MessageBus",
    "MessageLog",
    "Probability",
    "Range",
]

BUS_KINDS = (AGENT, GROUP, ENV, HEARTBEAT)
_ALL_SEEN = np.zeros(0, dtype=bool)
_ZERO_HOPS = np.zeros(1, dtype=np.int16)


class MessageBus:
    """Centralised bus of one simulation (all its worlds), with a channel model and per-slot inboxes.

    Attributes:
        n_worlds: Worlds B.
        n_agents: Agents per world N (slot ``s`` is in world ``s // N``).
        payload_dim: Payload width D.
        channel: The channel model.
        inbox: The inboxes; the overlay pushes its deliveries here too.
        keys: ``(B,)`` uint64 episode key of each world's loss draws (see the module docstring).
        starts: ``(B,)`` int64 step at which each world's episode began (``set_starts``); loss draws are keyed
            by the created step minus it.
        group: Group array ``(S,)`` used to validate GROUP targets at send time (by reference), or None.
    """

    __slots__ = tuple(
        "n_worlds n_agents payload_dim channel inbox keys starts group _keyed _world_of _queue _next_id _bw_used "
        "_bw_step _seq _sent_log _drop_log _ans_slot _ans_step _pushes".split()
    )

    def __init__(
        self,
        n_worlds: int,
        n_agents: int,
        payload_dim: int,
        channel: ChannelConfig,
        inbox_size: int,
        rng: np.random.Generator | Sequence[np.random.Generator] | None,
        *,
        group: np.ndarray | None = None,
        age_horizon: int = 100,
        hop_horizon: int = 16,
        pos_scale: float = 1.0,
    ) -> None:
        """Create an empty bus.

        Args:
            n_worlds: Worlds B (>= 1).
            n_agents: Agents per world N (>= 1).
            payload_dim: Payload width D (>= 0).
            channel: Channel model.
            inbox_size: Messages kept per slot M (>= 1).
            rng: Generator of the episode keys (spawned into one per world), one generator per world, or None
                (each world's key comes with its ``reset_world``; a lossy delivery before that raises).
            group: Optional ``(S,)`` group array (e.g. ``AgentState.group``) to validate GROUP targets.
            age_horizon: Inbox age feature horizon in steps (see ``Inbox``).
            hop_horizon: Inbox hops feature horizon (see ``Inbox``).
            pos_scale: Inbox relative-position scale in metres (see ``Inbox``).
        """
        for name, v in (("n_worlds", n_worlds), ("n_agents", n_agents)):
            if int(v) != v or int(v) < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if not isinstance(channel, ChannelConfig):
            raise ValueError(f"channel must be a ChannelConfig, got {type(channel).__name__}")
        self.n_worlds, self.n_agents = int(n_worlds), int(n_agents)
        self.payload_dim, self.channel = int(payload_dim), channel
        s = self.n_worlds * self.n_agents
        self.inbox = Inbox(
            s, inbox_size, payload_dim, age_horizon=age_horizon, hop_horizon=hop_horizon, pos_scale=pos_scale
        )
        self.group: np.ndarray | None = None
        if group is not None:
            self.bind_groups(group)
        self._world_of = np.arange(s, dtype=np.int64) // self.n_agents
        self._bw_used = np.zeros(s, dtype=np.int64)
        self._bw_step = np.full(s, -1, dtype=np.int64)
        self._seq = Sequencer(s)
        self.keys = np.zeros(self.n_worlds, dtype=np.uint64)
        self._keyed = np.zeros(self.n_worlds, dtype=bool)
        self.starts = np.zeros(self.n_worlds, dtype=np.int64)
        self.reset(rng)

    @property
    def n_slots(self) -> int:
        """Total slots S."""
        return self.n_worlds * self.n_agents

    @property
    def n_pending(self) -> int:
        """Messages queued and not yet delivered."""
        return len(self._queue)

    def bind_groups(self, group: np.ndarray) -> None:
        """Use ``group`` (``(S,)`` ints, read by reference) to validate GROUP targets in ``send``."""
        g = np.asarray(group)
        if g.shape != (self.n_slots,) or not np.issubdtype(g.dtype, np.integer):
            raise ValueError(f"group must be an integer array of shape ({self.n_slots},), got {g.dtype} {g.shape}")
        self.group = g

    def reset(self, rng: np.random.Generator | Sequence[np.random.Generator] | None) -> None:
        """Drop everything in flight, empty the inboxes and logs, and take new episode keys.

        Args:
            rng: One generator per world, one generator (used as is for a single world, spawned into one
                child per world otherwise), or None (no key until each world's ``reset_world``). Each
                world's key is ``rng.integers(2**63)`` of its generator.
        """
        rngs: list[np.random.Generator]
        if rng is None:
            rngs = []
        elif isinstance(rng, np.random.Generator):
            rngs = [rng] if self.n_worlds == 1 else [*rng.spawn(self.n_worlds)]
        else:
            rngs = list(rng)
            if len(rngs) != self.n_worlds or not all(isinstance(r, np.random.Generator) for r in rngs):
                raise ValueError(f"rng must be a numpy.random.Generator or {self.n_worlds} of them")
        self._keyed[:] = False
        for w, r in enumerate(rngs):
            self._set_key(w, r)
        self.inbox.clear()
        self._bw_used[:] = 0
        self._bw_step[:] = -1
        self._seq.reset()
        self._queue = _Queue(16, self.payload_dim)
        self._next_id = 0
        self._sent_log: list[MessageLog] = []
        self._drop_log: list[MessageLog] = []
        self._ans_slot: list[np.ndarray] = []
        self._ans_step: list[np.ndarray] = []
        self._pushes: list[tuple[Any, ...]] = []

    def set_starts(self, starts: np.ndarray) -> None:
        """Set the step at which each world's current episode began (loss draws key ``created - starts[w]``).

        Args:
            starts: ``(B,)`` integer steps, e.g. ``tick - step_count`` of the step being delivered.
        """
        a = np.asarray(starts)
        if a.shape != (self.n_worlds,) or not np.issubdtype(a.dtype, np.integer):
            raise ValueError(f"starts must be an integer array of shape ({self.n_worlds},), got {a.dtype} {a.shape}")
        self.starts[:] = a

    def reset_world(self, world: int, rng: np.random.Generator) -> None:
        """Drop world ``world``'s traffic and key its loss draws by ``rng.integers(2**63)`` (its episode's key)."""
        self.drop_world(world)
        self._set_key(world, rng)

    def _set_key(self, world: int, rng: np.random.Generator) -> None:
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        self.keys[world] = np.uint64(rng.integers(2**63))
        self._keyed[world] = True

    def _check_keys(self, world: np.ndarray) -> None:
        """ValueError when a row's world has no episode key yet."""
        if not self._keyed.all() and not self._keyed[world].all():
            w = int(world[~self._keyed[world]][0])
            raise ValueError(f"world {w} has no loss key: reset it (reset_world) before a lossy delivery")

    def drop_world(self, world: int) -> None:
        """Forget world ``world``'s traffic (messages in flight, answers, inboxes), e.g. when it is reset alone."""
        n = self.n_agents
        slots = np.arange(world * n, (world + 1) * n)
        self._queue.drop_world(world)
        answers = list(zip(self._ans_slot, self._ans_step))
        self._ans_slot = [a[a // n != world] for a, _ in answers]
        self._ans_step = [b[a // n != world] for a, b in answers]
        self.inbox.clear(slots)
        self._bw_used[slots] = 0
        self._bw_step[slots] = -1
        self._seq.drop_world(world, slots)

    def _new_ids(self, k: int) -> np.ndarray:
        ids = np.arange(self._next_id, self._next_id + k, dtype=np.int64)
        self._next_id += k
        return ids

    # ------------------------------------------------------------------ sending
    def send(
        self,
        kind: int,
        sender: np.ndarray,
        target: np.ndarray,
        payload: np.ndarray,
        step: int,
        *,
        world: np.ndarray | None = None,
        group: np.ndarray | None = None,
    ) -> np.ndarray:
        """Validate and queue ``k`` messages of one kind (a rejected batch queues nothing).

        Args:
            kind: ``AGENT``, ``GROUP``, ``ENV`` or ``HEARTBEAT`` (OVERLAY goes through the overlay).
            sender: Sender slots ``(k,)`` (-1 = environment / controller; ENV requires -1).
            target: ``(k,)`` receiver slot (AGENT, ENV, controller HEARTBEAT), group id (GROUP), or -1
                (an agent's HEARTBEAT answer to the controller).
            payload: ``(k, D)`` finite values.
            step: Current step (>= 0).
            world: ``(k,)`` (or scalar) world of each message; required for GROUP messages with sender -1,
                must match the sender's world otherwise.
            group: Group array to validate GROUP targets against (default: the bound ``self.group``).

        Returns:
            ``(k,)`` bool: accepted (False = dropped for bandwidth, counted and logged).
        """
        kind = int(kind)
        if kind not in BUS_KINDS:
            names = ", ".join(f"{KIND_NAMES[k]}={k}" for k in BUS_KINDS)
            raise ValueError(f"kind must be one of {names}, got {kind}")
        if int(step) != step or step < 0:
            raise ValueError(f"step must be an integer >= 0, got {step!r}")
        step = int(step)
        snd = int_vector(sender, "sender")
        k = snd.shape[0]
        tgt = int_vector(target, "target", k)
        pay = np.asarray(payload, dtype=np.float32)
        if pay.shape != (k, self.payload_dim):
            raise ValueError(f"payload must have shape ({k}, {self.payload_dim}) (k, D), got {pay.shape}")
        bad = ~np.isfinite(pay).all(axis=1) if self.payload_dim else np.zeros(k, dtype=bool)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"payload must be finite: row {i} (sender {snd[i]}) holds NaN/inf")
        g = self.group if group is None else np.asarray(group)
        wld = validate_send(kind, snd, tgt, world, g, self.n_worlds, self.n_agents)
        return self.enqueue(np.full(k, kind, dtype=np.int8), snd, tgt, wld, pay, step)

    def enqueue(
        self,
        kind: np.ndarray,
        sender: np.ndarray,
        target: np.ndarray,
        world: np.ndarray,
        payload: np.ndarray,
        step: int,
    ) -> np.ndarray:
        """Unchecked ``send`` for producers whose rows are valid by construction (the comms stack).

        Rows may mix kinds; they are accepted (bandwidth), logged and queued in the given order, exactly as
        consecutive ``send`` calls of the same rows would.

        Args:
            kind: ``(k,)`` int8 kind per row.
            sender: ``(k,)`` int64 sender slots (-1 = environment / controller).
            target: ``(k,)`` int64 targets (receiver slot, group id, or -1), as in ``send``.
            world: ``(k,)`` int64 world per row.
            payload: ``(k, D)`` float32, finite.
            step: Current step (>= 0).

        Returns:
            ``(k,)`` bool: accepted (False = dropped for bandwidth, counted and logged).
        """
        k = sender.shape[0]
        seq = self._seq.number(kind, sender, target, world, step)
        acc = self._bandwidth(sender, step)
        created = np.full(k, step, dtype=np.int64)
        log = MessageLog(
            self._new_ids(k),
            kind,
            sender,
            target,
            np.where(kind == GROUP, -1, target),
            created,
            created.copy(),
            np.zeros(k, dtype=np.int8),
        )
        self._sent_log.append(log)
        if acc.all():
            a, pay, wld, sq = log, payload, world, seq
        else:
            d = log.take(~acc)
            self._drop_log.append(
                MessageLog(
                    d.msg,
                    d.kind,
                    d.sender,
                    d.target,
                    d.receiver,
                    d.created,
                    d.step,
                    np.full(len(d), DROP_BANDWIDTH, dtype=np.int8),
                )
            )
            self.inbox.add_dropped(d.sender)
            a, pay, wld, sq = log.take(acc), payload[acc], world[acc], seq[acc]
        self._queue.append(
            pay,
            msg=a.msg,
            kind=a.kind,
            sender=a.sender,
            target=a.target,
            world=wld,
            created=a.created,
            seq=sq,
            due=a.created + self.channel.latency,
        )
        return acc

    def send_env(self, receiver: np.ndarray, payload: np.ndarray, step: int) -> np.ndarray:
        """Queue environment messages (sender -1) to slots; see ``messages.env_collision_payload``.

        Args:
            receiver: Receiver slots ``(k,)``.
            payload: ``(k, D)``.
            step: Current step.

        Returns:
            ``(k,)`` bool, all True (the environment is not bandwidth-limited).
        """
        r = int_vector(receiver, "receiver")
        return self.send(ENV, np.full(r.shape[0], -1, dtype=np.int64), r, payload, step)

    def _bandwidth(self, snd: np.ndarray, step: int) -> np.ndarray:
        acc = np.ones(snd.shape[0], dtype=bool)
        if self.channel.bandwidth > 0:
            bandwidth_kernel(snd, step, self.channel.bandwidth, self._bw_used, self._bw_step, acc)
        return acc

    # ------------------------------------------------------------------ delivery
    def deliver(
        self, step: int, pos: np.ndarray, online: np.ndarray, group: np.ndarray, *, push: bool = True
    ) -> DeliveryEvents:
        """Deliver every message due at ``step`` (or earlier) and return the step's traffic.

        The same as ``deliver_rows(take_due(step), ...)`` over every slot, repeated while latency-0 heartbeat
        answers become due in this call.

        Args:
            step: Current step.
            pos: Current positions ``(S, 3)`` (range check from the sender's current position).
            online: ``(S,)`` bool; offline slots never receive.
            group: ``(S,)`` group ids (-1 = none) used to expand GROUP messages now.
            push: Write the deliveries into the inboxes now; False leaves them to the caller (``take_pushes``),
                who pushes them with its own (one pass over the inboxes instead of two).

        Returns:
            The step's events (sent since the previous call, delivered and dropped).
        """
        step = int(step)
        pos, online, group = world_arrays(self.n_slots, pos, online, group)
        self._pushes = []
        delivered = [self._deliver_rows(self.take_due(step), step, pos, online, group, None, _ALL_SEEN)]
        while len(rows := self.take_due(step)):
            # a second round happens only when latency-0 heartbeat answers became due in this call
            delivered.append(self._deliver_rows(rows, step, pos, online, group, None, _ALL_SEEN))
        if push:
            self.inbox.push_batches(self.take_pushes())
        return self._events(step, delivered)

    def take_due(self, step: int) -> DueRows:
        """Pop the messages due at ``step`` (or earlier), in queue order; none are delivered yet."""
        b = self._queue.pop_due(int(step))
        if b is None:
            return DueRows.empty(self.payload_dim)
        return DueRows(b["msg"], b["kind"], b["sender"], b["target"], b["world"], b["created"], b["seq"], b["payload"])

    def deliver_rows(
        self,
        rows: DueRows,
        step: int,
        pos: np.ndarray,
        online: np.ndarray,
        group: np.ndarray,
        *,
        mine: np.ndarray | None = None,
        seen: np.ndarray | None = None,
        push: bool = True,
    ) -> DeliveryEvents:
        """Deliver ``rows`` (from ``take_due`` of this bus or of others) into the inboxes of own receivers.

        A pair (message, receiver) is handled here only when the receiver is own (``mine[r]``), or, for a
        heartbeat answer to the controller, when its sender is; the other pairs are left to the bus that owns
        them (no event, no counter). GROUP messages expand over own online members. Answers created by the
        heartbeats delivered here are queued in this bus (``take_due`` hands them out when due).

        Args:
            rows: Due messages, any order (delivered in the inbox order of the module docstring).
            step: Current step.
            pos: ``(S, 3)`` positions; only own receivers and seen senders are read.
            online: ``(S,)`` bool; only the values of own slots matter.
            group: ``(S,)`` group ids; only the values of own slots matter.
            mine: ``(S,)`` bool own slots, or None for every slot.
            seen: ``(S,)`` bool senders whose position is known, or None for all; with a range limit an
                unseen sender is out of range (the caller sees every sender within range of an own receiver).
            push: Write the deliveries into the inboxes now (False: ``take_pushes`` hands them out).

        Returns:
            This call's events: the messages sent and dropped since the previous ``deliver`` /
            ``deliver_rows`` and the pairs delivered and dropped now.
        """
        step = int(step)
        pos, online, group = world_arrays(self.n_slots, pos, online, group)
        own, known = bool_mask(mine, "mine", self.n_slots), bool_mask(seen, "seen", self.n_slots)
        n0 = len(self._pushes)
        delivered = self._deliver_rows(rows, step, pos, online, group, own, _ALL_SEEN if known is None else known)
        if push:
            new, self._pushes = self._pushes[n0:], self._pushes[:n0]
            self.inbox.push_batches(new)
        return self._events(step, [delivered])

    def _events(self, step: int, delivered: list[MessageLog]) -> DeliveryEvents:
        """The events of a delivery: the logged sends and drops (taken) and ``delivered``."""
        sent, dropped = MessageLog.concat(self._sent_log), MessageLog.concat(self._drop_log)
        self._sent_log, self._drop_log = [], []
        return DeliveryEvents(step, sent, MessageLog.concat(delivered), dropped)

    def take_pushes(self) -> list[tuple[Any, ...]]:
        """The deliveries of the latest ``deliver(..., push=False)`` as ``Inbox.push_batches`` batches (once)."""
        out, self._pushes = self._pushes, []
        return out

    def take_answers(self) -> tuple[np.ndarray, np.ndarray]:
        """Heartbeat answers that reached the controller since the previous call.

        Returns:
            ``(slots, steps)``: the answering slots and the step each answer arrived, int64.
        """
        if not self._ans_slot:
            return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
        out = np.concatenate(self._ans_slot), np.concatenate(self._ans_step)
        self._ans_slot, self._ans_step = [], []
        return out

    def _deliver_rows(self, rows, step, pos, online, group, mine, seen) -> MessageLog:  # type: ignore[no-untyped-def]
        ok, dr, n_hb, n_ans = channel_pairs(
            rows,
            self.channel,
            self.inbox,
            self._world_of,
            self.n_worlds,
            self.n_agents,
            self.keys,
            self.starts,
            pos,
            online,
            group,
            mine,
            seen,
            self._check_keys,
        )
        if dr[0].shape[0]:
            when = np.full(dr[0].shape[0], step, dtype=np.int64)
            self._drop_log.append(MessageLog(dr[0], dr[1], dr[2], dr[3], dr[4], dr[5], when, dr[6]))
        d_msg, d_kind, d_snd, d_tgt, d_rcv, d_cre, d_row = ok
        n_ok = d_msg.shape[0]
        if n_ok > n_ans:  # rows with receiver -1 (answers to the controller) are skipped by the push
            hops = np.broadcast_to(_ZERO_HOPS, (n_ok,))  # bus messages travel no hops
            self._pushes.append((d_rcv, d_kind, d_snd, hops, d_cre, rows.payload, d_row))
        if n_ans:
            ans = d_rcv < 0
            self._ans_slot.append(d_snd[ans])
            self._ans_step.append(np.full(n_ans, step, dtype=np.int64))
        if n_hb:  # each member that got a heartbeat answers the controller through the channel
            self._answer(d_rcv[(d_rcv >= 0) & (d_kind == HEARTBEAT)], step)
        return MessageLog(
            d_msg,
            d_kind,
            d_snd,
            d_tgt,
            d_rcv,
            d_cre,
            np.full(n_ok, step, dtype=np.int64),
            np.zeros(n_ok, dtype=np.int8),
        )

    def _answer(self, hb: np.ndarray, step: int) -> None:
        """Queue the heartbeat answers of slots ``hb`` (created now, numbered after their other messages)."""
        n_hb = hb.shape[0]
        ids = self._new_ids(n_hb)
        created = np.full(n_hb, step, dtype=np.int64)
        minus = np.full(n_hb, -1, dtype=np.int64)
        seq = self._seq.slots(hb, step)
        kind = np.full(n_hb, HEARTBEAT, dtype=np.int8)
        self._sent_log.append(
            MessageLog(ids, kind, hb, minus, minus.copy(), created, created.copy(), np.zeros(n_hb, dtype=np.int8))
        )
        self._queue.append(
            np.zeros((n_hb, self.payload_dim), dtype=np.float32),
            msg=ids,
            kind=kind.copy(),
            sender=hb,
            target=minus,
            world=self._world_of[hb],
            created=created,
            seq=seq,
            due=created + self.channel.latency,
        )
