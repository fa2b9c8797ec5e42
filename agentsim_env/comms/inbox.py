"""The per-slot inbox: the ``M`` newest messages every slot received, newest first, as arrays (the layout and the
order of a step's pushes: ``comms.messages``; the kernels: ``comms.inbox_kernels``)."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from agentsim_env.comms.inbox_kernels import (
    EMPTY_BATCH,
    SAME_ROWS,
    kernel_batch,
    mark_senders_kernel,
    observe_kernel,
    observe_rows_kernel,
    push_count,
    push_count_range,
    push_kernel,
)
from agentsim_env.comms.messages import FEATURES_PER_MESSAGE, KIND_NAMES, N_KINDS
from agentsim_env.core import threads as _threads
from agentsim_env.core.threads import RowThreads


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
        hd = np.clip(np.broadcast_to(np.asarray(hops), (k,)), 0, np.iinfo(np.int16).max).astype(np.int32)
        cd = np.broadcast_to(np.asarray(created), (k,)).astype(np.int64)
        p = np.asarray(payload, dtype=np.float32)
        if p.ndim == 1:
            p = np.broadcast_to(p, (k, p.shape[0]))
        if p.shape != (k, self.payload_dim):
            raise ValueError(f"payload must have shape ({k}, {self.payload_dim}), got {p.shape}")
        self.push_rows(r, kd, sd, hd, cd, np.ascontiguousarray(p), SAME_ROWS)

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
        n_ranges = len(self.threads.ranges(self.n_slots)) if self.threads.num_threads > 1 else 1
        scan = n_ranges >= _threads.SCAN_MIN_RANGES  # each range counts its own receivers (core.threads)
        for k in range(0, len(batches), 2):  # pairs in turn: the same as one push of everything, in order
            a = kernel_batch(batches[k])
            b = kernel_batch(batches[k + 1]) if k + 1 < len(batches) else EMPTY_BATCH
            if scan:  # each range finds its own receivers' messages, then pushes them: one parallel pass
                self.threads.run(partial(self._count_push_range, (*a, *b)), self.n_slots)
            else:
                push_count(self._newest, self._taken, a[0], b[0])
                self.threads.run(partial(self._push_range, (*a, *b)), self.n_slots)

    def _count_push_range(self, batches: tuple[Any, ...], lo: int, hi: int, part: int) -> None:
        # both passes of a push for the receivers of slots [lo, hi) (``push_count_range``, then ``_push_range``)
        push_count_range(self._newest, self._taken, batches[0], batches[8], lo, hi)
        self._push_range(batches, lo, hi, part)

    def _push_range(self, batches: tuple[Any, ...], lo: int, hi: int, _part: int) -> None:
        # one pair of batches (``kernel_batch`` form, a then b) into the inboxes of slots [lo, hi)
        push_kernel(
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
        args = (*self._observe_args(p, step), out, int(col), float(clip))
        self.threads.run(lambda lo, hi, _: observe_kernel(lo, hi, *args), self.n_slots)

    def observe_rows(self, pos: np.ndarray, step: int, rows: np.ndarray, clip: float = np.inf) -> np.ndarray:
        """The features of the inboxes of ``rows`` only: ``(len(rows), M, F)`` float32, a fresh array (the rows
        ``observe`` gives them, clipped alike; a shard observes its own agents only)."""
        r = np.ascontiguousarray(rows, dtype=np.int64)
        out = np.empty((r.shape[0], self.size, self.n_features), dtype=np.float32)
        self.observe_rows_flat(pos, step, r, out.reshape(r.shape[0], self.size * self.n_features), 0, clip)
        return out

    def observe_rows_flat(
        self,
        pos: np.ndarray,
        step: int,
        rows: np.ndarray,
        out: np.ndarray,
        col: int,
        clip: float = np.inf,
        at: np.ndarray | None = None,
    ) -> None:
        """``observe_rows`` written into columns ``[col, col + M F)`` of a 2D float32 ``out`` (any row stride), as
        ``observe_flat`` writes every slot's: slot ``rows[r]`` into row ``r`` of ``out`` ``(len(rows), width)``,
        or into row ``at[r]`` of ``out`` ``(>= max(at) + 1, width)`` when ``at`` is given."""
        r = np.ascontiguousarray(rows, dtype=np.int64)
        unit = out.ndim == 2 and (out.strides[1] == 4 or out.size == 0)  # numpy may give empty arrays other strides
        n_out = r.shape[0] if at is None else out.shape[0] if out.ndim == 2 else -1
        if not unit or out.shape[0] != n_out or out.dtype != np.float32 or not out.flags.writeable:
            want = f"({r.shape[0]}, width)" if at is None else "(rows, width)"
            raise ValueError(
                f"out must be a writable float32 array {want} with unit column stride, got {out.shape} {out.dtype}"
            )
        if not 0 <= col <= out.shape[1] - self.size * self.n_features:
            raise ValueError(f"col must leave {self.size * self.n_features} columns, got {col} of {out.shape[1]}")
        if at is None:
            rows_at = np.arange(r.shape[0], dtype=np.int64)
        else:
            rows_at = np.ascontiguousarray(at, dtype=np.int64)
            if rows_at.shape != r.shape or (rows_at.size and not 0 <= rows_at.min() <= rows_at.max() < n_out):
                raise ValueError(
                    f"at must hold one row of out in [0, {n_out}) per row of rows ({r.shape[0]}), got shape "
                    f"{rows_at.shape}" + (f" and values {rows_at.min()}..{rows_at.max()}" if rows_at.size else "")
                )
        p = np.ascontiguousarray(pos, dtype=np.float64)
        observe_rows_kernel(r, rows_at, *self._observe_args(p, step), out, int(col), float(clip))  # type: ignore[call-arg]

    def mark_senders(self, rows: np.ndarray, out: np.ndarray) -> None:
        """Set ``out[s]`` for every sender ``s`` of a message in the inboxes of ``rows`` (``out``: ``(S,)`` bool;
        ENV messages, which have no sender, are skipped): linear in the rows' inbox entries, not in every slot's.

        Raises:
            ValueError: For an ``out`` that is not a writable ``(S,)`` bool array.
        """
        if out.shape != (self.n_slots,) or out.dtype != np.bool_ or not out.flags.writeable:
            raise ValueError(
                f"out must be a writable bool array of shape ({self.n_slots},), got {out.shape} {out.dtype}"
            )
        mark_senders_kernel(np.ascontiguousarray(rows, dtype=np.int64), self.valid, self.sender, out)

    def _observe_args(self, pos: np.ndarray, step: int) -> tuple[Any, ...]:
        """The observation kernels' inputs before their output: the inbox arrays, positions, step and scales."""
        inbox = (self.valid, self.kind, self.sender, self.hops, self.created, self.payload)
        return (*inbox, pos, int(step), self.pos_scale, self.age_horizon, self.hop_horizon)

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
