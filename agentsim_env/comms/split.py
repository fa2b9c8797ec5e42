"""One world's bus split over K parts that each own some slots, with the same deliveries as one bus.

Each part has its own ``MessageBus`` over all ``S`` slots, and at every step:

1. it holds the messages its own slots send, and the environment / controller messages for its own slots
   (bandwidth is a sender-side check at send time, so it stays with the sender's part);
2. ``rows = bus.take_due(step)`` pops its due messages;
3. ``route(rows, owner)`` gives the rows each part must see: it keeps its own, ships the others;
4. ``bus.deliver_rows(union of kept and received rows, step, pos, online, group, mine=owner == part,
   seen=...)`` delivers them into its own slots only; heartbeat answers queued by that call with latency 0 are
   due at once: repeat 2-4 until no part has due rows (they route back to the same part).

The union over the parts of the delivered, dropped and sent events equals one bus's (``MessageBus.deliver``
is steps 2 and 4 over every slot); every own slot's inbox and drop counter equal one bus's, because loss draws
are keyed by what a message is and inbox order by ``(created, sender, seq, kind)`` (``comms.bus``). A slot
that changes part carries its inbox (the caller copies it); its messages in flight are routed by the owner at
their due step, so they reach it on its new part.
"""

from __future__ import annotations

import numpy as np

from agentsim_env.comms.events import DueRows
from agentsim_env.comms.messages import GROUP

__all__ = ["route"]


def route(rows: DueRows, owner: np.ndarray, n_parts: int | None = None) -> dict[int, DueRows]:
    """The rows each part must deliver.

    AGENT, ENV and controller HEARTBEAT rows go to the owner of their receiver (``owner[target]``); heartbeat
    answers (target -1) to the owner of their sender (the part that monitors it); GROUP rows to every part.
    Rows whose owner is -1 (nobody) reach no part.

    Args:
        rows: Due messages (``MessageBus.take_due``).
        owner: ``(S,)`` integer part index of every slot (-1 = nobody).
        n_parts: Number of parts K (default: ``owner.max() + 1``); the result has a key per part.

    Returns:
        ``{part: rows}`` for every part in ``range(K)`` (empty row sets included), rows in their given order.
    """
    own = np.asarray(owner)
    if own.ndim != 1 or not np.issubdtype(own.dtype, np.integer):
        raise ValueError(f"owner must be a 1-D integer array (a part per slot), got {own.dtype} {own.shape}")
    k = int(own.max(initial=-1)) + 1 if n_parts is None else int(n_parts)
    if k < 0 or (own.size and (own.min() < -1 or own.max() >= max(k, 1))):
        raise ValueError(f"owner must hold parts in [-1, {k}) and n_parts must be >= 0, got n_parts={n_parts}")
    grp = rows.kind == GROUP
    # the slot whose owner decides: the receiver, or the sender of an answer to the controller
    slot = np.where(grp, 0, np.where(rows.target >= 0, rows.target, rows.sender))
    if slot.size and (slot.min() < 0 or slot.max() >= own.shape[0]):
        raise ValueError(f"owner has {own.shape[0]} slots, rows name slot {int(slot.max())}")
    dest = np.where(grp, -1, own[slot])
    return {p: rows.take(grp | (dest == p)) for p in range(k)}
