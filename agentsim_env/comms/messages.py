"""Message vocabulary and the per-slot inbox.

Messages are rows of arrays, never Python objects. This module owns what every producer of messages shares:
the kind codes, the drop-reason codes, the environment (collision) payload encoding, and the :class:`Inbox`
into which the bus (``comms.bus``) and the overlay (``comms.overlay``) push what agents receive.

Inbox layout: per slot the ``M`` newest received messages, **newest first** (row 0 is the newest). A push
shifts older rows down; a message pushed past row ``M - 1`` is forgotten (it was still *received*, so it is
counted in ``received``). Within one step a slot receives the environment's collision notices first, then the
bus's deliveries in ``(created, sender, seq, kind)`` order (``comms.bus``), then the overlay's: the last of them
is row 0. ``dropped`` counts messages lost on the way: those addressed to the slot (receiver
offline, out of range, lost) and the slot's own messages refused for bandwidth or lost on the way to the
group controller (see ``comms.bus``).

Observation features per message (``Inbox.observe``), ``FEATURES_PER_MESSAGE + D`` float32 values:

=====  =====================================================================================
index  meaning
=====  =====================================================================================
0      valid (1 for a message, 0 for an empty row; an empty row is all zeros)
1-5    kind one-hot: AGENT, GROUP, ENV, OVERLAY, HEARTBEAT
6-8    sender position minus receiver position (x, y, z) / ``pos_scale`` (zeros for sender -1)
9      hops: ``min(hops, hop_horizon) / hop_horizon`` in [0, 1] (0 for bus messages)
10     age: ``clip(step - created, 0, age_horizon) / age_horizon`` in [0, 1]
11..   payload (D values, as sent)
=====  =====================================================================================

The sender's position is read at observation time (its *current* position), as a receiver would locate a
live transmitter; the environment and the group controller (sender ``-1``) have no position.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import numba as nb
import numpy as np

from agentsim_env.core.threads import RowThreads

AGENT = 1
"""Agent -> agent unicast (sender slot -> receiver slot)."""
GROUP = 2
"""Sender (agent or controller) -> every online member of a group in the sender's world."""
ENV = 3
"""Environment -> agent (e.g. a collision naming the other agent or the object)."""
OVERLAY = 4
"""Peer-to-peer flood delivered by the overlay (never queued on the bus)."""
HEARTBEAT = 5
"""Group controller -> member, and the member's automatic answer -> controller."""
N_KINDS = 5
KIND_NAMES = {AGENT: "AGENT", GROUP: "GROUP", ENV: "ENV", OVERLAY: "OVERLAY", HEARTBEAT: "HEARTBEAT"}

_SAME_ROWS = np.zeros(0, dtype=np.int64)  # push_rows: message j takes payload row j
#: The push kernel's one signature: receiver, kind, sender, hops, created, payload, rows of each batch.
_BATCH_DTYPES = (np.int64, np.int8, np.int64, np.int64, np.int64, np.float32, np.int64)
_EMPTY_BATCH = (
    _SAME_ROWS,
    np.zeros(0, dtype=np.int8),
    _SAME_ROWS,
    _SAME_ROWS,
    _SAME_ROWS,
    np.zeros((0, 0), dtype=np.float32),
    _SAME_ROWS,
    False,
)


def _kernel_batch(batch: tuple[Any, ...]) -> tuple[Any, ...]:
    """``batch`` with every array C-contiguous, writable and of the push kernel's dtype, and its table flag.

    numba compiles a kernel once per signature, and a signature tells C-contiguous from strided arrays (a
    stride-0 broadcast of one kind or hop count is strided with two messages or more, contiguous with one) and
    writable from read-only ones (Ray hands shards read-only arrays). Producers hand all of these; one form
    keeps the kernel at one compiled version, whatever a step delivers. The arrays are a step's messages, so
    the copies this may take are small; arrays already in form pass through untouched.
    """
    out: list[np.ndarray | bool] = []
    for a, dtype in zip(batch[:7], _BATCH_DTYPES):
        if a.dtype != dtype or not a.flags.c_contiguous or not a.flags.writeable:
            a = np.array(a, dtype=dtype, order="C")  # a fresh array: contiguous and writable
        out.append(a)
    out.append(bool(batch[7]) if len(batch) > 7 else False)
    return tuple(out)


