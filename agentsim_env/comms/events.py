"""Bus event records and the in-flight queue: what the bus logs and what it holds between send and delivery.

``MessageLog`` holds message events as column arrays (one row per event); ``DeliveryEvents`` groups one
step's sent, delivered and dropped logs. ``_Queue`` is the bus's private store of messages in flight and
``DueRows`` the messages it hands out when they are due (what a bus ships to the bus that owns a receiver).

Queue: growable column arrays; the live region is kept sorted by due step (appends are in step order; an
out-of-order append triggers one stable sort), so ``deliver`` slices a prefix: cost linear in the messages.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from agentsim_env.comms.messages import REASON_NONE


@dataclass(frozen=True, slots=True)
class MessageLog:
    """Message events as arrays, one row per event (for the data store).

    Attributes:
        msg: Message id ``(n,)`` int64 (a GROUP message has one id for all its receivers).
        kind: Kind code ``(n,)`` int8.
        sender: Sender slot ``(n,)`` int64 (-1 = environment / controller).
        target: Receiver slot, group id (GROUP) or -1 (controller) ``(n,)`` int64, as sent.
        receiver: Receiving slot ``(n,)`` int64 (-1: the controller, or a GROUP message not expanded).
        created: Step the message was sent ``(n,)`` int64.
        step: Step of this event ``(n,)`` int64.
        reason: Drop reason ``(n,)`` int8 (``messages.DROP_*``; 0 in sent and delivered rows).
    """

    msg: np.ndarray
    kind: np.ndarray
    sender: np.ndarray
    target: np.ndarray
    receiver: np.ndarray
    created: np.ndarray
    step: np.ndarray
    reason: np.ndarray

    def __len__(self) -> int:
        """Number of rows."""
        return int(self.msg.shape[0])

    @classmethod
    def make(cls, msg, kind, sender, target, receiver, created, step, reason=REASON_NONE) -> MessageLog:  # type: ignore[no-untyped-def]
        """Build a log of ``len(msg)`` rows; scalar columns are broadcast (fresh arrays)."""
        n = np.shape(msg)[0]
        cols = (msg, kind, sender, target, receiver, created, step, reason)
        return cls(
            *(
                np.full(n, c, dtype=_LOG_DTYPES[i]) if np.ndim(c) == 0 else np.array(c, _LOG_DTYPES[i])
                for i, c in enumerate(cols)
            )
        )

    def take(self, mask: np.ndarray) -> MessageLog:
        """The rows selected by a boolean mask or an index array."""
        return MessageLog(*(getattr(self, f.name)[mask] for f in fields(self)))

    @classmethod
    def concat(cls, parts: list[MessageLog]) -> MessageLog:
        """Concatenate logs (an empty log when ``parts`` is empty)."""
        if not parts:
            return cls.make(np.empty(0), 0, 0, 0, 0, 0, 0)
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))


_LOG_DTYPES = (np.int64, np.int8, np.int64, np.int64, np.int64, np.int64, np.int64, np.int8)


@dataclass(frozen=True, slots=True)
class DeliveryEvents:
    """The bus traffic of one step.

    Attributes:
        step: The step passed to ``deliver``.
        sent: Messages sent since the previous ``deliver`` (heartbeat answers included).
        delivered: (message, receiver) pairs delivered at ``step``.
        dropped: Bandwidth drops since the previous ``deliver`` and (message, receiver) pairs dropped now.
    """

    step: int
    sent: MessageLog
    delivered: MessageLog
    dropped: MessageLog


@dataclass(frozen=True, slots=True)
class DueRows:
    """Messages taken from a bus's queue at their due step: one row per message (not yet per receiver).

    The fields ``world`` (its episode key), ``created``, ``sender``, ``seq`` and ``kind`` are what a message's
    loss draws and inbox order are keyed by (see ``comms.bus``), so any bus delivers a row the same way.

    Attributes:
        msg: Message id ``(q,)`` int64 (unique within the bus that queued it).
        kind: Kind code ``(q,)`` int8.
        sender: Sender slot ``(q,)`` int64 (-1 = environment / controller).
        target: Receiver slot, group id (GROUP) or -1 (an answer to the controller) ``(q,)`` int64.
        world: World ``(q,)`` int64.
        created: Step the message was sent ``(q,)`` int64.
        seq: Sequence number ``(q,)`` int64 (see ``comms.bus``).
        payload: ``(q, D)`` float32.
    """

    msg: np.ndarray
    kind: np.ndarray
    sender: np.ndarray
    target: np.ndarray
    world: np.ndarray
    created: np.ndarray
    seq: np.ndarray
    payload: np.ndarray

    def __len__(self) -> int:
        """Number of messages."""
        return int(self.msg.shape[0])

    @classmethod
    def empty(cls, payload_dim: int) -> DueRows:
        """No messages (payload width ``payload_dim``)."""
        z = np.zeros(0, dtype=np.int64)
        return cls(z, np.zeros(0, dtype=np.int8), z, z, z, z, z, np.zeros((0, payload_dim), dtype=np.float32))

    def take(self, index: np.ndarray) -> DueRows:
        """The rows selected by a boolean mask or an index array (fresh arrays)."""
        return DueRows(*(getattr(self, f.name)[index] for f in fields(self)))

    @classmethod
    def concat(cls, parts: list[DueRows], payload_dim: int) -> DueRows:
        """Concatenate row sets in order (``empty(payload_dim)`` when there are none)."""
        if not parts:
            return cls.empty(payload_dim)
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))


class _Queue:
    """Messages in flight as growable columns; the live region ``[head, tail)`` is kept sorted by due step."""

    __slots__ = ("cols", "payload", "head", "tail", "last_due", "in_order")
    NAMES = ("msg", "kind", "sender", "target", "world", "created", "seq", "due")

    def __init__(self, cap: int, payload_dim: int) -> None:
        self.cols = {c: np.empty(cap, dtype=np.int8 if c == "kind" else np.int64) for c in self.NAMES}
        self.payload = np.empty((cap, payload_dim), dtype=np.float32)
        self.head = self.tail = 0
        self.last_due = -1
        self.in_order = True

    def __len__(self) -> int:
        return self.tail - self.head

    def append(self, payload: np.ndarray, **cols: np.ndarray) -> None:
        k = payload.shape[0]
        if k == 0:
            return
        cap, live = self.payload.shape[0], len(self)
        if live == 0:
            self.head = self.tail = 0
            self.last_due = -1  # order only matters among live messages
        if self.tail + k > cap:  # compact to the front, doubling when more than half full
            new_cap = max(cap, 2 * (live + k)) if live + k > cap // 2 else cap
            for c, a in self.cols.items():
                self.cols[c] = np.empty(new_cap, dtype=a.dtype)
                self.cols[c][:live] = a[self.head : self.tail]
            p = self.payload
            self.payload = np.empty((new_cap, p.shape[1]), dtype=np.float32)
            self.payload[:live] = p[self.head : self.tail]
            self.head, self.tail = 0, live
        sl = slice(self.tail, self.tail + k)
        for c in self.NAMES:
            self.cols[c][sl] = cols[c]
        self.payload[sl] = payload
        self.tail += k
        due = cols["due"]
        if due.min() < self.last_due:  # appended out of step order: sort once before the next pop
            self.in_order = False
        self.last_due = max(self.last_due, int(due.max()))

    def pop_due(self, step: int) -> dict[str, np.ndarray] | None:
        h, t = self.head, self.tail
        if h == t:
            return None
        if not self.in_order:
            order = h + np.argsort(self.cols["due"][h:t], kind="stable")
            for a in self.cols.values():
                a[h:t] = a[order]
            self.payload[h:t] = self.payload[order]
            self.in_order = True
        n = int(np.searchsorted(self.cols["due"][h:t], step, side="right"))
        if n == 0:
            return None
        # Copies: the region may be overwritten by answers appended during this delivery.
        batch = {c: a[h : h + n].copy() for c, a in self.cols.items()}
        batch["payload"] = self.payload[h : h + n].copy()
        self.head = h + n
        return batch

    def drop_world(self, world: int) -> None:
        """Remove the live messages of world ``world``, keeping the others in order."""
        h, t = self.head, self.tail
        if t > h:
            keep = self.cols["world"][h:t] != world
            if not keep.all():
                m = int(keep.sum())
                for c in self.NAMES:
                    self.cols[c][h : h + m] = self.cols[c][h:t][keep]
                self.payload[h : h + m] = self.payload[h:t][keep]
                self.tail = h + m
