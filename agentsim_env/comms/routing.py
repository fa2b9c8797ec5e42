"""Delivery kernels of the message bus: group membership, expansion of a batch into (message, receiver) pairs,
the channel filters and the event columns, each a linear pass (numba).

``comms.bus`` owns the rules (its module docstring); this module only computes them on arrays:

- ``group_members``: the online members of every (world, group) addressed, slot order within a group, as
  runs of one list (a counting sort when the key space is small, a stable argsort otherwise).
- ``expand``: one pair per unicast; one pair per online member of the target group for a GROUP message,
  the sender excluded; in the given message order (the inbox order), then slot order.
- ``filter_pairs``: the drop reason of each pair (offline receiver, range from the sender's current position
  (a sender the caller has not seen is out of range), loss from pre-drawn uniforms), the drop counters, and the
  delivered / dropped event columns (fresh arrays).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from agentsim_env.comms.messages import DROP_LOSS, DROP_OFFLINE, DROP_RANGE, GROUP, HEARTBEAT, REASON_NONE
from agentsim_env.core.threads import RowThreads, light_min_rows


@nb.njit(cache=True)
def _members_counting(online, group, world_of, n_g, n_keys):  # type: ignore[no-untyped-def]
    # Counting sort of the online members by key world * n_g + group; slots ascending within a key.
    s_n = online.shape[0]
    offsets = np.zeros(n_keys + 1, dtype=np.int64)
    for s in range(s_n):
        if online[s] and group[s] >= 0:
            offsets[world_of[s] * n_g + group[s] + 1] += 1
    for k in range(n_keys):
        offsets[k + 1] += offsets[k]
    fill = offsets[:-1].copy()
    slots = np.empty(offsets[n_keys], dtype=np.int64)
    for s in range(s_n):
        if online[s] and group[s] >= 0:
            k = world_of[s] * n_g + group[s]
            slots[fill[k]] = s
            fill[k] += 1
    return offsets, slots


def group_members(
    online: np.ndarray, group: np.ndarray, world_of: np.ndarray, n_worlds: int, n_g: int, keys: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Online members of the groups that messages address, as runs of a slot list.

    Args:
        online: ``(S,)`` bool.
        group: ``(S,)`` group ids (-1 = none), all ``< n_g``.
        world_of: ``(S,)`` int64 world of each slot.
        n_worlds: Worlds B.
        n_g: Group-id bound (larger than every group id in use and addressed).
        keys: ``(q,)`` int64 ``world * n_g + group`` of each message (any value for non-GROUP rows).

    Returns:
        ``(kid, offsets, slots)``: message ``i``'s group members are ``slots[offsets[kid[i]]:offsets[kid[i] + 1]]``,
        ascending (none when ``kid[i]`` is -1).
    """
    n_keys = n_worlds * n_g
    if n_keys <= 4 * online.shape[0] + 1024:  # a dense key space: one counting sort, O(S + keys)
        offsets, slots = _members_counting(online, group, world_of, n_g, n_keys)
        return np.where((keys >= 0) & (keys < n_keys), keys, -1), offsets, slots
    ms = np.flatnonzero(online & (group >= 0))
    mk = world_of[ms] * n_g + group[ms]
    order = np.argsort(mk, kind="stable")
    uk, first = np.unique(mk[order], return_index=True)
    at = np.minimum(np.searchsorted(uk, keys), max(uk.size - 1, 0))
    found = (uk.size > 0) & (uk[at] == keys) if uk.size else np.zeros(keys.shape, dtype=bool)
    return np.where(found, at, -1), np.append(first, mk.size), ms[order]


@nb.njit(cache=True, nogil=True)
def expand_count(lo, hi, kind, snd, kid, offsets, slots, order):  # type: ignore[no-untyped-def]
    """Pairs made by the messages at positions [lo, hi) of ``order`` (row order when it is empty)."""
    # (written out: a per-message helper taking the arrays made this pass six times slower)
    total = 0
    for i in range(lo, hi):
        k = order[i] if order.shape[0] else i
        if kind[k] != GROUP:
            total += 1
        elif kid[k] >= 0:
            for p in range(offsets[kid[k]], offsets[kid[k] + 1]):
                total += slots[p] != snd[k]
    return total


@nb.njit(cache=True, nogil=True)
def expand_fill(lo, hi, kind, snd, tgt, kid, offsets, slots, order, n, rep, recv):  # type: ignore[no-untyped-def]
    """Write the pairs of the messages at positions [lo, hi) of ``order`` from pair ``n`` on."""
    for i in range(lo, hi):
        k = order[i] if order.shape[0] else i
        if kind[k] == GROUP:
            if kid[k] >= 0:
                for p in range(offsets[kid[k]], offsets[kid[k] + 1]):
                    if slots[p] != snd[k]:
                        rep[n] = k
                        recv[n] = slots[p]
                        n += 1
        else:
            rep[n] = k
            recv[n] = tgt[k]
            n += 1


