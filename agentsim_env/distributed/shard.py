"""A shard that steps itself: the whole step pipeline for the agents it owns, with ghosts from its neighbours.

A ``Shard`` holds a whole-map ``World`` of the scenario (full-length slot arrays, so a slot keeps its index
everywhere) and a replica of the static scene; its own agents and its ghosts are online in it. One step is one
call, ``step`` (or ``act`` in a rollout, the policy inside the shard): the scenario's ``run_step`` (stage 1 for
the own agents that act, ``World.step``, the scoring), the same code as one process, with the world's ``bridge``
set to the shard, so the step meets the other shards at the exchange (``distributed.exchange``, routed by
``distributed.bridge``) at five barriers: after the motion (hand-overs and ghosts), after the groups stage (the
ghosts that went offline, the overlay's ghost frontier), at the bus delivery (messages across shards), at the
scoring (per-group sums, and the far senders in its inboxes whose positions the observations need) and before
the observations (those positions answered); a scenario without group sums asks for the far senders in a barrier
of their own (six). What it returns is what the caller asked for: the own agents' rows of rewards, terminations
and infos, their observations (``obs=True``) and their kinematics (``kinematics=True``, for a mirror of the
world).
"""

from __future__ import annotations

import os
import socket
import time
from typing import Any, Protocol

import numpy as np

from agentsim_env.comms.bus import DeliveryEvents, MessageBus
from agentsim_env.comms.events import DueRows, MessageLog
from agentsim_env.comms.messages import GROUP
from agentsim_env.core.pipeline import StepContext
from agentsim_env.distributed.bridge import Packed
from agentsim_env.distributed.floods import FloodEntries
from agentsim_env.distributed.partition import Strips
from agentsim_env.distributed.shard_overlay import ShardOverlay
from agentsim_env.distributed.shard_rollout import ShardRollout
from agentsim_env.scenarios.base import run_step
from agentsim_env.scenarios.registry import make_scenario
from agentsim_env.sim import World
from agentsim_env.sim.slot_rows import slot_arrays

_NONE = np.zeros(0, dtype=np.int64)
#: Per-slot arrays of a shard's world that are the shard's, not the agent's (its masks, its flood table).
SHARD_PATHS = ("comms.overlay.own", "comms.overlay.part", "comms.router")


class Swap(Protocol):
    """The exchange as a shard sees it: post, wait, get its part."""

    def __call__(self, key: tuple[int, str], k: int, payload: Packed) -> Packed:
        """Post ``payload`` for barrier ``key`` as shard ``k`` and return shard ``k``'s part."""


def _agent_arrays(world: World) -> dict[str, np.ndarray]:
    return {k: v for k, v in slot_arrays(world).items() if not k.startswith(SHARD_PATHS)}


def pack_rows(world: World, slots: np.ndarray, arrays: dict[str, np.ndarray] | None = None) -> Packed:
    """Every per-slot row of ``slots`` an agent takes with it to another shard (``sim.slot_rows``; ``arrays``:
    the world's agent arrays when the caller found them already)."""
    rows: Packed = {k: v[slots] for k, v in (_agent_arrays(world) if arrays is None else arrays).items()}
    rows["slots"] = slots
    return rows


def unpack_rows(world: World, rows: Packed, arrays: dict[str, np.ndarray] | None = None) -> None:
    """Write handed-over rows (``pack_rows``) into ``world`` (``arrays`` as for ``pack_rows``)."""
    slots = rows["slots"]
    arrays = _agent_arrays(world) if arrays is None else arrays
    for key, v in rows.items():
        if key in arrays:
            arrays[key][slots] = v