FEATURES_PER_MESSAGE = 11
"""Observation features of one message before its payload; a row has ``FEATURES_PER_MESSAGE + D`` values."""

# Why a message (for one receiver) was not delivered; 0 in the rows of sent / delivered events.
REASON_NONE = 0
DROP_BANDWIDTH = 1  # the sender had used its messages for this step (counted at the sender)
DROP_OFFLINE = 2  # the receiver was offline at delivery time
DROP_RANGE = 3  # the receiver was beyond max_range of the sender's current position
DROP_LOSS = 4  # lost on the channel (random draw)
REASON_NAMES = {
    REASON_NONE: "none",
    DROP_BANDWIDTH: "bandwidth",
    DROP_OFFLINE: "offline",
    DROP_RANGE: "range",
    DROP_LOSS: "loss",
}

# Environment message encoding: payload[0] says what the slot collided with, payload[1] which one
# (the other agent's index within its world, ``slot % n_agents``, or the static object's index within its world);
# the remaining payload values are 0. Exact in float32 for ids below 2**24. A narrower payload keeps what fits:
# D = 1 carries only what was hit, D = 0 only the message itself (its kind says it is from the environment).
ENV_COLLISION_AGENT = 1
ENV_COLLISION_OBJECT = 2


def env_collision_payload(what: np.ndarray | int, ident: np.ndarray, payload_dim: int) -> np.ndarray:
    """Build environment-message payloads that name what each slot collided with.

    Args:
        what: ``ENV_COLLISION_AGENT`` or ``ENV_COLLISION_OBJECT``, a scalar or ``(k,)``.
        ident: The other agent's index within the world (``slot % n_agents``) or the object's index within
            its world (``Scene.index_in_world``) ``(k,)``.
        payload_dim: Payload width D of the bus (>= 0; the fields that do not fit are left out).

    Returns:
        ``(k, D)`` float32 with ``[:, 0] = what`` (D >= 1), ``[:, 1] = ident`` (D >= 2) and zeros elsewhere.
    """
    if payload_dim < 0:
        raise ValueError(f"payload_dim must be >= 0, got {payload_dim}")
    ident = np.asarray(ident).reshape(-1)
    what_arr = np.broadcast_to(np.asarray(what), ident.shape)
    if not np.all(np.isin(what_arr, (ENV_COLLISION_AGENT, ENV_COLLISION_OBJECT))):
        raise ValueError("what must be ENV_COLLISION_AGENT (1) or ENV_COLLISION_OBJECT (2)")
    if np.any(ident < 0):
        raise ValueError("ident must be >= 0")
    out = np.zeros((ident.shape[0], payload_dim), dtype=np.float32)
    if payload_dim >= 1:
        out[:, 0] = what_arr
    if payload_dim >= 2:
        out[:, 1] = ident
    return out


@nb.njit(cache=True, nogil=True)
def _push_count(newest, taken, ra, rb):  # type: ignore[no-untyped-def]
    # Pass 1 of a push of batches a then b (as one push of their concatenation): walk the messages newest first
    # and keep, per receiver (>= 0), the M newest (index into a ++ b) and the count.
    m = newest.shape[1]
    na = ra.shape[0]
    for g in range(na + rb.shape[0] - 1, -1, -1):
        s = ra[g] if g < na else rb[g - na]
        if s < 0:
            continue
        t = taken[s]
        if t < m:
            newest[s, t] = g
        taken[s] = t + 1


