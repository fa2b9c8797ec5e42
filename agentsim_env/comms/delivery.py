"""Which (message, receiver) pairs of a batch of due bus rows survive the channel (``MessageBus``'s delivery).

One pass per batch, in the bus's rules (``comms.bus``): the inbox order of the rows, the online members of every
group addressed, the fan-out into pairs (a bus that owns some slots keeps its own receivers, and the answers of
its own senders), the keyed loss draws, then the filters (offline receiver, range, loss) with the drop counters.
The bus keeps what comes of it: the logs, the pushes into the inboxes and the heartbeat answers.

Keyed loss draws: the uniform of a pair is a hash (two chained SplitMix64 rounds, ``bus_kernels.keyed_draws``) of

    (episode key of the world, created step within the episode, sender, seq, kind, receiver)

- episode key: ``rng.integers(2**63)`` from the generator ``reset_world(w, rng)`` receives (a function of the
  episode seed; ``reset`` / the constructor take one per world the same way);
- created step within the episode: ``created - starts[world]``, where ``starts`` (``set_starts``, 0 until set)
  is the step at which each world's episode began. Steps are a global tick that no reset rewinds, so without
  it the same episode started at another tick would lose other messages; the comms stack sets it before each
  delivery (a message sent between a reset and the first step is the episode's step 0);
- seq: the message's index among the messages its sender created in the same step (a per-slot counter that
  restarts every step, counting every message created, bandwidth drops included, and the heartbeat answers
  the slot creates). Sender -1 (environment / controller) rows are numbered per (world, kind, target)
  instead: the n-th ENV message to slot r in a step has seq n-1 whoever sends the others;
- sender and receiver: slot indices within their world (``slot % N``; -1 for the environment / controller,
  and as the receiver of an answer to the controller), so world ``w`` of a batch draws what one world does.

So a pair's fate depends only on what the message is, not on the batch, its order or the process drawing it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from agentsim_env.comms.bus_kernels import keyed_draws
from agentsim_env.comms.channel import ChannelConfig
from agentsim_env.comms.events import DueRows
from agentsim_env.comms.inbox import Inbox
from agentsim_env.comms.messages import GROUP
from agentsim_env.comms.routing import expand_on, filter_pairs_on, group_members
from agentsim_env.comms.sequence import inbox_order

__all__ = ["channel_pairs"]

# Read-only inputs of the delivery kernels when a batch has no GROUP message / the channel no loss.
_NO_SLOTS = np.zeros(0, dtype=np.int64)
_NO_DRAWS = np.zeros(0)


def channel_pairs(
    rows: DueRows,
    channel: ChannelConfig,
    inbox: Inbox,
    world_of: np.ndarray,
    n_worlds: int,
    n_agents: int,
    keys: np.ndarray,
    starts: np.ndarray,
    pos: np.ndarray,
    online: np.ndarray,
    group: np.ndarray,
    mine: np.ndarray | None,
    seen: np.ndarray,
    check_keys: Callable[[np.ndarray], None],
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...], int, int]:
    """The delivered and dropped pairs of ``rows`` (``routing.filter_pairs``' columns and tallies).

    Args:
        rows: The due rows of one delivery.
        channel: The channel model (loss, range).
        inbox: The inboxes: their row threads run the fan-out and filters, their drop counters are charged.
        world_of: ``(S,)`` world of each slot.
        n_worlds: Worlds B.
        n_agents: Agents per world N (the loss draws key slots within their world).
        keys: ``(B,)`` episode keys of the loss draws.
        starts: ``(B,)`` step at which each world's episode began.
        pos: Positions ``(S, 3)`` at delivery time.
        online: ``(S,)`` online flags.
        group: ``(S,)`` group ids.
        mine: ``(S,)`` the slots this bus owns, or None for all.
        seen: Senders whose position the caller knows (empty: every sender).
        check_keys: Raises when a world of the rows has no episode key (called before any loss draw).

    Returns:
        Delivered columns, dropped columns, delivered heartbeats to slots, answers that reached the controller.
    """
    order = inbox_order(rows, inbox.n_slots)  # the pairs come out in it; the rows stay where they are
    kind, snd, tgt = rows.kind, rows.sender, rows.target
    kid, offsets, slots = _NO_SLOTS, _NO_SLOTS, _NO_SLOTS
    grp = kind == GROUP
    if grp.any():
        n_g = int(max(group.max(initial=-1), tgt[grp].max())) + 1
        members = online if mine is None else online & mine
        kid, offsets, slots = group_members(members, group, world_of, n_worlds, n_g, rows.world * n_g + tgt)
    threads = inbox.threads
    rep, recv = expand_on(threads, kind, snd, tgt, kid, offsets, slots, order)
    if mine is not None and rep.shape[0]:
        own = mine[np.where(recv >= 0, recv, snd[rep])]  # an answer belongs to the bus owning its sender
        if not own.all():
            rep, recv = rep[own], recv[own]
    loss = float(channel.loss)
    u: Any = _NO_DRAWS
    if loss > 0.0 and rep.shape[0]:
        check_keys(rows.world)
        when = rows.created - starts[rows.world]  # the step within the world's episode
        u = keyed_draws(rep, recv, keys, rows.world, n_agents, when, snd, rows.seq, kind)
    r_max = channel.max_range
    return filter_pairs_on(  # type: ignore[no-any-return]
        threads,
        rep,
        recv,
        rows.msg,
        kind,
        snd,
        tgt,
        rows.created,
        online,
        seen,
        pos,
        -1.0 if r_max is None else r_max * r_max,
        u,
        loss,
        inbox.dropped,
    )
