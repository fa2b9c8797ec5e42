"""Group controller: group ids, run-time reassignment, group broadcast, heartbeats and timeouts.

As in AgentSimJS, the controller assigns a group id to agents, changes it at run time and monitors its agents
with periodic heartbeats. It is the groups stage (6) of the pipeline and imports no other subsystem: ``tick``
returns the slots to ping and the slots that timed out; the comms stage carries the heartbeats and answers
over the bus, and the world takes timed-out slots offline.

Heartbeat protocol (all traffic crosses the bus, so latency and loss apply both ways):

- Every ``heartbeat_period`` steps of a world (``phase % heartbeat_period == 0``, phase = steps since that
  world's reset) ``tick`` asks for one HEARTBEAT to every ONLINE slot of a group (``group >= 0``); slots
  without a group are not monitored.
- The bus delivers it ``latency`` steps later (dropped if the slot went offline meanwhile) and the slot
  answers automatically; the answer reaches the controller another ``latency`` steps later unless lost.
- ``tick`` first reads the answers handed to it (those that arrived since the previous tick) into
  ``last_answer`` (the step each answer arrived), then reports every monitored slot with
  ``step - last_answer > timeout``, offline ones included (an offline slot never answers). A slot is reported once
  (``timed_out`` remembers it); the world
  marks it offline.

With the pipeline order of DESIGN section 4 (``tick`` before ``deliver`` in a step) and a loss-free channel,
an answer arrives ``2 * latency`` steps after its heartbeat and is read by the next tick, so an online
member's ``step - last_answer`` stays <= ``heartbeat_period`` once it answers regularly, <= ``2 * latency``
after ``reset`` at a heartbeat step, and <= ``heartbeat_period - 1 + 2 * latency`` right after joining a
group between two heartbeats (a joining slot starts with ``last_answer`` = the step it joined). Choose
``timeout >= heartbeat_period + 2 * latency`` and no answering member is ever reported; the constructor
checks ``timeout >= heartbeat_period`` and ``CommsConfig`` checks the latency term. A member whose last
answer arrived at step ``a`` is reported by the tick of step ``a + timeout + 1``.

The controller manages all worlds of its slot array (slot ``s`` is in world ``s // n_agents``); messages
never cross worlds. ``heartbeat_period = 0`` disables heartbeats and timeouts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agentsim_env.core.pipeline import StepContext
from agentsim_env.core.validation import short_repr


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


@dataclass(frozen=True, slots=True)
class GroupStepEvents:
    """What the groups stage (6) reports each step.

    Attributes:
        timed_out: Slots whose heartbeat answers stopped past the timeout (the world takes them offline).
        ping: Slots the comms stage sends a heartbeat to this step.
        changes: Group changes logged since the previous step (run-time reassignment).
    """

    timed_out: np.ndarray
    ping: np.ndarray
    changes: GroupEvents


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
        "home",
        "n_worlds",
        "n_agents",
        "heartbeat_period",
        "timeout",
        "group",
        "last_answer",
        "timed_out",
        "_step",
        "_next_tick",
        "_answers",
        "_events",
    )

    name = "groups"

    def __init__(
        self,
        n_worlds: int,
        n_agents: int,
        heartbeat_period: int,
        timeout: int,
        *,
        group: np.ndarray | None = None,
        home: np.ndarray | None = None,
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
            home: Optional ``(S,)`` array of the groups a world's slots return to when it is reset (read at each
                reset, e.g. ``AgentState.home_group``); ``None``: a reset keeps the current groups.
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
        self.home = home
        self.last_answer = np.zeros(s, dtype=np.int64)
        self.timed_out = np.zeros(s, dtype=bool)
        self._step = 0
        self._next_tick = 0
        self._answers: tuple[np.ndarray, np.ndarray] | None = None
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
        if g.size and (not np.issubdtype(g.dtype, np.integer) or g.min() < -1 or g.max() >= self.n_agents):
            raise ValueError(
                f"group ids must be integers in -1..{self.n_agents - 1} (-1 = none; at most one group per agent), "
                f"got {short_repr(np.asarray(groups).tolist())}"
            )
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

    # ------------------------------------------------------------------ the pipeline stage
    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """World ``w`` starts a new episode: its slots return to their home groups, monitoring restarts."""
        del rng  # the groups stage draws nothing
        sl = np.arange(w * self.n_agents, (w + 1) * self.n_agents)
        if self.home is not None:
            self.group[sl] = self.home[sl]
        self.reset_slots(sl, self._next_tick)

    def receive_answers(self, answers: tuple[np.ndarray, np.ndarray]) -> None:
        """Heartbeat answers the comms stage collected (``(slots, steps)``), read by the next ``step``."""
        if self._answers is None or not self._answers[0].size:
            self._answers = answers
        else:
            self._answers = (
                np.concatenate([self._answers[0], answers[0]]),
                np.concatenate([self._answers[1], answers[1]]),
            )

    def settle_answers(self) -> None:
        """Read the answers handed in since the previous tick into ``last_answer`` now (the tick would).

        The result of the next tick does not change; a shard calls it before handing agents over, so their
        ``last_answer`` travels with them.
        """
        answers, self._answers = self._answers, None
        if answers is not None and answers[0].size:
            np.maximum.at(self.last_answer, answers[0], answers[1])

    def step(self, ctx: StepContext) -> GroupStepEvents:
        """Stage 6: heartbeat tick; returns the timed-out slots, the slots to ping and the group changes."""
        st = ctx.state
        self._next_tick = ctx.tick + 1
        if not self.enabled:  # no heartbeats: only the group changes to report
            self._step = ctx.tick
            empty = np.empty(0, dtype=np.int64)
            return GroupStepEvents(empty, empty, self.take_events())
        answers, self._answers = self._answers, None
        timed_out, ping = self.tick(ctx.tick, st.online, answers, ctx.step_count[st.world_id], ctx.own)
        return GroupStepEvents(timed_out[st.online[timed_out]], ping, self.take_events())

    def take_events(self) -> GroupEvents:
        """Group changes logged since the previous call (the log is then emptied)."""
        ev = self._events
        self._events = []
        if not ev:
            e = np.empty(0, dtype=np.int64)
            return GroupEvents(e, e.copy(), np.empty(0, dtype=np.int32), np.empty(0, dtype=np.int32))
        return GroupEvents(*(np.concatenate([getattr(x, f) for x in ev]) for f in ("step", "slot", "old", "new")))

    def members(self, world: int, group: int) -> np.ndarray:
        """Slots of ``world`` in ``group`` (online or not), ascending int64."""
        if not 0 <= int(world) < self.n_worlds:
            raise ValueError(f"world must be in [0, {self.n_worlds}), got {world}")
        lo = int(world) * self.n_agents
        return lo + np.flatnonzero(self.group[lo : lo + self.n_agents] == int(group))

    def tick(
        self,
        step: int,
        online: np.ndarray,
        answers: tuple[np.ndarray, np.ndarray] | None = None,
        phase: np.ndarray | None = None,
        mine: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Read heartbeat answers, choose this step's heartbeats and report newly timed-out slots.

        The controller sends nothing itself: it returns the slots to ping and the comms stage carries the
        heartbeats over the bus (so its channel applies both ways) and hands the answers back.

        Args:
            step: Current step (the global tick the answers are stamped with).
            online: ``(S,)`` bool online mask now.
            answers: ``(slots, steps)`` heartbeat answers that reached the controller since the previous tick
                (the bus's ``take_answers``), or ``None``.
            phase: ``(S,)`` steps since each slot's world was reset (heartbeats go out when it is a multiple of
                the period, so a world's heartbeats do not depend on other worlds); default ``step``.
            mine: ``(S,)`` bool, the slots this controller monitors (a shard's own agents; the others are
                monitored by their own shard), or ``None`` for every slot.

        Returns:
            ``(timed_out, ping)``: slots (ascending int64) whose last answer is older than ``timeout`` steps,
            each reported once; and the slots to send a heartbeat to now.
        """
        step = int(step)
        self._step = step
        empty = np.empty(0, dtype=np.int64)
        if not self.enabled:
            return empty, empty
        online = np.asarray(online, dtype=bool)
        if online.shape != (self.n_slots,):
            raise ValueError(f"online must have shape ({self.n_slots},), got {online.shape}")
        if answers is not None and answers[0].size:
            np.maximum.at(self.last_answer, answers[0], answers[1])
        if phase is None:
            due = np.full(self.n_slots, step % self.heartbeat_period == 0)
        else:
            due = phase % self.heartbeat_period == 0
        watched = self.group >= 0 if mine is None else (self.group >= 0) & mine
        ping = np.flatnonzero(due & online & watched)
        late = watched & ~self.timed_out & (step - self.last_answer > self.timeout)
        self.timed_out |= late
        return np.flatnonzero(late), ping