class Shard:
    """The own agents of some strips and their ghosts, stepping themselves (see the module docstring).

    Args:
        index: This shard's index k.
        name: Registered scenario name.
        config: The scenario's config fields (as given to ``make``).
        strips: The partition (strip edges, halo and the strips' owners).
        swap: The exchange.
        delay_s: Test hook: sleep this long in every call (a slow machine).
    """

    def __init__(
        self, index: int, name: str, config: dict[str, Any], strips: Strips, swap: Swap, delay_s: float = 0.0
    ) -> None:
        self.index = int(index)
        self.scenario = make_scenario(name, **config)
        self.world = self.scenario.build(1)
        self.strips = strips
        self._swap = swap
        self.wait_s = 0.0
        """Seconds spent at the exchange in the current call (waiting for the others, routing, transfer)."""
        self.delay_s = float(delay_s)
        s = self.world.state.n_slots
        self.own = np.zeros(s, dtype=bool)
        self.held = np.zeros(s, dtype=bool)
        """The own agents and those that ended here: the bus delivers (and drops) their messages here."""
        self.ghost = np.zeros(s, dtype=bool)
        self.acting = np.zeros(s, dtype=bool)
        self.arrived = _NONE
        """The slots handed over to this shard in the latest step."""
        self._asked: tuple[int, np.ndarray, np.ndarray] | None = None  # (tick, need, serve) of ``combine``
        self.config = config
        self.carry: dict[str, np.ndarray] = {"acting": self.acting}
        """The shard's own per-slot arrays that travel with a handed-over agent (a rollout adds its sums)."""
        self.rollout: Any = None
        """The rollout in progress (``distributed.shard_rollout.ShardRollout``)."""
        self.address = f"{socket.gethostname()}:{os.getpid()}"
        self.obs_out: np.ndarray | None = None
        """Where the step API's observation rows go instead of the reply (``distributed.obs_shm``), if set."""
        self.obs_full: tuple[np.ndarray, ...] = ()
        """The driver's arrays of every slot's observation row (``obs_shm.ObsSegment.full``): a step told to
        fill one (``obs_buf`` in its control) writes its rows there at their slots' rows."""
        self.act_in: Any = None
        """Where the step API's actions come from when a call carries only their count (an
        ``obs_shm.RowReader``), if set."""
        self.reply_out: tuple[Any, Any] | None = None
        """Where a step's per-agent reply rows go instead of the reply (``obs_shm.RowReader`` of the acting
        agents' rows and of the own agents' kinematics), if set."""
        self.world.bridge = self
        self.overlay: ShardOverlay | None = None
        comms = self.world.comms
        if comms is not None:  # the bus is bridged through this worker; floods spread per shard
            self.overlay = ShardOverlay(comms.overlay, self.own)
            comms.overlay = self.overlay  # type: ignore[assignment]
            comms.router = self

    # ------------------------------------------------------------------ helpers
    def swap(self, key: tuple[int, str], k: int, payload: Packed) -> Packed:
        """The exchange (timed: ``wait_s``)."""
        t0 = time.perf_counter()
        try:
            return self._swap(key, k, payload)
        finally:
            self.wait_s += time.perf_counter() - t0

    def beat(self, t0: float) -> Packed:
        """The heartbeat every reply carries (``compute_s`` is the call's time, ``wait_s`` its exchanges')."""
        wait, self.wait_s = self.wait_s, 0.0
        return {
            "shard": self.index,
            "address": self.address,
            "step": int(self.world.tick),
            "compute_s": time.perf_counter() - t0,
            "wait_s": wait,
        }

    def set_delay(self, delay_s: float) -> None:
        """Test hook: sleep ``delay_s`` seconds in every later call (0: none)."""
        self.delay_s = float(delay_s)

    def _pause(self) -> None:
        if self.delay_s > 0:
            time.sleep(self.delay_s)

    def _near_edge(self, x: np.ndarray) -> np.ndarray:
        """Which of these x coordinates (of own agents) lie within a halo of their strip's inner edges."""
        st = self.strips
        r = st.strip_of(x)
        left = (x - st.edges[r] <= st.halo) & (r > 0)
        right = (st.edges[r + 1] - x <= st.halo) & (r < st.n_strips - 1)
        return left | right

    def _rows_out(
        self, slots: np.ndarray, res: Any, terminated: np.ndarray, obs: bool, kin: bool, full: int = -1
    ) -> Packed:
        st = self.world.state
        out: Packed = {"slots": slots, "own": np.flatnonzero(self.own)}
        if res is not None and self.reply_out is not None:  # into this shard's regions of the driver's segments
            acted, own = self.reply_out
            info = list(res.info.items())
            cols = {"rewards": np.asarray(res.rewards, dtype=np.float64), "terminated": terminated}
            cols.update({f"info{i}": np.asarray(v, dtype=np.float64) for i, (_, v) in enumerate(info)})
            out["rows_n"] = acted.write(slots, cols)
            out["info_dtypes"] = tuple((k, np.asarray(v).dtype.str) for k, v in info)
            kinematics = {"pos": st.pos, "vel": st.vel, "heading": st.heading, "online": st.online}
            out["own_n"] = own.write(out.pop("own"), kinematics if kin else None)
            out["own_kin"], kin = kin, False
            del out["slots"]
        elif res is not None:
            out["rewards"] = np.asarray(res.rewards, dtype=np.float64)[slots]
            out["terminated"] = terminated[slots]
            out["info"] = {k: v[slots] for k, v in res.info.items()}
        if obs:
            self._sender_positions()
            if 0 <= full < len(self.obs_full):  # straight at their slots' rows of the array the step returns
                self.flat_rows(slots, self.obs_full[full], at=slots)
                out["obs_at"] = full
            elif self.obs_out is None:
                out["obs"] = self.flat_rows(slots)
            else:  # into this shard's region of the driver's segment
                out["obs_n"] = int(self.flat_rows(slots, self.obs_out[: slots.size]).shape[0])
        if kin:
            mine = out["own"]
            out["pos"], out["vel"], out["heading"] = st.pos[mine], st.vel[mine], st.heading[mine]
            out["online"] = st.online[mine]
        return out

    # ------------------------------------------------------------------ the bridge (World.step calls these)
    def after_motion(self, world: World, ctx: StepContext) -> None:
        """Hand over the own agents that left this shard's strips; take in arrivals and this step's ghosts."""
        st = world.state
        mine = np.flatnonzero(self.own & st.online)
        x = st.pos[mine, 0]
        leaving = mine[self.strips.owner_of(x) != self.index]
        edge = mine[self._near_edge(x)]
        if world.groups is not None and leaving.size:
            world.groups.settle_answers()  # heartbeat answers not yet read go with their agents
        leave: Packed = {"slots": leaving}
        arrays: dict[str, np.ndarray] | None = None  # found once a call (a walk of the world's objects, ~1 ms)
        if leaving.size:  # the per-slot arrays are looked up only when an agent leaves
            arrays = _agent_arrays(world)
            leave = pack_rows(world, leaving, arrays)
            for name, arr in self.carry.items():
                leave[f"w.{name}"] = arr[leaving]
        leave["x"] = st.pos[leaving, 0]
        post: dict[str, Any] = {
            "edge": {"slots": edge, "x": st.pos[edge, 0], "pos": st.pos[edge]},
            "leave": leave,
        }
        if self.overlay is not None and leaving.size:
            post["leave_floods"] = self.overlay.part.take_leaving(leaving)
        got = self.swap((int(world.tick), "motion"), self.index, post)
        if self.overlay is not None and got.get("floods"):
            self.overlay.part.add(FloodEntries.concat(got["floods"], self.overlay.payload_dim))
        self.own[leaving] = False
        self.held[leaving] = False
        self.acting[leaving] = False
        st.online[leaving] = False
        arrivals = got["arrivals"]
        self.arrived = _NONE
        if arrivals is not None and arrivals["slots"].size:
            new = self.arrived = arrivals["slots"]
            unpack_rows(world, arrivals, arrays)
            self.own[new] = True
            self.held[new] = True
            for name, arr in self.carry.items():
                arr[new] = arrivals[f"w.{name}"]
        g = got["ghosts"]["slots"]
        self.ghost[:] = False
        self.ghost[g] = True
        st.pos[g] = got["ghosts"]["pos"]
        st.online[g] = True

    def after_offline(self, world: World, ctx: StepContext, went: np.ndarray) -> np.ndarray:
        """Tell the neighbours which own agents near an edge went offline; the ghosts that went offline."""
        st = world.state
        near = went[self.own[went] & self._near_edge(st.pos[went, 0])] if went.size else went
        post: Packed = {"slots": near}
        if self.overlay is not None:
            mine = np.flatnonzero(self.own)
            front = self.overlay.part.frontier_of(mine[self._near_edge(st.pos[mine, 0])])
            post["front"], post["front_x"] = front, st.pos[front.slot, 0]
        got = self.swap((int(world.tick), "offline"), self.index, post)
        if self.overlay is not None:
            self.overlay.ghost_frontier = FloodEntries.concat(got.get("front", []), self.overlay.payload_dim)
        gone = got["slots"]
        # they stay ghosts for this step (their positions hold: a message they sent before going offline is
        # still delivered, as in one process); they only leave the grid
        return gone[self.ghost[gone] & st.online[gone]]

    def deliver(
        self, bus: MessageBus, step: int, pos: np.ndarray, online: np.ndarray, group: np.ndarray
    ) -> DeliveryEvents:
        """Stage 7's bus part on a shard: the due messages of every shard for the own receivers.

        Rows for an own receiver (or a heartbeat answer about an own agent) stay here; the others, and every
        GROUP row (members may live anywhere), go through the exchange to the shard owning their receiver.
        Heartbeat answers that become due in this call (latency 0) concern own agents: delivered here.
        """
        rows = bus.take_due(step)
        grp = rows.kind == GROUP
        slot = np.where(grp, 0, np.where(rows.target >= 0, rows.target, rows.sender))
        here = grp | self.held[slot]
        got = self.swap((int(self.world.tick), "bus"), self.index, {"rows": rows.take(grp | ~here)})
        d = bus.payload_dim
        mine = DueRows.concat([rows.take(here), *got["rows"]], d)
        seen = self.own | self.ghost
        rounds = [bus.deliver_rows(mine, step, pos, online, group, mine=self.held, seen=seen, push=False)]
        while len(again := bus.take_due(step)):
            rounds.append(bus.deliver_rows(again, step, pos, online, group, mine=self.held, seen=seen, push=False))
        if len(rounds) == 1:
            return rounds[0]
        return DeliveryEvents(
            int(step),
            *(MessageLog.concat([getattr(r, f) for r in rounds]) for f in ("sent", "delivered", "dropped")),
        )

    def flat_rows(self, slots: np.ndarray, out: np.ndarray | None = None, at: np.ndarray | None = None) -> np.ndarray:
        """The flat observation rows of ``slots``, computed for those rows only (``Scenario.observation_rows``),
        into ``out`` when given (at its rows ``at`` when given)."""
        return self.scenario.flat_observation_rows(self.world, slots, out, at)

    @staticmethod
    def flat_layout(parts: dict[str, np.ndarray], n: int, out: np.ndarray | None = None) -> np.ndarray:
        """Observation parts of ``n`` rows as flat rows ``(n, obs_dim)`` float32 (the parts in their order), into
        ``out`` when given."""
        if out is None:
            out = np.empty((n, sum(int(np.prod(v.shape[1:])) for v in parts.values())), dtype=np.float32)
        at = 0
        for v in parts.values():  # each part straight into its columns
            w = int(np.prod(v.shape[1:]))
            out[:, at : at + w] = v.reshape(n, w)
            at += w
        return out

    def _sender_positions(self) -> None:
        """The current positions of the senders in own inboxes that live on other shards beyond the halo.

        An inbox observation locates each message's sender where it is now; a sender far away is known only
        to its own shard: two exchanges fetch those positions (who wants which, then the answers); one when the
        scoring's group sums asked already (``combine``).
        """
        st = self.world.state
        if self.world.comms is None:
            return
        tick = int(self.world.tick)
        if self._asked is not None and self._asked[0] == tick:  # asked with the group sums of this step
            _, need, serve = self._asked
        else:
            need = self._need()
            serve = self.swap((tick, "want"), self.index, {"slots": np.flatnonzero(need)})["slots"]
        self._asked = None
        got = self.swap((tick, "have"), self.index, {"slots": serve, "pos": st.pos[serve]})
        sl, pos = got["slots"], got["pos"]
        sel = need[sl]
        st.pos[sl[sel]] = pos[sel]

    def _need(self) -> np.ndarray:
        """``(S,)`` the senders in own inboxes that are neither own nor ghosts (a mask: linear in the own inbox
        rows)."""
        comms = self.world.comms
        need = np.zeros(self.world.state.n_slots, dtype=bool)
        if comms is None:
            return need
        comms.bus.inbox.mark_senders(np.flatnonzero(self.own), need)
        need &= ~(self.own | self.ghost)
        return need

    def combine(self, partials: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The per-group sums of every shard.

        The far senders whose positions the observations will need ride along (the inboxes are final once the
        bus delivered): ``_sender_positions`` then needs one exchange instead of two. An own agent that ends in
        the scoring after this leaves a few more asked for than needed; their answers are not used.
        """
        tick = int(self.world.tick)
        need = self._need()
        got = self.swap((tick, "groups"), self.index, {"partials": partials, "want": np.flatnonzero(need)})
        self._asked = (tick, need, got["serve"])
        return got["sums"]

    # ------------------------------------------------------------------ episode
    def reset(
        self,
        seed: np.random.SeedSequence,
        owner: np.ndarray,
        obs: bool = True,
        kin: bool = False,
        tick: int | None = None,
    ) -> Packed:
        """Start the episode of ``seed`` exactly as one process does, then keep this shard's agents online.

        Every shard replays the placement, so every shard knows every agent's start: the ghosts need no
        exchange here.

        Returns:
            The own slots with their observation rows (``obs``) and kinematics (``kin``), and a heartbeat.
        """
        t0 = time.perf_counter()
        self._pause()
        self._asked = None
        world, st = self.world, self.world.state
        self.strips.owner = np.asarray(owner, dtype=np.int64).copy()
        if tick is not None:  # the coordinator's clock: a shard started anew keeps step with the others
            world.tick = int(tick)
        world.bridge = None  # the reset's sensing runs on the whole, identical world first
        placement = world.reset_world(0, seed)
        self.scenario.reset_world(world, 0, placement)
        alive = np.flatnonzero(st.online)
        x = st.pos[alive, 0]
        self.own[:] = False
        self.own[alive[self.strips.owner_of(x) == self.index]] = True
        self.held[:] = self.own
        self.ghost[:] = False
        self.ghost[self.strips.ghosts(x, alive, self.index)] = True
        st.online[:] = self.own | self.ghost
        world.refresh([0])
        world.bridge = self
        self.acting[:] = False
        out = self._rows_out(np.flatnonzero(self.own), None, self.own, obs, kin)
        out["beat"] = self.beat(t0)
        return out

    def run(self, slots: np.ndarray, parts: dict[str, np.ndarray], control: Packed) -> tuple[Any, np.ndarray]:
        """Apply ``control``, then ``run_step`` for the own slots ``slots`` with action parts over every slot.

        Returns:
            The scenario's result and the terminated mask (``self.acting`` holds the slots that acted and are
            own after the hand-overs).
        """
        self._asked = None
        world, st = self.world, self.world.state
        self.strips.owner = np.asarray(control["owner"], dtype=np.int64).copy()
        for kind, centre, half in control.get("objects", ()):
            world.scene.add(kind, centre, half, 0)
        ended = control.get("ended")
        if ended is not None and ended.size:
            world.set_offline(ended)
            self.own[ended] = False
        st.online[self.ghost] = False  # ghosts come fresh after the motion
        self.ghost[:] = False
        self.acting[:] = False
        self.acting[slots] = True
        return run_step(self.scenario, world, parts, self.acting)

    # ------------------------------------------------------------------ code API (messages, groups)
    def send(self, sender: int, target: int, payload: np.ndarray, to_group: bool) -> Packed:
        """A bus message from code by the own agent ``sender`` (``env.send_message``): whether it was accepted."""
        t0 = time.perf_counter()
        comms, tick = self.world.comms, int(self.world.tick)
        assert comms is not None
        if to_group:
            ok = comms.to_group(int(sender), int(target), payload, tick)
        else:
            ok = comms.unicast(int(sender), int(target), payload, tick)
        return {"accepted": bool(ok), "beat": self.beat(t0)}

    def assign_group(self, slot: int, group: int) -> Packed:
        """Move the own agent ``slot`` to ``group`` (``env.assign_group``)."""
        t0 = time.perf_counter()
        assert self.world.groups is not None
        self.world.groups.assign(np.array([int(slot)]), int(group), self.world.tick)
        return {"beat": self.beat(t0)}

    # ------------------------------------------------------------------ rollout (distributed.shard_rollout)
    def begin(self, policy: Any, seed: int | None) -> Packed:
        """Build the policy for a rollout of the episode just reset."""
        t0 = time.perf_counter()
        self.rollout = ShardRollout(self, policy, seed)
        return {"beat": self.beat(t0)}

    def act(self, control: Packed) -> Packed:
        """One rollout step: the policy acts for the own live agents; counts back."""
        t0 = time.perf_counter()
        self._pause()
        out = self.rollout.act(control)
        out["beat"] = self.beat(t0)
        return out

    def finish(self) -> Packed:
        """The end of a rollout: the per-agent rows of the own agents (and of those that ended here)."""
        t0 = time.perf_counter()
        out = self.rollout.finish()
        out["beat"] = self.beat(t0)
        return out

    # ------------------------------------------------------------------ step
    def step(
        self,
        slots: np.ndarray,
        parts: dict[str, np.ndarray],
        control: Packed,
    ) -> Packed:
        """One whole step of the own agents (see the module docstring).

        Args:
            slots: The own slots that act this step (sorted).
            parts: Their validated action parts (rows in the order of ``slots``).
            control: ``ended`` (slots that ended at the previous step anywhere, or were lost with a shard),
                ``objects`` (static objects added since the previous step, ``(kind, centre, half)`` each),
                ``owner`` (``(K,)`` the shard owning each strip), ``obs`` / ``kinematics`` (what to send back).

        Returns:
            The rows of the slots that acted and are own after the hand-overs (``slots``, ``rewards``,
            ``terminated``, ``info``, ``obs``), every own slot (``own``, with kinematics when asked), the
            collisions of own agents and a heartbeat.
        """
        t0 = time.perf_counter()
        self._pause()
        if slots is None:  # the driver wrote them into this shard's region of its action segment
            if self.act_in is None:
                raise RuntimeError("a step without its actions, and no action segment to read them from")
            slots, parts = self.act_in.read(int(control["act_n"]))
        s = self.world.state.n_slots
        full = {}
        for key, rows in parts.items():
            a = np.zeros((s, *rows.shape[1:]), dtype=rows.dtype)
            a[slots] = rows
            full[key] = a
        res, terminated = self.run(slots, full, control)
        world = self.world
        done = np.flatnonzero(self.acting)
        obs, kin = bool(control.get("obs", True)), bool(control.get("kinematics"))
        out = self._rows_out(done, res, terminated, obs, kin, int(control.get("obs_buf", -1)))
        col = world.last_events.collisions
        out["col.agent"], out["col.other"], out["col.obj"] = col.agent, col.other_agent, col.obj
        comms = world.comms
        if control.get("events") and comms is not None and comms.events.bus is not None:
            ce = comms.events
            assert ce.bus is not None
            out["bus.sent"], out["bus.delivered"], out["bus.dropped"] = (
                ce.bus.sent,
                ce.bus.delivered,
                ce.bus.dropped,
            )
            out["overlay"], out["sent"] = ce.overlay, np.where(self.own, ce.sent, 0)
        out["beat"] = self.beat(t0)
        return out