@nb.njit(cache=True, nogil=True)
def _push_kernel(
    lo,
    hi,
    valid,
    kind,
    sender,
    hops,
    created,
    payload,
    received,
    newest,
    taken,  # type: ignore[no-untyped-def]
    ra,
    ka,
    sa,
    ha,
    ca,
    pa,
    qa,
    ta,
    rb,
    kb,
    sb,
    hb,
    cb,
    pb,
    qb,
    tb,
):
    # Pass 2 of a push (after ``_push_count``) into the inboxes of slots [lo, hi): ranges on different threads
    # touch different inboxes. Message j of a batch goes to slot r[j] with payload row p[q[j]] (row j when q is
    # empty) and hops clipped to [0, 32767]; its sender and created step are s[j] and c[j], or s[q[j]] and
    # c[q[j]] when the batch's flag t says they are tables too (the overlay's flood table: a few rows that stay
    # in the cache, where per-message columns are read at random). The inputs come in one form
    # (``_kernel_batch``), so this compiles once. The receivers are walked in slot order (the inbox arrays stream
    # through the cache once): shift the old rows down by min(count, M), write the new ones on top.
    m = valid.shape[1]
    d = payload.shape[2]
    na = ra.shape[0]
    for s in range(lo, hi):
        c = taken[s]
        if c == 0:
            continue
        taken[s] = 0
        received[s] += c
        shift = min(c, m)
        for i in range(m - 1, shift - 1, -1):
            valid[s, i] = valid[s, i - shift]
            kind[s, i] = kind[s, i - shift]
            sender[s, i] = sender[s, i - shift]
            hops[s, i] = hops[s, i - shift]
            created[s, i] = created[s, i - shift]
            for x in range(d):  # explicit loops: numba slice copies cost ~10x more for small D
                payload[s, i, x] = payload[s, i - shift, x]
        for i in range(shift):
            g = newest[s, i]
            valid[s, i] = True
            if g < na:
                row = g if qa.shape[0] == 0 else qa[g]
                at = row if ta else g
                kind[s, i], sender[s, i], created[s, i] = ka[g], sa[at], ca[at]
                hops[s, i] = min(max(ha[g], 0), 32767)
                for x in range(d):
                    payload[s, i, x] = pa[row, x]
            else:
                g -= na
                row = g if qb.shape[0] == 0 else qb[g]
                at = row if tb else g
                kind[s, i], sender[s, i], created[s, i] = kb[g], sb[at], cb[at]
                hops[s, i] = min(max(hb[g], 0), 32767)
                for x in range(d):
                    payload[s, i, x] = pb[row, x]


@nb.njit(cache=True, inline="always")
def _bound(v, lim):  # type: ignore[no-untyped-def]
    # v clipped to [-lim, lim] as np.clip does it (NaN stays NaN)
    if v > lim:
        return lim
    if v < -lim:
        return -lim
    return v


@nb.njit(cache=True, inline="always", error_model="numpy")
def _observe_row(
    s,
    r,
    valid,
    kind,
    sender,
    hops,
    created,
    payload,
    pos,
    step,
    pos_scale,
    age_h,
    hop_h,
    out,
    c0,  # type: ignore[no-untyped-def]  # noqa: E501
    lim,
):
    # Slot s's inbox into row r of the 2D ``out`` from column c0 (message i at c0 + i F), each value clipped to
    # [-lim, lim]; every output value is written once (the buffer may be reused).
    m = valid.shape[1]
    d = payload.shape[2]
    f = FEATURES_PER_MESSAGE + d
    for i in range(m):
        c = c0 + i * f
        if not valid[s, i]:
            for x in range(f):
                out[r, c + x] = 0.0
            continue
        out[r, c] = 1.0
        k = kind[s, i]
        for x in range(1, 6):  # kinds 1..5 map to columns 1..5
            out[r, c + x] = 1.0 if x == k else 0.0
        q = sender[s, i]
        for a in range(3):
            out[r, c + 6 + a] = _bound((pos[q, a] - pos[s, a]) / pos_scale, lim) if q >= 0 else 0.0
        out[r, c + 9] = min(max(hops[s, i], 0), hop_h) / hop_h
        out[r, c + 10] = min(max(step - created[s, i], 0), age_h) / age_h
        for x in range(d):
            out[r, c + FEATURES_PER_MESSAGE + x] = _bound(payload[s, i, x], lim)


@nb.njit(cache=True, nogil=True, error_model="numpy")  # no zero-division checks: every divisor is >= 1 or > 0
def _observe_kernel(
    lo,
    hi,
    valid,
    kind,
    sender,
    hops,
    created,
    payload,
    pos,
    step,
    pos_scale,
    age_h,
    hop_h,
    out,  # type: ignore[no-untyped-def]  # noqa: E501
    c0,
    lim,
):
    for s in range(lo, hi):
        _observe_row(
            s,
            s,
            valid,
            kind,
            sender,
            hops,
            created,
            payload,
            pos,
            step,
            pos_scale,
            age_h,
            hop_h,
            out,
            c0,
            lim,
        )


