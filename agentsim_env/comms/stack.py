"""The comms stage of the pipeline (stage 7): bus + overlay + inboxes, as one subsystem.

``CommsStack`` implements the subsystem protocol of ``core.pipeline``: ``reset_world(w, rng)`` drops world
``w``'s traffic and gives it its own loss stream; ``step(ctx)`` writes the environment's collision messages
(stage 5's events, read from the context) into the hit agents' inboxes, sends the heartbeats the groups stage
asked for, delivers the bus messages due this step and advances every overlay flood by one hop, and returns
the step's traffic (``CommsEvents``, including the heartbeat answers the world hands back to the groups stage).
Stage 1 calls ``send_actions`` with the agents' ``comm`` actions; ``send`` and ``broadcast`` are the code API
the env front ends use. ``observe`` gives the inbox features and per-step counters.

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
local to the agent, no channel applies), so the agent's final observation names what hit it: the other agent's
index in the world, or the object's index among its world's objects (as a single env of the same seed numbers it).
They take message ids from the bus and are reported with the step's bus traffic (a ``sent`` and a ``delivered``
row each, kind ENV), so the data store records every message an agent receives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Protocol

import numpy as np
from pydantic import Field

from agentsim_env.comms.bus import (
    Bandwidth,
    ChannelConfig,
    DeliveryEvents,
    Latency,
    MessageBus,
    Probability,
    Range,
)
from agentsim_env.comms.events import MessageLog
from agentsim_env.comms.messages import (
    AGENT,
    ENV,
    ENV_COLLISION_AGENT,
    ENV_COLLISION_OBJECT,
    FEATURES_PER_MESSAGE,
    GROUP,
    HEARTBEAT,
    OVERLAY,
    env_collision_payload,
)
from agentsim_env.comms.overlay import Deliveries, Overlay
from agentsim_env.comms.rangegraph import RangeGraph
from agentsim_env.comms.send_kernels import CHANNELS, COMM_HEADER, N_CHANNELS, comm_rows, decode  # noqa: F401  (the action layout, re-exported)
from agentsim_env.core.config_model import FieldError, Flag, Int, config
from agentsim_env.core.pipeline import StepContext
from agentsim_env.core.spatial import Grid
from agentsim_env.core.threads import RowThreads


@config("comms")
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

    payload_dim: Annotated[Int, Field(ge=0, le=64)] = 4
    inbox_size: Annotated[Int, Field(ge=1, le=64)] = 4
    latency: Latency = 0
    loss: Probability = 0.0
    bandwidth: Bandwidth = 0
    max_range: Range | None = None
    overlay_range: Range = 30.0
    overlay_full: Flag = False
    max_hops: Annotated[Int, Field(ge=1, le=255)] = 6
    nearest_range: Range = 30.0
    heartbeat_period: Annotated[Int, Field(ge=0)] = 0
    heartbeat_timeout: Annotated[Int, Field(ge=1)] = 10

    def __post_init__(self) -> None:
        if self.heartbeat_period and self.heartbeat_timeout < self.heartbeat_period + 2 * self.latency:
            raise FieldError(
                "heartbeat_timeout",
                f"must be >= heartbeat_period + 2 * latency ({self.heartbeat_period + 2 * self.latency}), "
                f"got {self.heartbeat_timeout}",
            )

    def channel(self) -> ChannelConfig:
        """The bus channel model."""
        return ChannelConfig(self.latency, self.loss, self.bandwidth, self.max_range)

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
    """The step's traffic for the data store (arrays).

    Attributes:
        bus: Bus messages sent, delivered and dropped (with reasons) this step, the environment's collision
            notices included (kind ENV: sent and delivered at once).
        overlay: Overlay deliveries of this step's hop.
        sent: ``(S,)`` messages each slot sent this step.
        answers: ``(slots, steps)`` heartbeat answers that reached the controller (for the groups stage).
    """

    bus: DeliveryEvents | None
    overlay: Deliveries | None
    sent: np.ndarray
    answers: tuple[np.ndarray, np.ndarray] = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))


_OVERLAY_KIND = np.full(1, OVERLAY, dtype=np.int8)
_NO_LINKS = (np.zeros(0, dtype=np.int64),) * 3
_NO_ROWS = np.zeros(0, dtype=np.int64)  # push_rows: delivery j takes payload row j


class BusRouter(Protocol):
    """Delivers a shard's due bus messages together with the other shards' (``MessageBus.deliver``'s contract)."""

    def deliver(
        self, bus: MessageBus, step: int, pos: np.ndarray, online: np.ndarray, group: np.ndarray
    ) -> DeliveryEvents:
        """Deliver the messages due at ``step`` into the own slots (pushes left to ``bus.take_pushes``)."""


class CommsStack:
    """Bus and overlay of B worlds (the comms subsystem), reading the state's group array.

    Args:
        cfg: Communication settings.
        n_worlds: Worlds B.
        n_agents: Agents per world N.
        group: The state's ``(S,)`` group array (read by reference; the groups stage writes it).
    """

    name = "comms"

    def __init__(self, cfg: CommsConfig, n_worlds: int, n_agents: int, group: np.ndarray) -> None:
        self.cfg = cfg
        self.n_agents = n_agents
        s = n_worlds * n_agents
        # each world's loss generator comes with its reset_world
        self.bus = MessageBus(
            n_worlds,
            n_agents,
            cfg.payload_dim,
            cfg.channel(),
            cfg.inbox_size,
            None,
            group=group,
            pos_scale=cfg.overlay_range,
        )
        self.overlay = Overlay(s, cfg.payload_dim, cfg.overlay_range, full_propagation=cfg.overlay_full)
        self.sent = np.zeros(s, dtype=np.int64)
        self._received0 = np.zeros(s, dtype=np.int64)
        self._dropped0 = np.zeros(s, dtype=np.int64)
        self.graph = RangeGraph(s, max(cfg.overlay_range, cfg.nearest_range), cfg.nearest_range)
        self._no_near = np.full(s, -1, dtype=np.int64)
        self._inbox_out = np.zeros((s, cfg.inbox_size, cfg.features), dtype=np.float32)
        self._notices: list[MessageLog] = []  # collision notices pushed this step, reported by ``deliver``
        self.events = CommsEvents(None, None, self.sent.copy())
        self.router: BusRouter | None = None
        """A shard's bus delivery (``distributed.shard``): its due messages bridged with the other shards."""

    @property
    def threads(self) -> RowThreads:
        """Threads of the comms kernels that split their work (the range graph's grid scan by rows, the
        overlay hop by floods, the inbox pushes and observations by receivers); results do not depend on them."""
        return self.graph.threads

    @threads.setter
    def threads(self, threads: RowThreads) -> None:
        self.graph.threads = self.overlay.threads = self.bus.inbox.threads = threads

    @property
    def pairs(self) -> tuple[np.ndarray, ...]:
        """Neighbour pairs ``(i, j, d)`` of the latest range graph (empty when it came from a grid)."""
        return self.graph.pairs

    @pairs.setter
    def pairs(self, pairs: tuple[np.ndarray, ...]) -> None:
        # The world sets the pairs of the current positions after a reset; "nearest" reads them.
        self.graph.set_pairs(pairs, np.zeros((0, 3)), np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64))

    def update_graph(
        self,
        neighbours: Grid | tuple[np.ndarray, ...],
        pos: np.ndarray,
        online: np.ndarray,
        world: np.ndarray,
    ) -> None:
        """Range graph of the current positions, which "nearest" sends and the overlay use.

        Args:
            neighbours: The step's neighbour grid (built over the online slots), or the pairs ``(i, j, d)`` of
                ``neighbor_pairs`` within ``max(overlay_range, nearest_range)``.
            pos: Positions ``(S, 3)``.
            online: ``(S,)`` bool.
            world: ``(S,)`` world ids.
        """
        if isinstance(neighbours, Grid):
            links = self.overlay.frontier_size > 0  # only a flood's next hop reads the links
            self.graph.set_grid(neighbours, pos, online, world, self.overlay.link_range, links)
        else:
            self.graph.set_pairs(neighbours, pos, online, world)

    # ------------------------------------------------------------------ lifecycle
    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """Drop the traffic of world ``w`` (it starts a new episode); its losses come from ``rng`` from now on."""
        slots = np.arange(w * self.n_agents, (w + 1) * self.n_agents)
        self.bus.reset_world(w, rng)
        self.overlay.drop_slots(slots)
        self.sent[slots] = 0
        self._received0[slots] = self.bus.inbox.received[slots]
        self._dropped0[slots] = self.bus.inbox.dropped[slots]

    # ------------------------------------------------------------------ code API
    def send(
        self, kind: int, sender: int, target: int, payload: np.ndarray, step: int, world: int | None = None
    ) -> bool:
        """Send one AGENT (to a slot) or GROUP (to a group id) message from code; counted as sent.

        Args:
            kind: ``AGENT`` or ``GROUP``.
            sender: Sending slot, or -1 for the group controller (a GROUP broadcast; then ``world`` is needed).
            target: Receiver slot (AGENT) or group id (GROUP).
            payload: ``(D,)`` payload.
            step: Current global tick.
            world: World of a controller broadcast.

        Returns:
            Whether the bus accepted it (False: over the sender's bandwidth this step).
        """
        pay = np.asarray(payload, dtype=np.float32).reshape(1, -1)
        wld = None if world is None else np.array([int(world)])
        acc = self.bus.send(kind, np.array([int(sender)]), np.array([int(target)]), pay, step, world=wld)
        if sender >= 0:
            self.sent[sender] += 1
        return bool(acc[0])

    def unicast(self, sender: int, receiver: int, payload: np.ndarray, step: int) -> bool:
        """An AGENT message from slot ``sender`` to slot ``receiver`` (see ``send``)."""
        return self.send(AGENT, sender, receiver, payload, step)

    def to_group(self, sender: int, group: int, payload: np.ndarray, step: int) -> bool:
        """A GROUP message from slot ``sender`` to every online member of ``group`` in its world."""
        return self.send(GROUP, sender, group, payload, step)

    def broadcast(self, world: int, group: int, payload: np.ndarray, step: int) -> bool:
        """Send ``payload`` from the group controller to every online member of ``group`` in ``world``."""
        return self.send(GROUP, -1, group, payload, step, world=world)

    # ------------------------------------------------------------------ stage 1
    def send_actions(self, step: int, comm: np.ndarray, acting: np.ndarray, group: np.ndarray) -> None:
        """Turn the acting slots' ``comm`` actions ``(S, 3 + D)`` into bus messages and overlay floods."""
        n, cfg = self.n_agents, self.cfg
        self.sent[:] = 0
        np.copyto(self._received0, self.bus.inbox.received)
        np.copyto(self._dropped0, self.bus.inbox.dropped)
        if comm.dtype == np.float64:
            comm = np.ascontiguousarray(comm)
            sel, named, hops, any_near = decode(comm, acting, n, cfg.max_hops, self.threads)
        else:  # the same arithmetic in numpy, in the comm array's own precision
            sel = np.minimum(((comm[:, 0] + 1.0) * (N_CHANNELS / 2.0)).astype(np.int64), N_CHANNELS - 1)
            sel[~acting] = 0
            slots = np.arange(comm.shape[0])
            named = (slots // n) * n + np.rint((comm[:, 1] + 1.0) * 0.5 * (n - 1)).astype(np.int64)
            hops = 1 + np.rint((comm[:, 2] + 1.0) * 0.5 * (cfg.max_hops - 1)).astype(np.int64)
            any_near = bool((sel == 2).any())
        # nearest from the range graph of the positions the agents act on
        near = self.graph.nearest() if any_near else self._no_near
        kind, snd, tgt, wld, pay, o_org, o_hops, o_pay = comm_rows(
            sel, group, near, named, hops, np.ascontiguousarray(comm), n, self.sent, self.threads
        )
        if snd.shape[0]:
            self.bus.enqueue(kind, snd, tgt, wld, pay, step)
        if o_org.shape[0]:
            self.overlay.start(o_org, o_hops, o_pay, step)

    # ------------------------------------------------------------------ stage 7
    def step(self, ctx: StepContext) -> CommsEvents:
        """Stage 7: collision messages, heartbeats, bus deliveries due now and one overlay hop.

        Reads stage 5's collisions and the groups stage's heartbeat requests (``ctx.outputs["groups"].ping``)
        from the context.
        """
        st, tick = ctx.state, ctx.tick
        col = ctx.collisions
        if col.agent.size:
            self.on_collisions(tick, col.agent, col.other_agent, ctx.scene.index_in_world(col.obj))
        groups = ctx.outputs.get("groups")
        ping = getattr(groups, "ping", None)
        if ping is not None and ping.size:
            k = ping.size
            self.bus.send(
                HEARTBEAT,
                np.full(k, -1, dtype=np.int64),
                ping,
                np.zeros((k, self.cfg.payload_dim), dtype=np.float32),
                tick,
            )
        # the tick each world's episode began: loss draws are keyed by the step within the episode, so a world
        # reset at any tick loses what the same episode loses in a fresh run
        self.bus.set_starts(tick - ctx.step_count)
        return self.deliver(tick, st.pos, st.online, st.group, st.world_id, ctx.grid)

    def on_collisions(self, step: int, agent: np.ndarray, other_agent: np.ndarray, obj: np.ndarray) -> None:
        """Write an ENV message into each hit agent's inbox naming the other agent or the object.

        Args:
            step: Current global tick.
            agent: ``(k,)`` hit slots.
            other_agent: ``(k,)`` slot of the other agent, or -1 for an object.
            obj: ``(k,)`` the object's index within its world (``Scene.index_in_world``), or -1.
        """
        if agent.size == 0:
            return
        what = np.where(other_agent >= 0, ENV_COLLISION_AGENT, ENV_COLLISION_OBJECT)
        ident = np.where(other_agent >= 0, other_agent % self.n_agents, obj)
        pay = env_collision_payload(what, ident, self.cfg.payload_dim)
        k = agent.size
        receiver = np.asarray(agent, dtype=np.int64)
        created = np.full(k, step, np.int64)
        self.bus.inbox.push(
            receiver, np.full(k, ENV, np.int8), np.full(k, -1, np.int64), np.zeros(k, np.int16), created, pay
        )
        # ids from the bus's counter: a notice is a message of the run like any other (unique id)
        self._notices.append(
            MessageLog(
                self.bus._new_ids(k),
                np.full(k, ENV, np.int8),
                np.full(k, -1, np.int64),
                receiver.copy(),
                receiver.copy(),
                created,
                created.copy(),
                np.zeros(k, np.int8),
            )
        )

    def deliver(
        self,
        step: int,
        pos: np.ndarray,
        online: np.ndarray,
        group: np.ndarray,
        world: np.ndarray,
        pairs: Grid | tuple[np.ndarray, ...],
    ) -> CommsEvents:
        """Deliver the bus messages due now and advance every overlay flood by one hop (or fully).

        ``pairs`` is the step's neighbour grid or its pairs (see ``update_graph``).
        """
        self.update_graph(pairs, pos, online, world)
        if self.router is None:
            bus_ev = self.bus.deliver(step, pos, online, group, push=False)
        else:
            bus_ev = self.router.deliver(self.bus, step, pos, online, group)
        if self._notices:  # the collision notices already in the inboxes: sent and delivered this step
            env = MessageLog.concat(self._notices)
            self._notices = []
            bus_ev = DeliveryEvents(
                bus_ev.step,
                MessageLog.concat([env, bus_ev.sent]),
                MessageLog.concat([env, bus_ev.delivered]),
                bus_ev.dropped,
            )
        pushes = self.bus.take_pushes()
        if self.overlay.frontier_size:
            ov = self.overlay.advance_graph(*self.graph.links(self.overlay.link_range))
        else:
            ov = self.overlay.advance_graph(*_NO_LINKS)
        k = len(ov)
        if k:
            # sender, created step and payload read from the flood table by flood id where the overlay has one
            snd, cre, pay, rows, by_rows = ov.push_columns()
            pushes.append((ov.receiver, np.broadcast_to(_OVERLAY_KIND, (k,)), snd, ov.hops, cre, pay, rows, by_rows))
        self.bus.inbox.push_batches(pushes)  # bus deliveries, then the overlay's: one pass over the inboxes
        self.events = CommsEvents(bus_ev, ov, self.sent.copy(), self.bus.take_answers())
        return self.events

    # ------------------------------------------------------------------ observation
    def observe(self, pos: np.ndarray, step: int, clip: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """Inbox features ``(S, M, F)`` (each clipped to ``[-clip, clip]``) and per-step counters ``(S, 2)``:
        received and dropped / inbox size.

        The inbox features are written into a buffer reused by the next call (copy them to keep them); the
        counters are a fresh array.
        """
        inbox = self.bus.inbox.observe(pos, step, out=self._inbox_out, clip=clip)
        return inbox, self._stats(slice(None))

    def observe_flat(self, pos: np.ndarray, step: int, out: np.ndarray, col: int, clip: float) -> None:
        """``observe`` written into columns ``[col, col + M F + 2)`` of a flat observation ``out`` ``(S, width)``
        float32: the inbox features clipped to ``[-clip, clip]``, then the two counters (no intermediate arrays)."""
        inbox = self.bus.inbox
        width = inbox.size * inbox.n_features
        inbox.observe_flat(pos, step, out, col, clip)
        out[:, col + width : col + width + 2] = self._stats(slice(None))

    def observe_rows(
        self, pos: np.ndarray, step: int, rows: np.ndarray, clip: float = np.inf
    ) -> tuple[np.ndarray, np.ndarray]:
        """``observe`` for the slots ``rows`` only (fresh arrays): what a shard needs for its own agents."""
        return self.bus.inbox.observe_rows(pos, step, rows, clip), self._stats(rows)

    def observe_rows_flat(
        self,
        pos: np.ndarray,
        step: int,
        rows: np.ndarray,
        out: np.ndarray,
        col: int,
        clip: float,
        at: np.ndarray | None = None,
    ) -> None:
        """``observe_rows`` written into columns ``[col, col + M F + 2)`` of ``out`` float32, as ``observe_flat``
        writes every slot's: slot ``rows[r]`` into row ``r`` (``out``: ``(len(rows), width)``), or into row
        ``at[r]`` when ``at`` is given."""
        inbox = self.bus.inbox
        width = inbox.size * inbox.n_features
        inbox.observe_rows_flat(pos, step, rows, out, col, clip, at)
        if at is None:
            out[:, col + width : col + width + 2] = self._stats(rows)
        else:
            out[at, col + width : col + width + 2] = self._stats(rows)

    def _stats(self, rows: slice | np.ndarray) -> np.ndarray:
        """Received and dropped this step / inbox size, ``(n, 2)`` float32 in [0, 1]."""
        m = float(self.cfg.inbox_size)
        inbox = self.bus.inbox
        rec = (inbox.received[rows] - self._received0[rows]) / m
        drop = (inbox.dropped[rows] - self._dropped0[rows]) / m
        return np.clip(np.column_stack([rec, drop]), 0.0, 1.0).astype(np.float32)
