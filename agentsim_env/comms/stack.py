"""The communication stack the world drives: bus + overlay + group controller + inboxes.

Pipeline hooks (DESIGN §4): ``send_actions`` in stage 1 (the agents' ``comm`` actions), ``on_collisions`` in
stage 5 (the environment tells each hit agent what hit it), ``tick_groups`` in stage 6 (heartbeats and
timeouts) and ``deliver`` in stage 7 (bus messages due this step, one overlay hop). ``observe`` gives the
inbox features and per-step counters.

The ``comm`` action of an agent, all values in [-1, 1] (``COMM_HEADER + payload_dim`` floats):

| idx   | meaning                                                                                   |
|-------|-------------------------------------------------------------------------------------------|
| 0     | channel: 5 equal bins of [-1, 1]: none, group, nearest, named, overlay                      |
| 1     | named receiver: agent index ``round(u * (N - 1))`` of the same world (u = (a + 1) / 2)      |
| 2     | overlay hop limit: ``1 + round(u * (max_hops - 1))``                                        |
| 3..   | payload (D floats)                                                                        |

"group" sends a GROUP message to the sender's group (nothing when it has none); "nearest" a unicast to the
nearest online agent of the world within ``nearest_range`` (nothing when none is that close); "named" a
unicast (nothing when it names the sender itself); "overlay" starts a flood (no bus involved).
Collision messages from the environment are written straight into the hit agent's inbox (the environment is
local to the agent, no channel applies), so the agent's final observation names what hit it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from agentsim_env.comms.bus import ChannelConfig, DeliveryEvents, MessageBus
from agentsim_env.comms.messages import (
    AGENT,
    ENV,
    ENV_COLLISION_AGENT,
    ENV_COLLISION_OBJECT,
    FEATURES_PER_MESSAGE,
    GROUP,
    OVERLAY,
    env_collision_payload,
)
from agentsim_env.comms.overlay import Deliveries, Overlay
from agentsim_env.groups.controller import GroupController, GroupEvents
from agentsim_env.scenarios.config import check_float, check_int

CHANNELS = ("none", "group", "nearest", "named", "overlay")


@nb.njit(cache=True)
def _nearest_kernel(i, j, d, n_slots, max_d):  # type: ignore[no-untyped-def]
    """Nearest neighbour of every slot over the range-graph pairs (ties: the lower slot); -1 when none."""
    best = np.full(n_slots, np.inf)
    out = np.full(n_slots, -1, dtype=np.int64)
    for k in range(i.shape[0]):
        if d[k] > max_d:
            continue
        a, b = i[k], j[k]
        if d[k] < best[a] or (d[k] == best[a] and b < out[a]):
            best[a], out[a] = d[k], b
        if d[k] < best[b] or (d[k] == best[b] and a < out[b]):
            best[b], out[b] = d[k], a
    return out


COMM_HEADER = 3


@dataclass(frozen=True)
class CommsConfig:
    """Communication settings of a scenario.

    Attributes:
        payload_dim: Payload width D of every message.
        inbox_size: Messages each agent observes (newest first).
        latency: Bus delivery latency in steps.
        loss: Bus loss probability per (message, receiver), in [0, 1].
        bandwidth: Messages an agent may send per step on the bus (0 = unlimited).
        max_range: Bus range limit in metres (None = unlimited).
        overlay_range: Transmission range of the overlay (peer to peer) in metres.
        overlay_full: Spread a flood to its hop limit within one step instead of one hop per step.
        max_hops: Largest hop limit an action can ask for.
        nearest_range: How far "nearest" looks for a receiver, in metres.
        heartbeat_period: Steps between heartbeats (0 = no heartbeats, nobody times out).
        heartbeat_timeout: Steps without an answer before an agent is declared offline.
    """

    payload_dim: int = 4
    inbox_size: int = 4
    latency: int = 0
    loss: float = 0.0
    bandwidth: int = 0
    max_range: float | None = None
    overlay_range: float = 30.0
    overlay_full: bool = False
    max_hops: int = 6
    nearest_range: float = 30.0
    heartbeat_period: int = 0
    heartbeat_timeout: int = 10

    def __post_init__(self) -> None:
        check_int("comms.payload_dim", self.payload_dim, 0, 64)
        check_int("comms.inbox_size", self.inbox_size, 1, 64)
        check_int("comms.max_hops", self.max_hops, 1, 255)
        check_int("comms.heartbeat_period", self.heartbeat_period, 0)
        check_int("comms.heartbeat_timeout", self.heartbeat_timeout, 1)
        check_float("comms.overlay_range", self.overlay_range, 0.0, lo_open=True)
        check_float("comms.nearest_range", self.nearest_range, 0.0, lo_open=True)
        if self.heartbeat_period and self.heartbeat_timeout < self.heartbeat_period + 2 * self.latency:
            raise ValueError(
                f"comms.heartbeat_timeout must be >= heartbeat_period + 2 * latency "
                f"({self.heartbeat_period + 2 * self.latency}), got {self.heartbeat_timeout}"
            )
        self.channel()  # validates latency, loss, bandwidth, max_range with their names

    def channel(self) -> ChannelConfig:
        """The bus channel model."""
        try:
            return ChannelConfig(self.latency, self.loss, self.bandwidth, self.max_range)
        except ValueError as exc:
            raise ValueError(f"comms.{exc}") from None

    @property
    def action_dim(self) -> int:
        """Length of the ``comm`` action."""
        return COMM_HEADER + self.payload_dim

    @property
    def features(self) -> int:
        """Features per inbox message."""
        return FEATURES_PER_MESSAGE + self.payload_dim


@dataclass(slots=True)
class CommsEvents:
    """The step's traffic for the data store (arrays)."""

    bus: DeliveryEvents | None
    overlay: Deliveries | None
    groups: GroupEvents | None
    sent: np.ndarray


