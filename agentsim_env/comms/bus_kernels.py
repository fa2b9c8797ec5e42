"""Numba kernels of the message bus (``comms.bus``): bandwidth, sequence numbers, keyed loss draws, order."""

from __future__ import annotations

import numba as nb
import numpy as np

from agentsim_env.comms.messages import ENV, GROUP


@nb.njit(cache=True)
def bandwidth_kernel(snd, step, bw, used, stamp, acc):  # type: ignore[no-untyped-def]
    """Accept messages against a per-sender budget of ``bw`` messages per step, in call order.

    Args:
        snd: ``(k,)`` int64 sender slots (-1 = environment / controller, never limited).
        step: Current step.
        bw: Messages an agent may send per step (> 0).
        used: ``(S,)`` int64 count of each slot at its stamped step (updated in place).
        stamp: ``(S,)`` int64 step of each slot's count (updated in place).
        acc: ``(k,)`` bool; rows over the budget are set False, the others are left as they are.
    """
    # In call order: an agent's count restarts when its stamp is an older step; accept below the limit.
    for i in range(snd.shape[0]):
        s = snd[i]
        if s < 0:
            continue  # the environment / controller is not limited
        if stamp[s] != step:
            stamp[s] = step
            used[s] = 0
        if used[s] < bw:
            used[s] += 1
        else:
            acc[i] = False


@nb.njit(cache=True)
def sequence_kernel(snd, step, used, stamp, seq):  # type: ignore[no-untyped-def]
    """Number each agent's messages of a step: ``seq[i]`` = messages ``snd[i]`` created before it this step.

    Args:
        snd: ``(k,)`` int64 sender slots (-1 rows are left as they are: the caller numbers them).
        step: Step the messages are created.
        used: ``(S,)`` int64 messages each slot created at its stamped step (updated in place).
        stamp: ``(S,)`` int64 step of each slot's count (updated in place).
        seq: ``(k,)`` int64 output.
    """
    for i in range(snd.shape[0]):
        s = snd[i]
        if s < 0:
            continue
        if stamp[s] != step:
            stamp[s] = step
            used[s] = 0
        seq[i] = used[s]
        used[s] += 1


@nb.njit(cache=True)
def control_sequence_kernel(kind, snd, tgt, step, used, stamp, seq):  # type: ignore[no-untyped-def]
    """Number the environment / controller messages to slots: a counter per (kind, target slot) and step.

    Args:
        kind: ``(k,)`` int8 kinds.
        snd: ``(k,)`` int64 senders; only rows with sender -1 and a kind other than GROUP are numbered.
        tgt: ``(k,)`` int64 target slots.
        step: Step the messages are created.
        used: ``(2, S)`` int64 counts, row 0 for ENV, row 1 for HEARTBEAT (updated in place).
        stamp: ``(2, S)`` int64 step of each count (updated in place).
        seq: ``(k,)`` int64 output.
    """
    for i in range(snd.shape[0]):
        if snd[i] >= 0 or kind[i] == GROUP:  # agents are numbered per sender, GROUP targets are group ids
            continue
        c = 0 if kind[i] == ENV else 1
        t = tgt[i]
        if stamp[c, t] != step:
            stamp[c, t] = step
            used[c, t] = 0
        seq[i] = used[c, t]
        used[c, t] += 1


# SplitMix64 (Steele, Lea & Flood 2014): the golden-ratio increment and the finaliser's two multipliers.
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_S32, _S8 = np.uint64(32), np.uint64(8)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53: the top 53 bits of a hash as a float64 in [0, 1)


