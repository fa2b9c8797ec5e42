"""Numba kernels of the message bus (``comms.bus``): bandwidth, sequence numbers, keyed loss draws, order."""

from __future__ import annotations

import numba as nb
import numpy as np


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


# SplitMix64 (Steele, Lea & Flood 2014): the golden-ratio increment and the finaliser's two multipliers.
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_ONE = np.uint64(1)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2**-53: the top 53 bits of a hash as a float64 in [0, 1)


@nb.njit(cache=True, inline="always")
def _mix(z):  # type: ignore[no-untyped-def]
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@nb.njit(cache=True)
def keyed_draws(rep, recv, key, created, snd, seq, kind, n_agents):  # type: ignore[no-untyped-def]
    """One uniform in [0, 1) per (message row, receiver) pair, a pure function of what the pair is.

    Pair ``p`` hashes ``(key[rep[p]], created, sender, seq, kind)`` of its message row and its receiver
    ``recv[p]`` through chained SplitMix64 rounds (each field is added to the running hash, which is then
    mixed), so the value depends on nothing else: not on the batch, its order or the process drawing it.
    Slots enter as their index within their world (``slot % n_agents``; -1 stays -1), so world ``w`` of a
    batch draws what a single world of the same episode key draws.

    Args:
        rep: ``(m,)`` int64 message row of each pair.
        recv: ``(m,)`` int64 receiver of each pair (-1: the controller).
        key: ``(q,)`` uint64 episode key of each message row's world.
        created: ``(q,)`` int64 step each message was created.
        snd: ``(q,)`` int64 sender slots (-1: environment / controller).
        seq: ``(q,)`` int64 sequence numbers (see ``comms.bus``).
        kind: ``(q,)`` int8 kinds.
        n_agents: Agents per world N.

    Returns:
        ``(m,)`` float64 in [0, 1).
    """
    m = rep.shape[0]
    out = np.empty(m)
    for p in range(m):
        k = rep[p]
        s = snd[k] % n_agents if snd[k] >= 0 else -1
        r = recv[p] % n_agents if recv[p] >= 0 else -1
        h = _mix(key[k] + _GOLDEN)
        h = _mix(h + np.uint64(created[k]) * _GOLDEN)
        h = _mix(h + np.uint64(s + 1))
        h = _mix(h + np.uint64(seq[k]))
        h = _mix(h + np.uint64(kind[k]))
        h = _mix(h + np.uint64(r + 1) + _ONE)
        out[p] = np.float64(h >> _S11) * _TO_UNIT
    return out


@nb.njit(cache=True)
def rows_in_order(created, snd, seq, kind):  # type: ignore[no-untyped-def]
    """Whether message rows are sorted by ``(created, sender, seq, kind)`` (the inbox order of ``comms.bus``)."""
    for i in range(1, created.shape[0]):
        j = i - 1
        if created[i] != created[j]:
            if created[i] < created[j]:
                return False
        elif snd[i] != snd[j]:
            if snd[i] < snd[j]:
                return False
        elif seq[i] != seq[j]:
            if seq[i] < seq[j]:
                return False
        elif kind[i] < kind[j]:
            return False
    return True