class CommsStack:
    """Bus, overlay and group controller of B worlds, sharing the state's group array.

    Args:
        cfg: Communication settings.
        n_worlds: Worlds B.
        n_agents: Agents per world N.
        group: The state's ``(S,)`` group array (shared by reference, written by the controller).
        rng: Generator for channel loss (replaced on ``reset``).
    """

    def __init__(
        self, cfg: CommsConfig, n_worlds: int, n_agents: int, group: np.ndarray, rng: np.random.Generator
    ) -> None:
        self.cfg = cfg
        self.n_agents = n_agents
        s = n_worlds * n_agents
        self.bus = MessageBus(n_worlds, n_agents, cfg.payload_dim, cfg.channel(), cfg.inbox_size, rng, group=group,
                              pos_scale=cfg.overlay_range)  # fmt: skip
        self.overlay = Overlay(s, cfg.payload_dim, cfg.overlay_range, full_propagation=cfg.overlay_full)
        period = cfg.heartbeat_period
        self.groups = GroupController(
            n_worlds, n_agents, period, max(cfg.heartbeat_timeout, period), group=group
        )
        self.sent = np.zeros(s, dtype=np.int64)
        self._received0 = np.zeros(s, dtype=np.int64)
        self._dropped0 = np.zeros(s, dtype=np.int64)
        self.pairs: tuple[np.ndarray, np.ndarray, np.ndarray] = (np.zeros(0, np.int64),) * 2 + (np.zeros(0),)
        self.events = CommsEvents(None, None, None, self.sent.copy())

    # ------------------------------------------------------------------ lifecycle
    def reset(self, rng: np.random.Generator, step: int) -> None:
        """Drop all traffic of every world; ``rng`` drives the channel's loss from now on."""
        self.bus.reset(rng)
        self.overlay.reset()
        self.groups.reset(step)
        self.sent[:] = 0

    def reset_world(self, w: int, step: int) -> None:
        """Drop the traffic of world ``w`` only (it starts a new episode while others go on)."""
        slots = np.arange(w * self.n_agents, (w + 1) * self.n_agents)
        self.bus.drop_world(w)
        self.overlay.drop_slots(slots)
        self.groups.reset_slots(slots, step)
        self.sent[slots] = 0

    # ------------------------------------------------------------------ stage 1
    def send_actions(self, step: int, comm: np.ndarray, acting: np.ndarray, group: np.ndarray) -> None:
        """Turn the acting slots' ``comm`` actions ``(S, 3 + D)`` into bus messages and overlay floods."""
        n, cfg = self.n_agents, self.cfg
        self.sent[:] = 0
        self._received0 = self.bus.inbox.received.copy()
        self._dropped0 = self.bus.inbox.dropped.copy()
        sel = np.minimum(((comm[:, 0] + 1.0) * (len(CHANNELS) / 2.0)).astype(np.int64), len(CHANNELS) - 1)
        sel[~acting] = 0
        payload = comm[:, COMM_HEADER:].astype(np.float32)
        u = (comm + 1.0) * 0.5
        slots = np.arange(comm.shape[0])
        # group
        g = np.flatnonzero((sel == 1) & (group >= 0))
        if g.size:
            self.bus.send(GROUP, g, group[g], payload[g], step)
            self.sent[g] += 1
        # nearest (from the pairs of the positions the agents act on)
        m = np.flatnonzero(sel == 2)
        if m.size:
            near = self._nearest()
            m = m[near[m] >= 0]
            if m.size:
                self.bus.send(AGENT, m, near[m], payload[m], step)
                self.sent[m] += 1
        # named
        m = np.flatnonzero(sel == 3)
        if m.size:
            tgt = (m // n) * n + np.rint(u[m, 1] * (n - 1)).astype(np.int64)
            keep = tgt != m
            m, tgt = m[keep], tgt[keep]
            if m.size:
                self.bus.send(AGENT, m, tgt, payload[m], step)
                self.sent[m] += 1
        # overlay flood
        m = slots[sel == 4]
        if m.size:
            hops = 1 + np.rint(u[m, 2] * (cfg.max_hops - 1)).astype(np.int64)
            self.overlay.start(m, hops, payload[m], step)
            self.sent[m] += 1

    def _nearest(self) -> np.ndarray:
        i, j, d = self.pairs
        return _nearest_kernel(i, j, d, self.sent.shape[0], float(self.cfg.nearest_range))

    # ------------------------------------------------------------------ stages 5-7
    def on_collisions(self, step: int, agent: np.ndarray, other_agent: np.ndarray, obj: np.ndarray) -> None:
        """Write an ENV message into each hit agent's inbox naming the other agent (index in world) or object."""
        if agent.size == 0:
            return
        what = np.where(other_agent >= 0, ENV_COLLISION_AGENT, ENV_COLLISION_OBJECT)
        ident = np.where(other_agent >= 0, other_agent % self.n_agents, obj)
        pay = env_collision_payload(what, ident, self.cfg.payload_dim)
        k = agent.size
        self.bus.inbox.push(agent, np.full(k, ENV, np.int8), np.full(k, -1, np.int64), np.zeros(k, np.int16),
                            np.full(k, step, np.int64), pay)  # fmt: skip

    def tick_groups(self, step: int, online: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Heartbeats; returns the slots that timed out (the world takes them offline)."""
        return self.groups.tick(step, self.bus, online, pos)

    def deliver(
        self,
        step: int,
        pos: np.ndarray,
        online: np.ndarray,
        group: np.ndarray,
        world: np.ndarray,
        pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> CommsEvents:
        """Deliver the bus messages due now and advance every overlay flood by one hop (or fully)."""
        self.pairs = pairs
        bus_ev = self.bus.deliver(step, pos, online, group)
        ov = self.overlay.advance(pos, online, world, pairs, step)
        if len(ov):
            self.bus.inbox.push(ov.receiver, np.full(len(ov), OVERLAY, np.int8), ov.origin,
                                np.minimum(ov.hops, 32767).astype(np.int16), ov.created, ov.payload)  # fmt: skip
        self.events = CommsEvents(bus_ev, ov, self.groups.take_events(), self.sent.copy())
        return self.events

    # ------------------------------------------------------------------ observation
    def observe(self, pos: np.ndarray, step: int) -> tuple[np.ndarray, np.ndarray]:
        """Inbox features ``(S, M, F)`` and per-step counters ``(S, 2)``: received and dropped / inbox size."""
        inbox = self.bus.inbox.observe(pos, step)
        m = float(self.cfg.inbox_size)
        rec = (self.bus.inbox.received - self._received0) / m
        drop = (self.bus.inbox.dropped - self._dropped0) / m
        stats = np.clip(np.column_stack([rec, drop]), 0.0, 1.0).astype(np.float32)
        return inbox, stats