@nb.njit(cache=True)
def expand(kind, snd, tgt, kid, offsets, slots, order):  # type: ignore[no-untyped-def]
    """(message row, receiver) pairs of a batch: GROUP messages fan out to their members, sender excluded.

    Messages are taken in ``order`` (row indices; empty = row order), members in slot order.
    """
    q = kind.shape[0]
    total = expand_count(0, q, kind, snd, kid, offsets, slots, order)
    rep = np.empty(total, dtype=np.int64)
    recv = np.empty(total, dtype=np.int64)
    expand_fill(0, q, kind, snd, tgt, kid, offsets, slots, order, 0, rep, recv)
    return rep, recv


@nb.njit(cache=True, nogil=True)
def pair_reasons(lo, hi, rep, recv, snd, online, seen, pos, r_max2, u, loss, reason):  # type: ignore[no-untyped-def]
    """The drop reason of pairs [lo, hi) into ``reason`` (``filter_pairs``' rules); returns how many pass."""
    n_ok = 0
    for p in range(lo, hi):
        r = recv[p]
        s = snd[rep[p]]
        why = REASON_NONE
        if r >= 0:
            if not online[r]:
                why = DROP_OFFLINE
            elif r_max2 >= 0.0 and s >= 0 and seen.shape[0] > 0 and not seen[s]:
                why = DROP_RANGE  # the caller does not know where the sender is: it is not in range
            elif r_max2 >= 0.0 and s >= 0:
                d0 = pos[s, 0] - pos[r, 0]
                d1 = pos[s, 1] - pos[r, 1]
                d2 = pos[s, 2] - pos[r, 2]
                if (d0 * d0 + d2 * d2) + d1 * d1 > r_max2:  # numpy's einsum association, bit for bit
                    why = DROP_RANGE
        if why == REASON_NONE and loss > 0.0 and u[p] < loss:
            why = DROP_LOSS
        reason[p] = why
        n_ok += why == REASON_NONE
    return n_ok


@nb.njit(cache=True, nogil=True)
def pair_columns(lo, hi, rep, recv, reason, msg, kind, snd, tgt, created, a, b, ok, dr):  # type: ignore[no-untyped-def]
    """The event columns of pairs [lo, hi): delivered ones into ``ok`` from row ``a``, dropped ones into ``dr``
    from row ``b``; returns the delivered heartbeats to slots and answers to the controller."""
    d_msg, d_kind, d_snd, d_tgt, d_rcv, d_cre, d_row = ok
    x_msg, x_kind, x_snd, x_tgt, x_rcv, x_cre, x_why = dr
    n_hb = 0
    n_ans = 0
    for p in range(lo, hi):
        k = rep[p]
        if reason[p] == REASON_NONE:
            d_msg[a], d_kind[a], d_snd[a], d_tgt[a] = msg[k], kind[k], snd[k], tgt[k]
            d_rcv[a], d_cre[a], d_row[a] = recv[p], created[k], k
            if recv[p] < 0:
                n_ans += 1
            elif kind[k] == HEARTBEAT:
                n_hb += 1
            a += 1
        else:
            x_msg[b], x_kind[b], x_snd[b], x_tgt[b] = msg[k], kind[k], snd[k], tgt[k]
            x_rcv[b], x_cre[b], x_why[b] = recv[p], created[k], reason[p]
            b += 1
    return n_hb, n_ans


@nb.njit(cache=True)
def _event_columns(n):  # type: ignore[no-untyped-def]
    # the columns both event tables have: message, kind, sender, target, receiver, created step
    return (
        np.empty(n, dtype=np.int64),
        np.empty(n, dtype=np.int8),
        np.empty(n, dtype=np.int64),
        np.empty(n, dtype=np.int64),
        np.empty(n, dtype=np.int64),
        np.empty(n, dtype=np.int64),
    )


@nb.njit(cache=True)
def pair_arrays(n_ok, n_dr):  # type: ignore[no-untyped-def]
    """Fresh delivered and dropped event columns of ``n_ok`` and ``n_dr`` rows (the delivered ones end with the
    message's row, the dropped ones with the reason)."""
    m, k, s, t, r, c = _event_columns(n_ok)
    ok = (m, k, s, t, r, c, np.empty(n_ok, dtype=np.int64))
    m, k, s, t, r, c = _event_columns(n_dr)
    dr = (m, k, s, t, r, c, np.empty(n_dr, dtype=np.int8))
    return ok, dr


@nb.njit(cache=True)
def count_drops(x_rcv, x_snd, dropped):  # type: ignore[no-untyped-def]
    """One drop for each dropped pair's receiver (its sender for an answer to the controller)."""
    for j in range(x_rcv.shape[0]):
        c = x_rcv[j] if x_rcv[j] >= 0 else x_snd[j]
        if c >= 0:
            dropped[c] += 1


