"""The inbox's numba kernels (``comms.inbox``): the push of a step's messages into the slots' newest-first rows, and
the observation features of every row (``comms.messages`` gives their layout).

A push batch is a tuple of arrays in one form (``kernel_batch``), so each kernel compiles once whatever a step
delivers.
"""

from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from agentsim_env.comms.messages import FEATURES_PER_MESSAGE

SAME_ROWS = np.zeros(0, dtype=np.int64)  # push_rows: message j takes payload row j
#: The push kernel's one signature: receiver, kind, sender, hops, created, payload, rows of each batch. ``kind``
#: and ``hops`` may hold one value for every message (a length-1 array: a batch of one kind or hop count).
BATCH_DTYPES = (np.int64, np.int8, np.int64, np.int32, np.int64, np.float32, np.int64)
HOPS_MAX = 32767  # hops are kept in int16 inbox rows
_ONE_VALUE = (1, 3)  # kind, hops
EMPTY_BATCH = (
    SAME_ROWS,
    np.zeros(0, dtype=np.int8),
    SAME_ROWS,
    np.zeros(0, dtype=np.int32),
    SAME_ROWS,
    np.zeros((0, 0), dtype=np.float32),
    SAME_ROWS,
    False,
)


def kernel_batch(batch: tuple[Any, ...]) -> tuple[Any, ...]:
    """``batch`` with every array C-contiguous, writable and of the push kernel's dtype, and its table flag.

    numba compiles a kernel once per signature, and a signature tells C-contiguous from strided arrays (a
    stride-0 broadcast of one kind or hop count is strided with two messages or more, contiguous with one) and
    writable from read-only ones (Ray hands shards read-only arrays). Producers hand all of these; one form
    keeps the kernel at one compiled version, whatever a step delivers. A stride-0 broadcast of ``kind`` or
    ``hops`` becomes its one value (no copy of a million equal entries); hops of another integer type are
    clipped to ``[0, HOPS_MAX]`` before they are narrowed. Arrays already in form pass through untouched.
    """
    out: list[np.ndarray | bool] = []
    for j, (a, dtype) in enumerate(zip(batch[:7], BATCH_DTYPES)):
        if j in _ONE_VALUE and a.ndim == 1 and a.shape[0] > 1 and a.strides[0] == 0:
            a = a[:1]
        if j == 3 and a.dtype != dtype:
            a = np.clip(a, 0, HOPS_MAX).astype(dtype)
        if a.dtype != dtype or not a.flags.c_contiguous or not a.flags.writeable:
            a = np.array(a, dtype=dtype, order="C")  # a fresh array: contiguous and writable
        out.append(a)
    out.append(bool(batch[7]) if len(batch) > 7 else False)
    return tuple(out)


@nb.njit(cache=True, nogil=True)
def push_count(newest, taken, ra, rb):  # type: ignore[no-untyped-def]
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
def push_count_range(newest, taken, ra, rb, lo, hi):  # type: ignore[no-untyped-def]
    # ``push_count`` for the receivers in [lo, hi) only: every range reads all receivers (a sequential read) and
    # writes its own rows, so ranges run on threads at once; the same walk keeps each receiver's order.
    m = newest.shape[1]
    na = ra.shape[0]
    for g in range(rb.shape[0] - 1, -1, -1):
        s = rb[g]
        if s >= lo and s < hi:
            t = taken[s]
            if t < m:
                newest[s, t] = g + na
            taken[s] = t + 1
    for g in range(na - 1, -1, -1):
        s = ra[g]
        if s >= lo and s < hi:
            t = taken[s]
            if t < m:
                newest[s, t] = g
            taken[s] = t + 1


@nb.njit(cache=True, nogil=True)
def push_kernel(
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
    # Pass 2 of a push (after ``push_count``) into the inboxes of slots [lo, hi): ranges on different threads
    # touch different inboxes. Message j of a batch goes to slot r[j] with payload row p[q[j]] (row j when q is
    # empty) and hops clipped to [0, 32767]; its sender and created step are s[j] and c[j], or s[q[j]] and
    # c[q[j]] when the batch's flag t says they are tables too (the overlay's flood table: a few rows that stay
    # in the cache, where per-message columns are read at random). The inputs come in one form
    # (``kernel_batch``), so this compiles once. The receivers are walked in slot order (the inbox arrays stream
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
                kind[s, i], sender[s, i], created[s, i] = ka[min(g, ka.shape[0] - 1)], sa[at], ca[at]
                hops[s, i] = min(max(ha[min(g, ha.shape[0] - 1)], 0), 32767)
                for x in range(d):
                    payload[s, i, x] = pa[row, x]
            else:
                g -= na
                row = g if qb.shape[0] == 0 else qb[g]
                at = row if tb else g
                kind[s, i], sender[s, i], created[s, i] = kb[min(g, kb.shape[0] - 1)], sb[at], cb[at]
                hops[s, i] = min(max(hb[min(g, hb.shape[0] - 1)], 0), 32767)
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
def observe_kernel(
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
def observe_rows_kernel(
    rows,
    at,
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
    col,
    lim,
):
    # Slot rows[r]'s inbox into row at[r] of out, from column col (any row stride).
    for r in range(rows.shape[0]):
        _observe_row(
            rows[r],
            at[r],
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
            col,
            lim,
        )


@nb.njit(cache=True)
def mark_senders_kernel(rows, valid, sender, out):  # type: ignore[no-untyped-def]
    # out[s] = True for every sender s >= 0 of a valid message in the inboxes of rows.
    for i in range(rows.shape[0]):
        r = rows[i]
        for j in range(valid.shape[1]):
            if valid[r, j]:
                s = sender[r, j]
                if s >= 0:
                    out[s] = True