@nb.njit(cache=True, error_model="numpy")
def _observe_rows_kernel(
    rows,
    valid,
    kind,
    sender,
    hops,
    created,
    payload,
    pos,
    step,
    pos_scale,
    age_h,
    hop_h,  # type: ignore[no-untyped-def]
    out,
    lim,
):
    for r in range(rows.shape[0]):
        _observe_row(
            rows[r],
            r,
            valid,
            kind,
            sender,
            hops,
            created,
            payload,
            pos,
            step,
            pos_scale,
            age_h,
            hop_h,
            out,
            0,
            lim,
        )


class Inbox:
    """The ``M`` newest received messages of every slot, newest first, as arrays.

    Attributes:
        n_slots: Number of slots S.
        size: Messages kept per slot M.
        payload_dim: Payload width D.
        age_horizon: Age (steps) that maps to feature value 1 (older ages are clipped).
        hop_horizon: Hop count that maps to feature value 1 (more hops are clipped).
        pos_scale: Metres per unit of the relative-position features.
        valid: ``(S, M)`` bool, whether the row holds a message.
        kind: ``(S, M)`` int8 message kind.
        sender: ``(S, M)`` int64 sender slot (-1 = environment / controller).
        hops: ``(S, M)`` int16 hops travelled (0 on the bus, >= 1 on the overlay).
        created: ``(S, M)`` int64 step the message was sent.
        payload: ``(S, M, D)`` float32.
        received: ``(S,)`` int64 messages delivered to the slot.
        dropped: ``(S,)`` int64 messages addressed to the slot (or sent by it) that were lost.
    """

    __slots__ = (
        "n_slots",
        "size",
        "payload_dim",
        "age_horizon",
        "hop_horizon",
        "pos_scale",
        "valid",
        "kind",
        "sender",
        "hops",
        "created",
        "payload",
        "received",
        "dropped",
        "_newest",
        "_taken",
        "threads",
    )

    def __init__(
        self,
        n_slots: int,
        size: int,
        payload_dim: int,
        *,
        age_horizon: int = 100,
        hop_horizon: int = 16,
        pos_scale: float = 1.0,
    ) -> None:
        """Allocate an empty inbox.

        Args:
            n_slots: Number of slots S (>= 1).
            size: Messages kept per slot M (>= 1).
            payload_dim: Payload width D (>= 0).
            age_horizon: Steps of age mapped to 1 in the age feature (>= 1).
            hop_horizon: Hops mapped to 1 in the hops feature (>= 1).
            pos_scale: Divisor of the relative-position features in metres (> 0).
        """
        for name, value, lo in (
            ("n_slots", n_slots, 1),
            ("size", size, 1),
            ("payload_dim", payload_dim, 0),
            ("age_horizon", age_horizon, 1),
            ("hop_horizon", hop_horizon, 1),
        ):
            if int(value) != value or int(value) < lo:
                raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
        if not (np.isfinite(pos_scale) and pos_scale > 0):
            raise ValueError(f"pos_scale must be a finite number > 0, got {pos_scale!r}")
        s, m, d = int(n_slots), int(size), int(payload_dim)
        self.n_slots, self.size, self.payload_dim = s, m, d
        self.age_horizon, self.hop_horizon, self.pos_scale = (
            int(age_horizon),
            int(hop_horizon),
            float(pos_scale),
        )
        self.valid = np.zeros((s, m), dtype=bool)
        self.kind = np.zeros((s, m), dtype=np.int8)
        self.sender = np.full((s, m), -1, dtype=np.int64)
        self.hops = np.zeros((s, m), dtype=np.int16)
        self.created = np.zeros((s, m), dtype=np.int64)
        self.payload = np.zeros((s, m, d), dtype=np.float32)
        self.received = np.zeros(s, dtype=np.int64)
        self.dropped = np.zeros(s, dtype=np.int64)
        # push scratch: the M newest new messages of each slot and how many it got (all 0 between pushes)
        self._newest = np.zeros((s, m), dtype=np.int64)
        self._taken = np.zeros(s, dtype=np.int64)
        self.threads = RowThreads(1)
        """Threads of the push and observe kernels (slot ranges); results do not depend on them."""

    @property
    def n_features(self) -> int:
        """Features per message row of ``observe``: ``FEATURES_PER_MESSAGE + D``."""
        return FEATURES_PER_MESSAGE + self.payload_dim

    def push(
        self,
        receiver: np.ndarray,
        kind: np.ndarray | int,
        sender: np.ndarray | int,
        hops: np.ndarray | int,
        created: np.ndarray | int,
        payload: np.ndarray,
    ) -> None:
        """Deliver ``k`` messages; messages to the same receiver keep their order (the last is the newest).

        Args:
            receiver: Receiver slots ``(k,)``.
            kind: Kind code(s), scalar or ``(k,)``.
            sender: Sender slot(s) (-1 = environment / controller), scalar or ``(k,)``.
            hops: Hops travelled, scalar or ``(k,)`` (clipped to the int16 range).
            created: Step(s) the messages were sent, scalar or ``(k,)``.
            payload: ``(k, D)`` (or ``(D,)``, shared by all ``k``).
        """
        r = np.asarray(receiver, dtype=np.int64).reshape(-1)
        k = r.shape[0]
        if k == 0:
            return
        if r.min() < 0 or r.max() >= self.n_slots:
            raise ValueError(f"receiver must be slots in [0, {self.n_slots}), got min {r.min()} max {r.max()}")
        kd = np.broadcast_to(np.asarray(kind), (k,)).astype(np.int8)
        if kd.min() < 1 or kd.max() > N_KINDS:
            raise ValueError(f"kind must be in 1..{N_KINDS} ({', '.join(KIND_NAMES.values())})")
        sd = np.broadcast_to(np.asarray(sender), (k,)).astype(np.int64)
        hd = np.clip(np.broadcast_to(np.asarray(hops), (k,)), 0, np.iinfo(np.int16).max).astype(np.int64)
        cd = np.broadcast_to(np.asarray(created), (k,)).astype(np.int64)
        p = np.asarray(payload, dtype=np.float32)
        if p.ndim == 1:
            p = np.broadcast_to(p, (k, p.shape[0]))
        if p.shape != (k, self.payload_dim):
            raise ValueError(f"payload must have shape ({k}, {self.payload_dim}), got {p.shape}")
        self.push_rows(r, kd, sd, hd, cd, np.ascontiguousarray(p), _SAME_ROWS)

    def push_rows(
        self,
        receiver: np.ndarray,
        kind: np.ndarray,
        sender: np.ndarray,
        hops: np.ndarray,
        created: np.ndarray,
        payload: np.ndarray,
        rows: np.ndarray,
    ) -> None:
        """Unchecked ``push`` for producers whose rows are valid by construction (the bus, the overlay).

        Message ``j`` goes to ``receiver[j]`` (entries < 0 are skipped) with payload ``payload[rows[j]]``.

        Args:
            receiver: Receiver slots ``(k,)`` int64, each < S.
            kind: ``(k,)`` int8 kinds in 1..5 (a stride-0 broadcast of one value is fine, as for the others).
            sender: ``(k,)`` int64 sender slots.
            hops: ``(k,)`` integer hops (clipped to the int16 range).
            created: ``(k,)`` int64 created steps.
            payload: ``(n, D)`` float32 payload table.
            rows: ``(k,)`` int64 row of ``payload`` for each message, or empty: row ``j`` for message ``j``.
        """
        self.push_batches([(receiver, kind, sender, hops, created, payload, rows)])

    def push_batches(self, batches: list[tuple[Any, ...]]) -> None:
        """``push_rows`` of several batches in one pass (as one batch of their concatenation, in order).

        Args:
            batches: ``(receiver, kind, sender, hops, created, payload, rows)`` tuples, as for ``push_rows``, each
                optionally with an eighth item ``True``: ``sender`` and ``created`` are then tables indexed by
                ``rows`` like ``payload`` (message ``j`` has ``sender[rows[j]]``), not one value per message.
        """
        for k in range(0, len(batches), 2):  # pairs in turn: the same as one push of everything, in order
            a = _kernel_batch(batches[k])
            b = _kernel_batch(batches[k + 1]) if k + 1 < len(batches) else _EMPTY_BATCH
            _push_count(self._newest, self._taken, a[0], b[0])
            self.threads.run(partial(self._push_range, (*a, *b)), self.n_slots)

    def _push_range(self, batches: tuple[Any, ...], lo: int, hi: int, _part: int) -> None:
        # one pair of batches (``_kernel_batch`` form, a then b) into the inboxes of slots [lo, hi)
        _push_kernel(
            lo,
            hi,
            self.valid,
            self.kind,
            self.sender,
            self.hops,
            self.created,
            self.payload,
            self.received,
            self._newest,
            self._taken,
            *batches,
        )

    def add_dropped(self, slots: np.ndarray) -> None:
        """Count one lost message per entry of ``slots`` (repeats count several times).

        Args:
            slots: Slots to charge ``(k,)``; entries < 0 (environment / controller) are ignored.
        """
        s = np.asarray(slots, dtype=np.int64).reshape(-1)
        s = s[s >= 0]
        if s.size:
            self.dropped += np.bincount(s, minlength=self.n_slots)

    def observe(self, pos: np.ndarray, step: int, out: np.ndarray | None = None, clip: float = np.inf) -> np.ndarray:
        """Feature tensor of every inbox (layout in the module docstring).

        Args:
            pos: Current positions ``(S, 3)``.
            step: Current step (for the age feature).
            out: Optional preallocated ``(S, M, FEATURES_PER_MESSAGE + D)`` float32 buffer, overwritten.
            clip: Each feature is clipped to ``[-clip, clip]`` (as ``np.clip``; ``np.inf``: not clipped).

        Returns:
            ``out`` (or a new array) of shape ``(S, M, FEATURES_PER_MESSAGE + D)``.
        """
        shape = (self.n_slots, self.size, self.n_features)
        if out is None:
            out = np.empty(shape, dtype=np.float32)
        elif out.shape != shape or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous float32 array of shape {shape}, got {out.dtype} {out.shape}")
        self.observe_flat(pos, step, out.reshape(self.n_slots, -1), 0, clip)
        return out

    def observe_flat(self, pos: np.ndarray, step: int, out: np.ndarray, col: int, clip: float) -> None:
        """``observe`` written into columns ``[col, col + M F)`` of a 2D float32 ``out`` ``(S, >= col + M F)``
        (message ``i`` of a slot at ``col + i F``; any row stride), each value clipped to ``[-clip, clip]``
        (``np.inf``: none): a flat observation row gets its inbox part without a copy.
        """
        if (
            out.ndim != 2
            or out.shape[0] != self.n_slots
            or out.dtype != np.float32
            or out.strides[1] != 4
            or not out.flags.writeable
        ):
            raise ValueError(f"out must be a writable float32 array (S={self.n_slots}, width) with unit column stride")
        if not 0 <= col <= out.shape[1] - self.size * self.n_features:
            raise ValueError(f"col must leave {self.size * self.n_features} columns, got {col} of {out.shape[1]}")
        p = np.asarray(pos, dtype=np.float64)
        if p.shape != (self.n_slots, 3):
            raise ValueError(f"pos must have shape ({self.n_slots}, 3), got {p.shape}")
        args = (
            self.valid,
            self.kind,
            self.sender,
            self.hops,
            self.created,
            self.payload,
            p,
            int(step),
            self.pos_scale,
            self.age_horizon,
            self.hop_horizon,
            out,
            int(col),
            float(clip),
        )
        self.threads.run(lambda lo, hi, _: _observe_kernel(lo, hi, *args), self.n_slots)

    def observe_rows(self, pos: np.ndarray, step: int, rows: np.ndarray, clip: float = np.inf) -> np.ndarray:
        """The features of the inboxes of ``rows`` only: ``(len(rows), M, F)`` float32, a fresh array (the rows
        ``observe`` gives them, clipped alike; a shard observes its own agents only)."""
        p = np.ascontiguousarray(pos, dtype=np.float64)
        r = np.ascontiguousarray(rows, dtype=np.int64)
        out = np.empty((r.shape[0], self.size, self.n_features), dtype=np.float32)
        _observe_rows_kernel(
            r,
            self.valid,
            self.kind,
            self.sender,
            self.hops,
            self.created,
            self.payload,
            p,
            int(step),
            self.pos_scale,
            self.age_horizon,
            self.hop_horizon,
            out.reshape(r.shape[0], self.size * self.n_features),
            float(clip),
        )
        return out

    def clear(self, slots: np.ndarray | None = None) -> None:
        """Empty the inboxes and zero the counters of ``slots`` (all slots when None).

        Args:
            slots: Slots to clear ``(k,)`` or None.
        """
        idx = slice(None) if slots is None else np.asarray(slots, dtype=np.int64).reshape(-1)
        self.valid[idx] = False
        self.kind[idx] = 0
        self.sender[idx] = -1
        self.hops[idx] = 0
        self.created[idx] = 0
        self.payload[idx] = 0.0
        self.received[idx] = 0
        self.dropped[idx] = 0