@nb.njit(cache=True)
def filter_pairs(rep, recv, msg, kind, snd, tgt, created, online, seen, pos, r_max2, u, loss, dropped):  # type: ignore[no-untyped-def]
    """Filter the pairs and build the event columns.

    Drop reasons in priority order: receiver offline, beyond ``r_max2`` (squared metres, < 0 = no limit; agent
    senders only; a sender with ``seen[s]`` False counts as beyond it, ``seen`` empty = every sender seen), lost
    (``u[p] < loss``; ``u`` is empty when ``loss`` is 0). A receiver ``-1`` is the
    controller (a heartbeat answer): never offline or out of range. Each drop adds one to ``dropped`` of the
    receiver (of the sender for an answer to the controller).

    Returns:
        Delivered columns ``(msg, kind, sender, target, receiver, created, row)`` (``row``: the message's batch
        row), dropped columns ``(msg, kind, sender, target, receiver, created, reason)``, and the number of
        delivered heartbeats to slots and of answers that reached the controller.
    """
    m = rep.shape[0]
    reason = np.empty(m, dtype=np.int8)
    n_ok = pair_reasons(0, m, rep, recv, snd, online, seen, pos, r_max2, u, loss, reason)
    ok, dr = pair_arrays(n_ok, m - n_ok)
    n_hb, n_ans = pair_columns(0, m, rep, recv, reason, msg, kind, snd, tgt, created, 0, 0, ok, dr)
    count_drops(dr[4], dr[2], dropped)
    return ok, dr, n_hb, n_ans


def _ranges(threads: RowThreads, n: int, min_rows: int | None) -> int:
    """How many ranges ``threads.run`` cuts ``n`` rows into (1 with one thread)."""
    return 1 if threads.num_threads == 1 else len(threads.ranges(n, min_rows))


def expand_on(
    threads: RowThreads,
    kind: np.ndarray,
    snd: np.ndarray,
    tgt: np.ndarray,
    kid: np.ndarray,
    offsets: np.ndarray,
    slots: np.ndarray,
    order: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``expand`` over ranges of messages on ``threads`` (a message fans out to ~10 pairs: ``MIN_ROWS`` messages a
    range): each range counts its pairs, then writes them from its first row; the same pairs in the same order."""
    q = kind.shape[0]
    if _ranges(threads, q, None) == 1:
        return expand(kind, snd, tgt, kid, offsets, slots, order)  # type: ignore[no-any-return]
    counts = threads.run(lambda lo, hi, _: expand_count(lo, hi, kind, snd, kid, offsets, slots, order), q)
    first = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rep, recv = np.empty(int(first[-1]), dtype=np.int64), np.empty(int(first[-1]), dtype=np.int64)
    threads.run(
        lambda lo, hi, r: expand_fill(lo, hi, kind, snd, tgt, kid, offsets, slots, order, first[r], rep, recv), q
    )
    return rep, recv


def filter_pairs_on(
    threads: RowThreads,
    rep: np.ndarray,
    recv: np.ndarray,
    msg: np.ndarray,
    kind: np.ndarray,
    snd: np.ndarray,
    tgt: np.ndarray,
    created: np.ndarray,
    online: np.ndarray,
    seen: np.ndarray,
    pos: np.ndarray,
    r_max2: float,
    u: np.ndarray,
    loss: float,
    dropped: np.ndarray,
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...], int, int]:
    """``filter_pairs`` over ranges of pairs on ``threads`` (a few nanoseconds a pair: ``light_min_rows`` pairs a
    range): reasons and counts per range, then each range writes its delivered and dropped rows from its first
    ones; the drop counters after. The same columns, counters and totals for any thread count."""
    m = rep.shape[0]
    light = light_min_rows()
    if _ranges(threads, m, light) == 1:
        return filter_pairs(rep, recv, msg, kind, snd, tgt, created, online, seen, pos, r_max2, u, loss, dropped)  # type: ignore[no-any-return]
    reason = np.empty(m, dtype=np.int8)
    n_ok = threads.run(
        lambda lo, hi, _: pair_reasons(lo, hi, rep, recv, snd, online, seen, pos, r_max2, u, loss, reason), m, light
    )
    spans = threads.ranges(m, light)
    ok_first = np.concatenate([[0], np.cumsum(n_ok)]).astype(np.int64)
    dr_first = np.concatenate([[0], np.cumsum([hi - lo - k for (lo, hi), k in zip(spans, n_ok)])]).astype(np.int64)
    ok, dr = pair_arrays(int(ok_first[-1]), int(dr_first[-1]))
    tallies = threads.run(
        lambda lo, hi, r: pair_columns(
            lo, hi, rep, recv, reason, msg, kind, snd, tgt, created, ok_first[r], dr_first[r], ok, dr
        ),
        m,
        light,
    )
    count_drops(dr[4], dr[2], dropped)
    return ok, dr, sum(t[0] for t in tallies), sum(t[1] for t in tallies)
