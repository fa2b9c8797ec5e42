"""What the coordinator keeps and makes of the shards' replies: each shard's heartbeat record (``ShardInfo``),
the bytes of a step (``Traffic``), and the merges of the shards' per-agent rows and events into what one
process gives (rollout rows, message events, collisions in slot order).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim_env.comms.events import DeliveryEvents, MessageLog
from agentsim_env.comms.overlay import Deliveries
from agentsim_env.comms.stack import CommsEvents
from agentsim_env.core.collisions import CollisionEvents
from agentsim_env.distributed.bridge import Packed
from agentsim_env.scenarios.base import Scenario
from agentsim_env.sim import World

_NONE = np.zeros(0, dtype=np.int64)


@dataclass(slots=True)
class ShardInfo:
    """What the coordinator knows of one shard (the integrator's map of machines).

    Attributes:
        index: Shard index k.
        address: ``host:pid`` of its process (from its heartbeats).
        alive: Whether it still answers.
        last_answer: ``time.time()`` of its latest heartbeat.
        last_step: The simulation tick of its latest heartbeat.
        step_s: Seconds of its latest call (its exchanges included).
        wait_s: Seconds of that call spent at the exchange (waiting for the others, routing, transfers).
        reason: Why it went offline (empty while alive).
        restarts: How many times it was started anew.
    """

    index: int
    address: str = ""
    alive: bool = True
    last_answer: float = 0.0
    last_step: int = -1
    step_s: float = 0.0
    wait_s: float = 0.0
    reason: str = ""
    restarts: int = 0


@dataclass(slots=True)
class Traffic:
    """Bytes that crossed between processes in the latest step (or, after a rollout, per step of it), by kind.

    ``actions`` and ``replies`` travel between the coordinator and the shards; the others between the shards,
    through the exchange: ``halo`` (ghost positions), ``handover`` (the agents that changed shards, with all their
    per-slot rows), ``offline`` (ghosts that went offline, the overlay's ghost frontier), ``bus`` (messages whose
    receiver lives on another shard), ``positions`` (far inbox senders), ``groups`` (per-group sums).
    """

    actions: int = 0
    replies: int = 0
    halo: int = 0
    handover: int = 0
    offline: int = 0
    bus: int = 0
    positions: int = 0
    groups: int = 0

    @property
    def total(self) -> int:
        """Every byte of the step."""
        return sum(getattr(self, f) for f in self.__slots__)  # type: ignore[attr-defined]

    @property
    def between_shards(self) -> int:
        """The bytes of the exchanges (what crosses between machines besides the coordinator's calls)."""
        return self.total - self.actions - self.replies

    def add_exchange(self, counts: dict[str, int], scale: float = 1.0) -> None:
        """Add the exchange's byte counts by phase (``Bridge.take_bytes``), times ``scale``."""
        for phase, field_name in (
            ("halo", "halo"),
            ("handover", "handover"),
            ("offline", "offline"),
            ("bus", "bus"),
            ("want", "positions"),
            ("have", "positions"),
            ("groups", "groups"),
        ):
            setattr(self, field_name, getattr(self, field_name) + int(counts.get(phase, 0) * scale))


def rollout_rows(
    world: World, finished: list[Packed], info_keys: tuple[str, ...]
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Every agent's return, final position and info sums from the shards' last rows; the live slots."""
    s = world.state.n_slots
    returns = np.zeros(s)
    pos = np.array(world.state.pos, dtype=np.float64)  # agents of a lost shard: where they were last seen
    sums = {k: np.zeros(s) for k in info_keys}
    live = []
    for r in finished:
        sl = r["slots"]
        returns[sl], pos[sl] = r["returns"], r["pos"]
        for k in info_keys:
            sums[k][sl] = r["sums"][k]
        live.append(r["live"])
    alive = np.sort(np.concatenate(live)) if live else _NONE
    return returns, pos, sums, alive


def merge_comms(replies: list[Packed], step: int) -> CommsEvents:
    """The shards' message events of one step as one process's (bus logs and overlay deliveries)."""

    def logs(key: str) -> MessageLog:
        return MessageLog.concat([r[key] for r in replies if key in r])

    bus = DeliveryEvents(step, logs("bus.sent"), logs("bus.delivered"), logs("bus.dropped"))
    got = [r["overlay"] for r in replies if "overlay" in r]
    ov = Deliveries(
        *(
            np.concatenate([getattr(d, f) for d in got])
            for f in ("receiver", "flood", "origin", "hops", "created", "payload")
        )
    )
    sent = np.sum([r["sent"] for r in replies if "sent" in r], axis=0)
    return CommsEvents(bus, ov, sent)


def obs_dim(scenario: Scenario) -> int:
    """Length of the scenario's flat observation row."""
    return int(sum(p.size for p in scenario.obs_parts().values()))


def merge_collisions(replies: list[Packed]) -> CollisionEvents:
    """Every shard's collisions of its own agents, in slot order of the hit agent (the single-process order)."""
    if not replies:
        return CollisionEvents.empty()
    agent = np.concatenate([r["col.agent"] for r in replies])
    other = np.concatenate([r["col.other"] for r in replies])
    obj = np.concatenate([r["col.obj"] for r in replies])
    order = np.argsort(agent, kind="stable")
    return CollisionEvents(agent[order], other[order], obj[order])
