"""Group controller: group ids, run-time reassignment, group broadcast, heartbeats and timeouts.

As in AgentSimJS, the controller assigns a group id to agents, changes it at run time, broadcasts to a
group through the bus (GROUP messages with sender -1) and monitors its agents with periodic heartbeats.

Heartbeat protocol (all traffic crosses the bus, so latency and loss apply both ways):

- Every ``heartbeat_period`` steps (``step % heartbeat_period == 0``) ``tick`` sends one HEARTBEAT to every
  ONLINE slot that belongs to a group (``group >= 0``); slots without a group are not monitored.
- The bus delivers it ``latency`` steps later (dropped if the slot went offline meanwhile) and the slot
  answers automatically; the answer reaches the controller another ``latency`` steps later unless lost.
- ``tick`` first reads the answers that arrived since the previous tick into ``last_answer`` (the step each
  answer arrived), then reports every monitored slot with ``step - last_answer > timeout``, offline ones
  included (an offline slot never answers). A slot is reported once (``timed_out`` remembers it); the world
  marks it offline.

With the pipeline order of DESIGN section 4 (``tick`` before ``deliver`` in a step) and a loss-free channel,
an answer arrives ``2 * latency`` steps after its heartbeat and is read by the next tick, so an online
member's ``step - last_answer`` stays <= ``heartbeat_period`` once it answers regularly, <= ``2 * latency``
after ``reset`` at a heartbeat step, and <= ``heartbeat_period - 1 + 2 * latency`` right after joining a
group between two heartbeats (a joining slot starts with ``last_answer`` = the step it joined). Choose
``timeout >= heartbeat_period + 2 * latency`` and no answering member is ever reported; the constructor
checks ``timeout >= heartbeat_period`` and ``tick`` checks ``timeout >= 2 * latency``. A member whose last
answer arrived at step ``a`` is reported by the tick of step ``a + timeout + 1``.

The controller manages all worlds of its slot array (slot ``s`` is in world ``s // n_agents``); messages
never cross worlds. ``heartbeat_period = 0`` disables heartbeats and timeouts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim_env.comms.bus import MessageBus
from agentsim_env.comms.messages import GROUP, HEARTBEAT


@dataclass(frozen=True, slots=True)
class GroupEvents:
    """Group changes as arrays, one row per slot whose group changed.

    Attributes:
        step: Step of the change ``(n,)`` int64.
        slot: Slot ``(n,)`` int64.
        old: Previous group ``(n,)`` int32 (-1 = none).
        new: New group ``(n,)`` int32 (-1 = none).
    """

    step: np.ndarray
    slot: np.ndarray
    old: np.ndarray
    new: np.ndarray

    def __len__(self) -> int:
        """Number of rows."""
        return int(self.slot.shape[0])


class GroupController:
    """Groups and heartbeat monitoring for the slots of ``n_worlds`` worlds.

    Attributes:
        n_worlds: Worlds B.
        n_agents: Agents per world N.
        heartbeat_period: Steps between heartbeats (0 = disabled).
        timeout: Steps without an answer after which a monitored slot is reported.
        group: ``(S,)`` int32 group id per slot (-1 = none); the array given to the constructor when one is.
        last_answer: ``(S,)`` int64 step the latest heartbeat answer of each slot arrived.
        timed_out: ``(S,)`` bool, slots already reported by ``tick``.
    """

    __slots__ = (
        "n_worlds",
        "n_agents",
        "heartbeat_period",
        "timeout",
        "group",
        "last_answer",
        "timed_out",
        "_step",
        "_events",
    )

    def __init__(
        self,
        n_worlds: int,
        n_agents: int,
        heartbeat_period: int,
        timeout: int,
        *,
        group: np.ndarray | None = None,
    ) -> None:
        """Create a controller; every slot starts without a group.

        Args:
            n_worlds: Worlds B (>= 1).
            n_agents: Agents per world N (>= 1).
            heartbeat_period: Steps between heartbeats (>= 0; 0 disables heartbeats and timeouts).
            timeout: Steps without an answer before a slot is reported (>= heartbeat_period and >= 1
                when enabled; any value >= 0 when disabled).
            group: Optional ``(S,)`` int32 array to own and write in place (e.g. ``AgentState.group``, so the
                world, the bus and the controller read one array); its current values are kept.
        """
        for name, v, lo in (
            ("n_worlds", n_worlds, 1),
            ("n_agents", n_agents, 1),
            ("heartbeat_period", heartbeat_period, 0),
            ("timeout", timeout, 0),
        ):
            if isinstance(v, bool) or int(v) != v or int(v) < lo:
                raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
        if heartbeat_period > 0 and timeout < max(1, heartbeat_period):
            raise ValueError(
                f"timeout must be >= heartbeat_period ({heartbeat_period}) and >= 1, got {timeout} "
                "(a member that answers every heartbeat would time out between two of them)"
            )
        self.n_worlds, self.n_agents = int(n_worlds), int(n_agents)
        self.heartbeat_period, self.timeout = int(heartbeat_period), int(timeout)
        s = self.n_worlds * self.n_agents
        if group is None:
            group = np.full(s, -1, dtype=np.int32)
        elif not isinstance(group, np.ndarray) or group.shape != (s,) or group.dtype != np.int32:
            raise ValueError(
                f"group must be an int32 numpy array of shape ({s},) (written in place), got "
                f"{getattr(group, 'dtype', type(group).__name__)} {np.shape(group)}"
            )
        if np.any(group < -1):
            raise ValueError("group ids must be >= -1 (-1 = no group)")
        self.group = group
        self.last_answer = np.zeros(s, dtype=np.int64)
        self.timed_out = np.zeros(s, dtype=bool)
        self._step = 0
        self._events: list[GroupEvents] = []

    @property
    def n_slots(self) -> int:
        """Total slots S."""
        return self.n_worlds * self.n_agents

    @property
    def enabled(self) -> bool:
        """Whether heartbeats and timeouts run."""
        return self.heartbeat_period > 0

    def reset(self, step: int = 0) -> None:
        """Forget answers, timeouts and events (groups are kept); every last answer becomes ``step``."""
        self.last_answer[:] = int(step)
        self.timed_out[:] = False
        self._step = int(step)
        self._events = []

    def reset_slots(self, slots: np.ndarray, step: int) -> None:
        """Restart monitoring of ``slots`` (a world reset alone): last answer ``step``, not timed out."""
        self.last_answer[slots] = int(step)
        self.timed_out[slots] = False

    def assign(self, slots: np.ndarray, groups: np.ndarray | int, step: int | None = None) -> None:
        """Set the group of ``slots`` and log every actual change.

        Args:
            slots: Distinct slots ``(k,)``.
            groups: New group ids, scalar or ``(k,)`` (>= -1; -1 = leave every group).
            step: Step of the change (default: the step of the latest ``tick``).
        """
        sl = np.asarray(slots).reshape(-1)
        if sl.size and not np.issubdtype(sl.dtype, np.integer):
            raise ValueError(f"slots must be integers, got {sl.dtype}")
        sl = sl.astype(np.int64)
        if sl.size and (sl.min() < 0 or sl.max() >= self.n_slots):
            raise ValueError(f"slots must be in [0, {self.n_slots}), got min {sl.min()} max {sl.max()}")
        if np.unique(sl).size != sl.size:
            raise ValueError("slots must be distinct (one new group per slot)")
        g = np.broadcast_to(np.asarray(groups), sl.shape)
        if g.size and (not np.issubdtype(g.dtype, np.integer) or g.min() < -1):
            raise ValueError(f"groups must be integers >= -1 (-1 = none), got {np.asarray(groups)!r}")
        st = self._step if step is None else int(step)
        old = self.group[sl].copy()
        changed = old != g
        joined = changed & (old < 0)
        self.last_answer[sl[joined]] = st  # a new member gets a full timeout before its first answer
        self.group[sl] = g
        if changed.any():
            c = sl[changed]
            self._events.append(
                GroupEvents(np.full(c.size, st, dtype=np.int64), c, old[changed], g[changed].astype(np.int32))
            )

    def take_events(self) -> GroupEvents:
        """Group changes logged since the previous call (the log is then emptied)."""
        ev = self._events
        self._events = []
        if not ev:
            e = np.empty(0, dtype=np.int64)
            return GroupEvents(e, e.copy(), np.empty(0, dtype=np.int32), np.empty(0, dtype=np.int32))
        return GroupEvents(
            *(np.concatenate([getattr(x, f) for x in ev]) for f in ("step", "slot", "old", "new"))
        )

    def members(self, world: int, group: int) -> np.ndarray:
        """Slots of ``world`` in ``group`` (online or not), ascending int64."""
        if not 0 <= int(world) < self.n_worlds:
            raise ValueError(f"world must be in [0, {self.n_worlds}), got {world}")
        lo = int(world) * self.n_agents
        return lo + np.flatnonzero(self.group[lo : lo + self.n_agents] == int(group))

    def broadcast(self, bus: MessageBus, world: int, group: int, payload: np.ndarray, step: int) -> bool:
        """Send ``payload`` to every online member of ``group`` in ``world`` (GROUP message, sender -1).

        Args:
            bus: The bus (its channel applies; GROUP targets are validated against this controller's groups).
            world: World index.
            group: Group id with at least one member in ``world``.
            payload: ``(D,)`` payload.
            step: Current step.

        Returns:
            Whether the bus accepted it (the controller is not bandwidth-limited, so True).
        """
        if not 0 <= int(world) < self.n_worlds:
            raise ValueError(f"world must be in [0, {self.n_worlds}), got {world}")
        p = np.asarray(payload, dtype=np.float32).reshape(1, -1)
        acc = bus.send(
            GROUP,
            np.array([-1]),
            np.array([int(group)]),
            p,
            step,
            world=np.array([int(world)]),
            group=self.group,
        )
        return bool(acc[0])

    def tick(
        self, step: int, bus: MessageBus, online: np.ndarray, pos: np.ndarray | None = None
    ) -> np.ndarray:
        """Read heartbeat answers, send this step's heartbeats and report newly timed-out slots.

        Args:
            step: Current step.
            bus: The bus the heartbeats and answers cross.
            online: ``(S,)`` bool online mask now.
            pos: ``(S, 3)`` positions; unused (the controller has no position, its messages are not
                range-limited), accepted so the world calls every subsystem alike.

        Returns:
            Slots (ascending int64) whose last answer is older than ``timeout`` steps, each reported once.
        """
        del pos
        step = int(step)
        self._step = step
        if not self.enabled:
            return np.empty(0, dtype=np.int64)
        if 2 * bus.channel.latency > self.timeout:
            raise ValueError(
                f"timeout ({self.timeout}) must be >= 2 * channel latency ({bus.channel.latency}): an answer "
                "needs a round trip"
            )
        online = np.asarray(online, dtype=bool)
        if online.shape != (self.n_slots,):
            raise ValueError(f"online must have shape ({self.n_slots},), got {online.shape}")
        slots, when = bus.take_answers()
        if slots.size:
            np.maximum.at(self.last_answer, slots, when)
        if step % self.heartbeat_period == 0:
            to = np.flatnonzero(online & (self.group >= 0))
            if to.size:
                bus.send(
                    HEARTBEAT,
                    np.full(to.size, -1, dtype=np.int64),
                    to,
                    np.zeros((to.size, bus.payload_dim), dtype=np.float32),
                    step,
                )
        late = (self.group >= 0) & ~self.timed_out & (step - self.last_answer > self.timeout)
        self.timed_out |= late
        return np.flatnonzero(late)
