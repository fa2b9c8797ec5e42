"""Communication: message kinds and inboxes (``messages``), the centralised bus (``bus``); the overlay
flooding lives in ``comms.overlay`` and the split of a bus over parts in ``comms.split`` (imported from there,
not re-exported here)."""

from agentsim_env.comms.bus import BUS_KINDS, ChannelConfig, DeliveryEvents, DueRows, MessageBus, MessageLog
from agentsim_env.comms.inbox import Inbox
from agentsim_env.comms.messages import (
    AGENT,
    DROP_BANDWIDTH,
    DROP_LOSS,
    DROP_OFFLINE,
    DROP_RANGE,
    ENV,
    ENV_COLLISION_AGENT,
    ENV_COLLISION_OBJECT,
    FEATURES_PER_MESSAGE,
    GROUP,
    HEARTBEAT,
    KIND_NAMES,
    N_KINDS,
    OVERLAY,
    REASON_NAMES,
    REASON_NONE,
    env_collision_payload,
)

__all__ = [
    "AGENT",
    "BUS_KINDS",
    "DROP_BANDWIDTH",
    "DROP_LOSS",
    "DROP_OFFLINE",
    "DROP_RANGE",
    "ENV",
    "ENV_COLLISION_AGENT",
    "ENV_COLLISION_OBJECT",
    "FEATURES_PER_MESSAGE",
    "GROUP",
    "HEARTBEAT",
    "KIND_NAMES",
    "N_KINDS",
    "OVERLAY",
    "REASON_NAMES",
    "REASON_NONE",
    "ChannelConfig",
    "DeliveryEvents",
    "DueRows",
    "Inbox",
    "MessageBus",
    "MessageLog",
    "env_collision_payload",
]
