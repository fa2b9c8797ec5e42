"""Message vocabulary and the layout of the per-slot inbox.

Messages are rows of arrays, never Python objects. This module owns what every producer of messages shares: the
kind codes, the drop-reason codes, the environment (collision) payload encoding, and the layout of the per-slot
inbox (``comms.inbox``; its kernels: ``comms.inbox_kernels``) into which the bus (``comms.bus``) and the overlay
(``comms.overlay``) push what agents receive.

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

import numpy as np

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
