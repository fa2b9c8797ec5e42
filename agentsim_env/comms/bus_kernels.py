"""Numba kernels of the message bus (``comms.bus``)."""

from __future__ import annotations

import numba as nb


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