@nb.njit(cache=True, inline="always")
def _mix(z):  # type: ignore[no-untyped-def]
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@nb.njit(cache=True)
def keyed_draws(rep, recv, keys, world, n_agents, created, snd, seq, kind):  # type: ignore[no-untyped-def]
    """One uniform in [0, 1) per (message row, receiver) pair, a pure function of what the pair is.

    Two chained SplitMix64 rounds: ``h0 = mix(keys[world] + (created + 1) * golden)``, then
    ``mix((h0 ^ (sender + 1) << 32 | (receiver + 1)) + (seq << 8 | kind) * M2)`` with sender and receiver as
    indices within the world (-1 stays -1). The value depends on nothing else: not on the batch, its order,
    the world's position in a batch or the process drawing it.

    Args:
        rep: ``(m,)`` int64 message row of each pair.
        recv: ``(m,)`` int64 receiver slot of each pair (-1: the controller).
        keys: ``(B,)`` uint64 episode key of each world.
        world: ``(q,)`` int64 world of each message row.
        n_agents: Agents per world N (slot ``s`` of world ``w`` is index ``s - w * N`` within it).
        created: ``(q,)`` int64 step each message was created, counted from its world's episode start (the
            bus passes ``created - starts[world]``, so an episode draws the same whatever tick it began at).
        snd: ``(q,)`` int64 sender slots (-1: environment / controller).
        seq: ``(q,)`` int64 sequence numbers (see ``comms.bus``).
        kind: ``(q,)`` int8 kinds.

    Returns:
        ``(m,)`` float64 in [0, 1).
    """
    m = rep.shape[0]
    out = np.empty(m)
    last_w, last_c, h0 = -1, -1, _GOLDEN
    for p in range(m):
        k = rep[p]
        w = world[k]
        if w != last_w or created[k] != last_c:  # the first round depends on (world, created) only: reuse it
            last_w, last_c = w, created[k]
            h0 = _mix(keys[w] + np.uint64(last_c + 1) * _GOLDEN)
        base = w * n_agents
        s = snd[k] - base if snd[k] >= 0 else -1
        r = recv[p] - base if recv[p] >= 0 else -1
        pair = (np.uint64(s + 1) << _S32) | np.uint64(r + 1)
        h = _mix((h0 ^ pair) + ((np.uint64(seq[k]) << _S8) | np.uint64(kind[k])) * _M2)
        out[p] = np.float64(h >> _S11) * _TO_UNIT
    return out


@nb.njit(cache=True)
def rows_in_order(created, snd, seq, kind):  # type: ignore[no-untyped-def]
    """Whether message rows are sorted by ``(created, sender, seq, kind)`` (the inbox order of ``comms.bus``)."""
    for i in range(1, created.shape[0]):
        if _before(created, snd, seq, kind, i, i - 1):
            return False
    return True


@nb.njit(cache=True, inline="always")
def _before(created, snd, seq, kind, i, j):  # type: ignore[no-untyped-def]
    # whether row i comes strictly before row j in (created, sender, seq, kind) order
    if created[i] != created[j]:
        return created[i] < created[j]
    if snd[i] != snd[j]:
        return snd[i] < snd[j]
    if seq[i] != seq[j]:
        return seq[i] < seq[j]
    return kind[i] < kind[j]


@nb.njit(cache=True)
def sender_order(created, snd, seq, kind, n_slots):  # type: ignore[no-untyped-def]
    """Stable counting sort of message rows by sender (-1 first), O(rows + slots).

    Returns:
        ``(order, ok)``: ``ok`` says whether ``order`` is the full ``(created, sender, seq, kind)`` order, i.e.
        all rows share one created step and each sender's rows already came in ``(seq, kind)`` order (the
        queue appends a sender's messages in creation order, so they do unless the controller's are mixed).
    """
    q = snd.shape[0]
    start = np.zeros(n_slots + 2, dtype=np.int64)
    for i in range(q):
        start[snd[i] + 2] += 1
    for b in range(n_slots + 1):
        start[b + 1] += start[b]
    order = np.empty(q, dtype=np.int64)
    for i in range(q):
        b = snd[i] + 1
        order[start[b]] = i
        start[b] += 1
    for j in range(1, q):
        if created[order[j]] != created[order[0]] or _before(created, snd, seq, kind, order[j], order[j - 1]):
            return order, False
    return order, True
