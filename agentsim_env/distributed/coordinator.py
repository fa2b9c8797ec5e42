"""The coordinator of shards that step themselves: it hands out actions, keeps the clock and the heartbeats.

Each shard (``distributed.shard``) runs the whole step for its own agents and meets the others at the exchange
(``distributed.exchange``, routed by ``distributed.bridge``). The driver does not order stages: a step is one
``step`` call per live shard, waited for with a deadline. What it keeps: which shard owns which slot (from the
replies, for splitting the caller's actions), each shard's heartbeat, the strips of a shard that went offline,
and the rows the caller asked for (rewards, terminations, infos, observations; kinematics into ``world``, the
mirror the step hooks, ``render`` and ``state()`` read).

Faults: a shard that dies, misses the deadline or raises is offline at once (the backend drops it from the
exchange, so the others finish their step): its agents report ``terminations`` once, its strips pass to the
nearest live shard, the rest goes on; ``reset`` restarts it. With no shard left the call raises a
``RuntimeError`` naming every shard's reason (chained to the exception a shard raised, if any).
"""

from __future__ import annotations

import logging
import time
import weakref
from typing import Any

import numpy as np

from agentsim_env.distributed.backends import Failure
from agentsim_env.distributed.bridge import Packed, nbytes
from agentsim_env.distributed.partition import Strips
from agentsim_env.distributed.replies import (
    ShardInfo,
    Traffic,
    merge_collisions,
    merge_comms,
    obs_dim,
    rollout_rows,
)
from agentsim_env.distributed.row_kernels import scatter_rows
from agentsim_env.scenarios.base import Scenario, StepResult, StepScores
from agentsim_env.sim import StepEvents, World

log = logging.getLogger("agentsim_env.distributed")
__all__ = ["Coordinator", "ShardInfo", "Traffic"]
_NONE = np.zeros(0, dtype=np.int64)


