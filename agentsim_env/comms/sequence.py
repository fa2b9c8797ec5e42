"""Sequence numbers of bus messages and the inbox order they define (the rules are in ``comms.bus``).

A message's sequence number is its index among the messages its sender created in the same step: a per-slot
counter that restarts every step. Environment / controller messages (sender -1) are numbered per
``(world, kind, target)`` instead, so the number does not depend on who else the controller wrote to, nor on
which process sent it.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.comms.bus_kernels import (
    control_sequence_kernel,
    rows_in_order,
    sender_order,
    sequence_kernel,
)
from agentsim_env.comms.events import DueRows
from agentsim_env.comms.messages import GROUP

__all__ = ["Sequencer", "inbox_order"]

# Code of an environment / controller counter: (world * _CTL_KINDS + kind) << _CTL_SHIFT | target.
_CTL_KINDS, _CTL_SHIFT = 8, 36
_IDENTITY = np.zeros(0, dtype=np.int64)


class Sequencer:
    """The step's message counters of every slot and of the environment / controller.

    Attributes:
        used: ``(S,)`` int64 messages each slot created at its ``stamp`` step.
        stamp: ``(S,)`` int64 step of each slot's count (-1: none yet).
    """

    __slots__ = ("used", "stamp", "_to_slot_used", "_to_slot_stamp", "_ctl_step", "_ctl_codes", "_ctl_counts")

    def __init__(self, n_slots: int) -> None:
        """Counters for ``n_slots`` slots, all at zero."""
        self.used = np.zeros(n_slots, dtype=np.int64)
        self.stamp = np.full(n_slots, -1, dtype=np.int64)
        # environment / controller messages to a slot: one counter per (ENV or HEARTBEAT, target slot)
        self._to_slot_used = np.zeros((2, n_slots), dtype=np.int64)
        self._to_slot_stamp = np.full((2, n_slots), -1, dtype=np.int64)
        self.reset()

    def reset(self) -> None:
        """Forget every count."""
        self.stamp[:] = -1
        self._to_slot_stamp[:] = -1
        self._ctl_step = -1
        self._ctl_codes = np.zeros(0, dtype=np.int64)  # sorted codes of the current step's counters
        self._ctl_counts = np.zeros(0, dtype=np.int64)

    def drop_world(self, world: int, slots: np.ndarray) -> None:
        """Forget the counts of world ``world`` (its ``slots`` and its environment / controller counters)."""
        self.stamp[slots] = -1
        self._to_slot_stamp[:, slots] = -1
        keep = (self._ctl_codes >> _CTL_SHIFT) // _CTL_KINDS != world
        self._ctl_codes, self._ctl_counts = self._ctl_codes[keep], self._ctl_counts[keep]

    def slots(self, snd: np.ndarray, step: int) -> np.ndarray:
        """Number messages of agent senders ``snd`` (all >= 0) created at ``step``, in row order."""
        seq = np.zeros(snd.shape[0], dtype=np.int64)
        sequence_kernel(snd, step, self.used, self.stamp, seq)
        return seq

    def number(self, kind: np.ndarray, snd: np.ndarray, tgt: np.ndarray, wld: np.ndarray, step: int) -> np.ndarray:
        """Number messages created at ``step`` (rows in creation order), advancing the counters.

        Args:
            kind: ``(k,)`` int8 kinds.
            snd: ``(k,)`` int64 senders (-1: environment / controller).
            tgt: ``(k,)`` int64 targets (slot or group id; >= 0 for sender -1).
            wld: ``(k,)`` int64 worlds.
            step: The step the messages are created.

        Returns:
            ``(k,)`` int64 sequence numbers.
        """
        seq = self.slots(snd, step)  # the kernel leaves sender -1 rows at 0
        ctl = snd < 0
        if not ctl.any():
            return seq
        control_sequence_kernel(kind, snd, tgt, step, self._to_slot_used, self._to_slot_stamp, seq)
        ctl &= kind == GROUP  # controller broadcasts: a counter per (world, group id), few, kept in numpy
        if not ctl.any():
            return seq
        # sorted codes (world, kind, group) and their counts
        if self._ctl_step != step:
            self._ctl_step, self._ctl_codes, self._ctl_counts = (
                step,
                self._ctl_codes[:0],
                self._ctl_counts[:0],
            )
        codes = ((wld[ctl] * _CTL_KINDS + kind[ctl].astype(np.int64)) << _CTL_SHIFT) + tgt[ctl]
        order = np.argsort(codes, kind="stable")
        uniq, first, count = np.unique(codes[order], return_index=True, return_counts=True)
        at = np.searchsorted(self._ctl_codes, uniq)
        known = at < self._ctl_codes.shape[0]
        known[known] = self._ctl_codes[at[known]] == uniq[known]
        base = np.zeros(uniq.shape[0], dtype=np.int64)
        base[known] = self._ctl_counts[at[known]]
        ranks = np.empty(codes.shape[0], dtype=np.int64)
        ranks[order] = np.arange(codes.shape[0]) - np.repeat(first, count) + np.repeat(base, count)
        seq[ctl] = ranks
        self._ctl_counts[at[known]] += count[known]
        if not known.all():
            all_codes = np.concatenate([self._ctl_codes, uniq[~known]])
            o = np.argsort(all_codes)
            self._ctl_codes = all_codes[o]
            self._ctl_counts = np.concatenate([self._ctl_counts, count[~known]])[o]
        return seq


def inbox_order(rows: DueRows, n_slots: int) -> np.ndarray:
    """Row indices of ``rows`` in ``(created, sender, seq, kind)`` order (empty: already in that order).

    Args:
        rows: Due messages.
        n_slots: Slots S (senders are below it).
    """
    c, s, q, k = rows.created, rows.sender, rows.seq, rows.kind
    if len(rows) < 2 or rows_in_order(c, s, q, k):
        return _IDENTITY
    if n_slots + 2 <= 8 * len(rows) + 4096:  # a dense sender range: one counting sort, linear
        order, ok = sender_order(c, s, q, k, n_slots)
        if ok:
            return order
    if c.min() == c.max() and s.max() < 2**35 and q.max() < 2**24:
        return np.argsort((((s + 1) << 24 | q) << 3) | k.astype(np.int64), kind="stable")
    return np.lexsort((k, q, s, c))