class Coordinator:
    """Steps K self-stepping shards over one world (see the module docstring).

    Args:
        scenario: The scenario (validated config, shardable).
        world: The mirror world (``scenario.build(1)``): kinematics when asked, the scene, the clock.
        strips: The partition.
        pool: The shards' backend (``backends.LocalShards`` or ``ray_backend.RayShards``).
        timeout_s: Deadline of every call, in seconds.
    """

    def __init__(self, scenario: Scenario, world: World, strips: Strips, pool: Any, timeout_s: float) -> None:
        self.scenario = scenario
        self.world = world
        self.strips = strips
        self.backend = pool
        self.timeout_s = float(timeout_s)
        self.shards = [ShardInfo(k) for k in range(pool.n_shards)]
        s = world.state.n_slots
        self.owner = np.full(s, -1, dtype=np.int64)
        self._ended = _NONE
        self._objects: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.lost = _NONE
        self._traffic = Traffic()
        self._unread = 0  # steps whose exchange bytes the exchange still holds (fetched when traffic is read)
        self.obs: np.ndarray | None = None
        """Every slot's observation row as last gathered (complete after a reset; a step given ``out`` writes its
        rows there and keeps here only the rows of the agents that ended)."""
        self._filled: Any = None  # weak reference to the array the last step filled
        self._given: Any = None  # weak reference to the ``out`` the last step was given (the same, or its copy)
        self._copy: np.ndarray | None = None  # that copy, when the last step made one
        self.kinematics = True
        """Gather every own agent's position each step into ``world`` (the mirror); off for rollouts."""
        self.profile: dict[str, Any] = {}
        """The latest rollout's seconds: ``wall_s`` of its steps, each shard's ``compute_s`` and ``wait_s`` (sums),
        and per step ``steps``: (the step call's wall time, each shard's call, each shard's exchange time)."""
        self.gather_events = False
        """Gather the step's message deliveries into ``world.last_events`` (also whenever hooks are attached)."""

    # ------------------------------------------------------------------ faults
    @property
    def alive(self) -> np.ndarray:
        """``(K,)`` bool: the shards still answering."""
        return np.array([i.alive for i in self.shards], dtype=bool)

    @property
    def traffic(self) -> Traffic:
        """Bytes of the latest step (after a rollout: per step of it), by kind (:class:`Traffic`).

        The exchange's part is asked for when this is read, not every step (a call to the exchange): read after
        every step it is that step's; read after several, their mean per step.
        """
        if self._unread:
            self._traffic.add_exchange(self.backend.exchange_bytes(), 1.0 / self._unread)
            self._unread = 0
        return self._traffic

    def _declare_offline(self, k: int, failure: Failure) -> None:
        info = self.shards[k]
        if not info.alive:
            return
        info.alive, info.reason = False, failure.reason
        slots = np.flatnonzero(self.owner == k)
        self.owner[slots] = -1
        self.world.set_offline(slots)
        self.lost = np.union1d(self.lost, slots)
        if not self.alive.any():
            reasons = "; ".join(f"shard {i.index}: {i.reason}" for i in self.shards)
            raise RuntimeError(
                f"every shard is offline ({reasons}): the simulation cannot go on (reset() restarts them)"
            ) from failure.error
        self.strips.reassign(k, self.alive)
        self.backend.set_owner(self.strips.owner)
        log.warning(
            "shard %d (%s) is offline: %s; its %d agents terminate, the simulation goes on",
            k,
            info.address,
            failure.reason,
            slots.size,
            exc_info=failure.error,
        )

    def _call(self, method: str, calls: dict[int, tuple[Any, ...]], on_reply: Any = None) -> dict[int, Packed]:
        # ``on_reply(k, reply)``: called with each shard's reply as it comes in (the Ray backend), while the
        # others still run
        calls = {k: a for k, a in calls.items() if self.shards[k].alive}
        replies = self.backend.call(method, calls, self.timeout_s, on_reply)
        out: dict[int, Packed] = {}
        now = time.time()
        failed = []
        for k, r in replies.items():
            if isinstance(r, Failure):
                failed.append((k, r))
                continue
            beat, info = r["beat"], self.shards[k]
            info.address, info.last_answer, info.last_step = beat["address"], now, beat["step"]
            info.step_s, info.wait_s = beat["compute_s"], beat.get("wait_s", 0.0)
            out[k] = r
        for k, r in failed:
            self._declare_offline(k, r)
        return out

    def restart_offline(self) -> None:
        """Start every offline shard anew and give each its strips back (before an episode)."""
        for info in self.shards:
            if not info.alive:
                self.backend.restart(info.index)
                info.alive, info.reason = True, ""
                info.restarts += 1
                log.info("shard %d restarted", info.index)
        self.strips.owner = np.arange(self.strips.n_strips, dtype=np.int64)
        self.backend.set_owner(self.strips.owner)

    def call_owner(self, slot: int, method: str, *args: Any) -> Packed:
        """Run ``method`` on the shard owning ``slot`` now (the code API: messages, group changes).

        Raises:
            ValueError: When the slot's shard is offline (its agents ended).
        """
        k = int(self.owner[int(slot)])
        if k < 0:
            raise ValueError(f"agent slot {slot} is not live on any shard")
        got = self._call(method, {k: args})
        if k not in got:
            raise ValueError(f"the shard of agent slot {slot} went offline: {self.shards[k].reason}")
        return got[k]

    def add_objects(self, kind: np.ndarray, centre: np.ndarray, half: np.ndarray) -> None:
        """Add static objects to the world now; every shard gets them before the next step's motion."""
        self.world.scene.add(kind, centre, half, 0)
        sc = self.world.scene
        k = np.atleast_2d(np.asarray(centre)).shape[0]
        self._objects.append((sc.kind[-k:].copy(), sc.centre[-k:].copy(), sc.half[-k:].copy()))

    # ------------------------------------------------------------------ gathering
    def _take_obs(self, k: int, r: Packed, out: np.ndarray | None = None, threads: int = 1) -> None:
        """Shard ``k``'s observation rows into ``out`` (default ``obs``): returned, or written into the shared
        segment (``obs_shm``); over ``threads`` threads."""
        out = self.obs if out is None else out
        assert out is not None
        rows = r["obs"] if "obs" in r else self.backend.obs_rows(k, int(r["obs_n"]))
        scatter_rows(out, np.asarray(r["slots"]), np.asarray(rows), threads)

    def _take(self, replies: dict[int, Packed], obs: bool, out: np.ndarray | None = None, threads: int = 1) -> None:
        """The replies' owners, observation rows (into ``out``, default ``obs``) and kinematics (into the mirror)."""
        st = self.world.state
        for k, r in replies.items():
            self.owner[r["own"]] = k
            if obs:
                self._take_obs(k, r, out, threads)
            if "pos" in r:
                mine = np.asarray(r["own"])
                scatter_rows(st.pos, mine, np.asarray(r["pos"]))
                scatter_rows(st.vel, mine, np.asarray(r["vel"]))
                st.heading[mine], st.online[mine] = r["heading"], r["online"]

    # ------------------------------------------------------------------ episode
    def reset(self, seed: np.random.SeedSequence, gather: bool = True) -> None:
        """Start the episode of ``seed`` on the mirror and on every shard (offline shards restarted first).

        ``gather``: bring every agent's observation back (the step API); a rollout keeps them on the shards.
        """
        self.restart_offline()
        world, sc = self.world, self.scenario
        placement = world.reset_world(0, seed)
        sc.reset_world(world, 0, placement)
        self._ended, self._objects, self.lost = _NONE, [], _NONE
        self._filled = self._given = None
        self.owner[:] = -1
        s = world.state.n_slots
        self.obs = np.zeros((s, obs_dim(sc)), np.float32)
        if gather:  # shards beside the driver take their actions and send their rows through shared memory
            layout = tuple((k, p.size, "<f8") for k, p in sc.act_parts().items())
            self.backend.share_rows(s, obs_dim(sc), layout, len(sc.info_keys()))
        replies = self._call(
            "reset",
            {
                k: (seed, self.strips.owner, gather, self.kinematics and gather, int(world.tick))
                for k in range(len(self.shards))
            },
        )
        self._take(replies, obs=gather)
        self.backend.set_slot_owner(self.owner)
        if not self.alive.all():  # a shard that failed its reset loses its agents at once
            self.lost = np.flatnonzero(world.state.online & (self.owner < 0))
            world.set_offline(self.lost)

    def rollout(
        self,
        policy: Any,
        steps: int,
        seed: np.random.SeedSequence,
        policy_seed: int | None,
        done: int,
        max_steps: int,
        on_step: Any = None,
    ) -> dict[str, Any]:
        """``env.rollout`` over the shards: the policy runs inside them; only counts come back each step.

        Args:
            policy: A baseline name, a trained model folder or a policy object (built or sent to every shard).
            steps: Steps to run (fewer when every agent ends first).
            seed: The episode's seed sequence.
            policy_seed: The seed given to ``policy.reset``.
            done: Steps of the episode taken before (0 after the reset).
            max_steps: The scenario's episode length (the last step truncates).
            on_step: ``on_step(taken, acted, live, info)`` after every step, with masks and info arrays over
                every slot (the shards then send the acting agents' rows, positions into the mirror); True stops.

        Returns:
            ``steps``, ``agent_steps``, ``events`` (counts), ``returns`` / ``final_pos`` / ``sums`` over every
            slot, and ``live`` (the slots still live).
        """
        from agentsim_env.env.rollout import EVENT_KEYS

        self.reset(seed, gather=False)
        n = len(self.shards)
        self._call("begin", {k: (policy, policy_seed) for k in range(n)})
        if on_step is not None:
            on_step(0, None, None, None)
        live = int((self.owner >= 0).sum())
        events = np.zeros(len(EVENT_KEYS), dtype=np.int64)
        taken = agent_steps = 0
        self.profile = {"wall_s": 0.0, "compute_s": np.zeros(n), "wait_s": np.zeros(n), "steps": []}
        tr = self._traffic = Traffic()
        self.backend.exchange_bytes()  # the reset's (and unread steps') are not the rollout's
        self._unread = 0
        t_start = time.perf_counter()
        while taken < steps and live:
            self.lost = _NONE
            control: Packed = {
                "ended": self._ended,
                "objects": self._objects,
                "owner": self.strips.owner,
                "taken": taken,
                "over": done + taken + 1 >= max_steps,
                "gather": on_step is not None,
            }
            self._objects = []
            t_step = time.perf_counter()
            replies = self._call("act", dict.fromkeys(range(n), (control,)))
            wall_step = time.perf_counter() - t_step
            tr.actions += nbytes(control)
            agent_steps += live
            taken += 1
            ended = [r["ended"] for r in replies.values()]
            self._ended = np.union1d(np.concatenate(ended) if ended else _NONE, self.lost)
            self.owner[self._ended] = -1
            call, wait = np.zeros(n), np.zeros(n)
            for k, r in replies.items():
                call[k], wait[k] = r["beat"]["compute_s"], r["beat"]["wait_s"]
                events += np.asarray(r["events"], dtype=np.int64)
                tr.replies += nbytes(r)
                self.owner[r["arrived"]] = k
            self.profile["compute_s"] += call
            self.profile["wait_s"] += wait
            self.profile["steps"].append((wall_step, call, wait))
            events[EVENT_KEYS.index("offline")] += self.lost.size
            live = sum(int(r["live"]) for r in replies.values())
            self.world.tick += 1
            self.world.step_count += 1
            if on_step is not None and on_step(taken, *self._step_view(replies)):
                break
        self.profile["wall_s"] = time.perf_counter() - t_start
        if taken:  # per step
            tr.add_exchange(self.backend.exchange_bytes())
            for f in tr.__slots__:  # type: ignore[attr-defined]
                setattr(tr, f, int(getattr(tr, f) / taken))
        got = self._call("finish", dict.fromkeys(range(n), ()))
        finished = list(got.values())
        returns, pos, sums, alive = rollout_rows(self.world, finished, self.scenario.info_keys())
        self.owner[:] = -1
        self.obs = np.zeros((self.world.state.n_slots, obs_dim(self.scenario)), np.float32)
        self._filled = None
        for k, r in got.items():  # where step() goes on from: the owners, the live agents' observations
            self.owner[r["own"]] = k
            self.obs[r["live"]] = r["obs"]
        self.world.state.pos[:] = pos
        return {
            "steps": taken,
            "agent_steps": agent_steps,
            "events": dict(zip(EVENT_KEYS, events.tolist())),
            "returns": returns,
            "final_pos": pos,
            "sums": sums,
            "live": alive,
        }

    def filled(self, out: np.ndarray) -> np.ndarray | None:
        """The array holding every slot's observation row of the last step when it was given ``out``: ``out``
        itself, or a copy of it when a shard was lost while it may still have been writing there; None when the
        last step was not given ``out``."""
        if self._filled is None or self._given is None or self._given() is not out:
            return None
        return self._filled()  # type: ignore[no-any-return]

    def obs_buffer(self) -> np.ndarray | None:
        """An array for the next step's observation rows that the shards beside the driver fill themselves
        (shared memory, ``obs_shm``): free, and not the previous step's; None when there is none (the caller
        then gives its own array, and the rows are copied there)."""
        prev = self._filled() if self._filled is not None else None
        return self.backend.obs_buffer(prev)  # type: ignore[no-any-return]

    def _complete(self, out: np.ndarray, replies: dict[int, Packed], acting: np.ndarray) -> None:
        """The rows of ``out`` no shard wrote this step: an ended agent's last row (kept in ``obs``); an agent of
        a shard lost in this step keeps the row of the previous step (the previous ``out``, still referenced)."""
        fresh = np.zeros(out.shape[0], dtype=bool)
        for r in replies.values():
            fresh[r["slots"]] = True
        stale = np.flatnonzero(~fresh)
        if not stale.size:
            return
        assert self.obs is not None
        rows = self.obs[stale]
        prev = self._filled() if self._filled is not None else None
        if prev is not None and prev.shape == out.shape:  # (``out`` itself when the caller let it go)
            was = acting[stale]  # acting, yet no row: its shard was lost now
            rows[was] = prev[stale[was]]
        out[stale] = rows

    def _step_view(self, replies: dict[int, Packed]) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """A rollout step's masks and info arrays over every slot, positions into the mirror."""
        st = self.world.state
        s = st.n_slots
        acted, still = np.zeros(s, dtype=bool), np.zeros(s, dtype=bool)
        info: dict[str, np.ndarray] = {}
        for r in replies.values():
            sl = r["acted"]
            acted[sl], still[sl], st.pos[sl] = True, r["still"], r["pos"]
            st.online[r["ended"]] = False  # terminated (a truncated agent stays online, as in one process)
            for k, v in r["info"].items():
                if k not in info:
                    info[k] = np.zeros(s, dtype=v.dtype)
                info[k][sl] = v
        return acted, still, info

    def step(
        self, parts: dict[str, np.ndarray], acting: np.ndarray, out: np.ndarray | None = None
    ) -> tuple[StepResult, np.ndarray]:
        """One step over the shards: each runs it for its own agents; their rows come back.

        Args:
            parts: Validated action parts ``(S, size)`` of every slot.
            acting: ``(S,)`` the live slots.
            out: ``(S, obs_dim)`` float32: where the step's observation rows go, every slot's row (``filled``
                then says so); ``None``: into ``obs``.

        Returns:
            The step's result over every slot and the slots that terminated (those of an offline shard too).
        """
        world, st = self.world, self.world.state
        s = st.n_slots
        self.lost, self._copy = _NONE, None
        tr = self._traffic = Traffic()
        events_wanted = self.gather_events or bool(world.hooks)
        control: Packed = {
            "ended": self._ended,
            "objects": self._objects,
            "owner": self.strips.owner,
            "obs": True,
            "kinematics": self.kinematics,
            "events": events_wanted,
        }
        calls: dict[int, tuple[Any, ...]] = {}
        full = self.backend.full_index(out)  # an array the shards beside the driver fill at their slots' rows
        for k in range(len(self.shards)):
            slots = np.flatnonzero(acting & (self.owner == k))
            n = self.backend.write_actions(k, slots, parts) if self.shards[k].alive else None
            if n is None:  # the call carries them
                calls[k] = (slots, {p: v[slots] for p, v in parts.items()}, control)
                tr.actions += nbytes(calls[k][:2])
            else:  # written into the shard's region of the action segment: the call carries their count
                calls[k] = (None, None, {**control, "act_n": n, "obs_buf": full})
                tr.actions += slots.nbytes + n * sum(v[0].nbytes for v in parts.values())
        self._objects = []
        taken: set[int] = set()
        rewards = np.zeros(s)
        terminated = np.zeros(s, dtype=bool)
        info: dict[str, np.ndarray] = {}
        keys = self.scenario.info_keys()

        def take(k: int, r: Packed) -> None:  # a shard's rows, as its reply comes in (the slower ones still run)
            if "rows_n" in r:  # written into the shared segments: views of them
                self.backend.reply_rows(k, r)
            sl = r["slots"]
            rewards[sl] = r["rewards"]
            terminated[sl] = r["terminated"]
            for key in keys:
                v = r["info"][key]
                if key not in info:
                    info[key] = np.zeros(s, dtype=v.dtype)
                info[key][sl] = v
            # rows through shared memory (float32), counted as they crossed: into a region, or at their slots' rows
            shared = int(r.get("obs_n", 0)) + (len(sl) if "obs_at" in r else 0)
            tr.replies += nbytes(r) + 4 * shared * obs_dim(self.scenario)
            # on two threads: the shards meet at a barrier just before their observations, so they answer within
            # a few ms of each other and the other CPU is idle by then (measured: the second reply is in before
            # the first one's rows are copied)
            self._take({k: r}, obs="obs_at" not in r, out=out, threads=2)  # "obs_at": written there already
            taken.add(k)

        replies = self._call("step", calls, take)
        for k, r in replies.items():  # a backend that does not call back
            if k not in taken:
                take(k, r)
        for key in keys:
            info.setdefault(key, np.zeros(s))
        given = out
        if (
            out is not None
            and full >= 0
            and any(k not in replies and calls[k][2].get("obs_buf") == full for k in calls)
        ):
            # a shard lost in this step may still be writing into ``out`` until its process is gone: the step's
            # rows are taken from a copy, and that array is never handed out again
            self.backend.retire(full)
            out = self._copy = out.copy()  # held here until the next step: the front end hands it out
        if out is not None:
            self._complete(out, replies, acting)
        self._unread += 1
        lost = self.lost
        if lost.size:  # agents of a shard that went offline: they terminate now, with their last observation
            terminated[lost[acting[lost]]] = True
        col = [r for r in replies.values() if r["col.agent"].size]
        events = merge_collisions(col)
        ended = np.flatnonzero(terminated)
        if out is not None:  # an ended agent's row is its last one: kept for the steps it no longer acts in
            assert self.obs is not None
            self.obs[ended] = out[ended]
            self._filled, self._given = weakref.ref(out), weakref.ref(given)  # type: ignore[arg-type]
        world.set_offline(ended)
        self.owner[ended] = -1
        self._ended = np.union1d(ended, lost)
        world.tick += 1
        world.step_count += 1
        ev = StepEvents(events, _NONE)
        ev.lost = lost
        if events_wanted and world.comms is not None:
            ev.comms = merge_comms(list(replies.values()), int(world.tick) - 1)
        res = StepResult(rewards, terminated, info)
        world.last_events = ev
        if world.hooks:
            ev.scores = StepScores(acting, rewards, terminated, info)
            world.run_hooks(ev)
        return res, terminated
