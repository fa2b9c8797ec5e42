"""The recorder: a stage-10 step hook that writes each step's arrays to the SQLite store.

``Recorder`` knows nothing about the env front ends: ``begin`` registers a run, ``reset`` starts episodes (and
writes their step-0 state), the hook writes every step (rows from the step's arrays with multi-row ``INSERT``
statements, one transaction per ``commit_every`` steps) and ``finish`` closes the run. ``recorder.wrappers``
drives it from a ``ParallelEnv``, a ``BatchedEnv`` or a bare ``World``.

A write that fails (read-only file, full disk, a lock held too long) never reaches the simulation: the recorder
detaches, warns once naming the path and the reason, and the env keeps running. Committed steps stay in the file.
"""

from __future__ import annotations

import json
import os
import socket
import sqlite3
import sys
import time
import warnings
from collections.abc import Iterable, Sequence
from functools import lru_cache
from itertools import chain, repeat
from typing import Any

import numpy as np

from agentsim_env.comms.messages import GROUP
from agentsim_env.recorder.schema import StoreError, add_info_columns, connect
from agentsim_env.sim.world import StepEvents, World

_REASONS = {0: None, 1: "bandwidth", 2: "offline", 3: "range", 4: "loss"}
_CHUNK_ROWS = 256
"""Most rows per ``INSERT ... VALUES (...), (...), ...`` statement (a power of two: see ``_insert``)."""
_CHECKPOINT_PAGES = 10_000
"""WAL pages between automatic checkpoints of a recorder's connection (SQLite's default: 1,000)."""


@lru_cache(maxsize=512)
def _values_sql(head: str, ncols: int, rows: int, nconst: int = 0) -> str:
    """``head`` followed by ``rows`` groups of ``ncols`` SQL parameters ``?`` (after ``nconst`` leading constants)."""
    groups = ", ".join(["(" + ", ".join("?" * ncols) + ")"] * rows)
    if not nconst:
        return f"{head}VALUES {groups}"
    consts = ", ".join(f"?{i + 1}" for i in range(nconst))  # bound once per statement, not once per row
    return f"{head}SELECT {consts}, * FROM (VALUES {groups})"


def _insert(con: sqlite3.Connection, head: str, ncols: int, rows: Iterable[tuple[Any, ...]]) -> None:
    """Insert ``rows`` (tuples of ``ncols`` values) with multi-row ``INSERT`` statements (``_insert_flat``)."""
    _insert_flat(con, head, ncols, list(chain.from_iterable(rows)))


def _insert_flat(con: sqlite3.Connection, head: str, ncols: int, flat: list[Any], const: Sequence[Any] = ()) -> None:
    """Insert the rows of ``flat`` (row after row, ``ncols`` values each) with multi-row ``INSERT``s, in order.

    One statement per up to ``_CHUNK_ROWS`` rows costs about 2/3 of ``executemany`` (one statement run per row)
    at 1,000 rows. Chunks are powers of two (256, 128, ..., 1 rows), so a table has at most 9 statement texts,
    all kept in the connection's statement cache, whatever the number of rows.

    Args:
        con: The connection.
        head: ``"INSERT INTO table (columns) "``.
        ncols: Values per row.
        flat: The values.
        const: Values of the leading columns that every row shares (bound once per statement).
    """
    n = len(flat) // ncols
    try:  # SQLite >= 3.32 allows 32766 variables per statement; older builds 999
        limit = con.getlimit(sqlite3.SQLITE_LIMIT_VARIABLE_NUMBER)
    except AttributeError:  # Python < 3.11
        limit = 999
    k = _CHUNK_ROWS
    while k > 1 and k * ncols + len(const) > limit:
        k //= 2
    pos = 0
    lead = list(const)
    while pos < n:
        while k > n - pos:
            k //= 2
        con.execute(_values_sql(head, ncols, k, len(lead)), lead + flat[pos * ncols : (pos + k) * ncols])
        pos += k


def package_versions() -> dict[str, str]:
    """Versions of the packages a run depends on (stored with every run)."""
    import numba

    import agentsim_env

    return {
        "agentsim_env": agentsim_env.__version__,
        "numpy": np.__version__,
        "numba": numba.__version__,
        "python": sys.version.split()[0],
    }


def _config_json(config: Any) -> str:
    """A config (dataclass) as JSON; values JSON cannot hold become strings."""
    import dataclasses

    def enc(v: Any) -> Any:
        if dataclasses.is_dataclass(v) and not isinstance(v, type):
            return {f.name: enc(getattr(v, f.name)) for f in dataclasses.fields(v)}
        if isinstance(v, (list, tuple)):
            return [enc(x) for x in v]
        if isinstance(v, dict):
            return {str(k): enc(x) for k, x in v.items()}
        if isinstance(v, (bool, int, float, str)) or v is None:
            return v
        if isinstance(v, np.generic):
            return v.item()
        return str(v)

    return json.dumps(enc(config), sort_keys=True)


class Recorder:
    """Writes runs to one SQLite store.

    Args:
        path: The store file (created with its tables when missing; its folder must exist).
        commit_every: Steps per transaction (1: every step is durable once ``step`` returns).
        observations: Agent indices (within each world) whose flat observation is stored every step, or
            ``None`` (default: none; the ``observations`` table is large).
        label: Free text stored with the run.

    Raises:
        StoreError: When the store cannot be opened (missing folder, not a store, another schema version).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        commit_every: int = 1,
        observations: Sequence[int] | None = None,
        label: str | None = None,
    ) -> None:
        if isinstance(commit_every, bool) or not isinstance(commit_every, int) or commit_every < 1:
            raise ValueError(f"commit_every must be an integer >= 1, got {commit_every!r}")
        self.path = str(path)
        self.commit_every = commit_every
        self.observe_agents = None if observations is None else np.asarray(list(observations), dtype=np.int64)
        self.label = label
        self.con: sqlite3.Connection | None = connect(path)
        # checkpoint the WAL into the file every ~40 MB instead of SQLite's 4 MB: a step of 1,000 agents writes
        # ~30 pages, and the pages rewritten every step (the tables' last pages, ``runs``) are copied once per
        # checkpoint, so fewer checkpoints copy less (about a tenth of the hook's time at 1x1000); the WAL file
        # is cut back to 64 MB after a checkpoint and removed when the store is closed
        self.con.execute(f"PRAGMA wal_autocheckpoint = {_CHECKPOINT_PAGES}")
        self.con.execute("PRAGMA journal_size_limit = 67108864")
        self.run: int | None = None
        self.error: str | None = None
        self._world: World | None = None
        self._n = 1
        self._max_steps: int | None = None
        self._info_keys: tuple[str, ...] = ()
        self._episode = np.zeros(0, dtype=np.int64)
        self._pending = 0
        self._last_step = 0

    # ------------------------------------------------------------------ run lifecycle
    @property
    def active(self) -> bool:
        """Whether the recorder is attached and writing."""
        return self.con is not None and self.run is not None

    def begin(self, world: World, *, scenario: Any = None, seed: int | None = None) -> int:
        """Register a run of ``world`` (and its scenario, for names, infos and the time limit); attach the hook.

        Returns:
            The run id.
        """
        con = self._con()
        self._world = world
        self._n = world.n_agents
        self._episode = np.full(world.n_worlds, -1, dtype=np.int64)
        name, config, keys = "world", "{}", tuple[str, ...]()
        if scenario is not None:
            name, config, keys = scenario.name, _config_json(scenario.config), tuple(scenario.info_keys())
            self._max_steps = int(scenario.max_steps)
        self._info_keys = tuple(k for k in keys if k.replace("_", "").isalnum())
        try:
            add_info_columns(con, list(self._info_keys))
            cur = con.execute(
                "INSERT INTO runs (scenario, config, seed, n_worlds, n_agents, versions, label, started, status, "
                "pid, host, last_step) VALUES (?, ?, ?, ?, ?, ?, ?, ?, 'running', ?, ?, 0)",
                (
                    name,
                    config,
                    seed,
                    world.n_worlds,
                    world.n_agents,
                    json.dumps(package_versions()),
                    self.label,
                    time.time(),
                    os.getpid(),
                    socket.gethostname(),
                ),
            )
            con.commit()
        except sqlite3.Error as exc:
            con.close()  # nothing was recorded: the recorder is closed (record() raises before any step)
            self.con = None
            raise StoreError(f"{self.path}: cannot write to the store: {exc}") from None
        self.run = int(cur.lastrowid or 0)
        world.add_hook(self.hook)
        return self.run

    def finish(self, status: str = "complete") -> None:
        """Commit, mark the run ``status`` (``complete`` or ``incomplete``) and detach; the file stays valid."""
        self._detach()
        con, run = self.con, self.run
        if con is not None and run is not None:
            try:
                con.execute(
                    "UPDATE runs SET status = ?, ended = ?, last_step = ? WHERE run = ?",
                    (status, time.time(), self._last_step, run),
                )
                con.commit()
            except sqlite3.Error as exc:
                self._fail(exc)
        if self.con is not None:
            self.con.close()
        self.con = None
        self.run = None

    def _con(self) -> sqlite3.Connection:
        if self.con is None:
            raise StoreError(f"{self.path}: the recorder is closed" + (f" ({self.error})" if self.error else ""))
        return self.con

    def _detach(self) -> None:
        """Remove the hook from the world's hooks.

        The list is replaced, not changed in place: ``World.run_hooks`` may be iterating over it (a hook that
        fails detaches from inside it), and removing an item under a running ``for`` would skip the next hook.
        """
        world = self._world
        if world is not None and self.hook in world.hooks:
            world.hooks = [h for h in world.hooks if h != self.hook]

    def _fail(self, exc: BaseException) -> None:
        """Detach after a failed write: warn once, keep the env running.

        The transaction in progress is rolled back (the committed steps stay in the file) and the run is marked
        ``incomplete`` where the store still takes that write; where it does not (read-only, full), the run
        stays ``running`` until this process ends, and the next ``connect`` marks it ``incomplete``.
        """
        self.error = f"{type(exc).__name__}: {exc}"
        msg = f"agentsim recorder: writing {self.path} failed ({self.error}); recording stopped, the run goes on"
        warnings.warn(msg, RuntimeWarning, stacklevel=3)
        self._detach()
        con, run = self.con, self.run
        self.con = None
        self.run = None
        if con is None:
            return
        try:
            con.rollback()
            if run is not None:
                con.execute("UPDATE runs SET status = 'incomplete' WHERE run = ?", (run,))
                con.commit()
        except sqlite3.Error:
            pass
        try:
            con.close()
        except sqlite3.Error:
            pass

    # ------------------------------------------------------------------ writing
    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[Any] | None = None) -> None:
        """New episodes of ``worlds``: an ``episodes`` row each and the step-0 state of their agents."""
        if not self.active:
            return
        world = self._world
        assert world is not None
        ws = np.asarray(list(worlds), dtype=np.int64)
        self._episode[ws] += 1
        seeds = list(seeds) if seeds is not None else [None] * len(ws)
        try:
            con = self._con()
            con.executemany(
                "INSERT INTO episodes VALUES (?, ?, ?, ?, 0)",
                [(self.run, int(w), int(self._episode[w]), None if s is None else str(s)) for w, s in zip(ws, seeds)],
            )
            slots = (ws[:, None] * self._n + np.arange(self._n)).ravel()
            self._write_states(con, slots, np.zeros(slots.size, dtype=np.int64), None)
            self._commit(force=True)
        except (sqlite3.Error, OSError) as exc:
            self._fail(exc)

    def hook(self, world: World, events: StepEvents) -> None:
        """Stage 10: write the step (states, messages, events, sensors); never raises into the simulation."""
        if not self.active:
            return
        try:
            con = self._con()
            sc = events.scores
            acting = sc.acting if sc is not None else world.state.online
            slots = np.flatnonzero(acting)
            step = world.step_count[slots // self._n]
            self._write_states(con, slots, step, events)
            self._write_messages(con, world, events)
            self._write_events(con, world, events)
            self._write_sensors(con, world, events)
            self._last_step = int(world.step_count.max())
            self._pending += 1
            self._commit()
        except (sqlite3.Error, OSError) as exc:
            self._fail(exc)

    def observations(self, slots: np.ndarray, flat: np.ndarray) -> None:
        """Store the flat observations ``(k, obs_dim)`` of ``slots`` at their world's current step."""
        if not self.active or self.observe_agents is None:
            return
        world = self._world
        assert world is not None
        keep = np.isin(slots % self._n, self.observe_agents)
        slots, flat = slots[keep], flat[keep]
        if not slots.size:
            return
        w = slots // self._n
        try:
            self._con().executemany(
                "INSERT INTO observations VALUES (?, ?, ?, ?, ?, ?)",
                zip(
                    repeat(self.run),
                    self._episode[w].tolist(),
                    w.tolist(),
                    world.step_count[w].tolist(),
                    (slots % self._n).tolist(),
                    [json.dumps(r) for r in np.asarray(flat, float).tolist()],
                ),
            )
            if self._pending == 0:  # the step was just committed: its observations are durable with it
                self._con().commit()
        except sqlite3.Error as exc:
            self._fail(exc)

    def _commit(self, force: bool = False) -> None:
        if force or self._pending >= self.commit_every:
            con = self._con()
            con.execute("UPDATE runs SET last_step = ? WHERE run = ?", (self._last_step, self.run))
            con.commit()
            self._pending = 0

    def _write_states(self, con: sqlite3.Connection, slots: np.ndarray, step: np.ndarray, ev: Any) -> None:
        """``steps`` rows of ``slots`` (state now; rewards and flags from the step's scores when given)."""
        world = self._world
        assert world is not None
        if not slots.size:
            return
        st, n = world.state, self._n
        w = slots // n
        sc = None if ev is None else ev.scores
        keys = self._info_keys
        # one float64 block, raveled into one list: the fastest way from arrays to bound values. Integers are
        # exact in float64 and INTEGER columns store them as integers; NaN is stored as NULL (SQLite's rule).
        a = np.empty((slots.size, 13 + len(keys)))
        a[:, 0] = slots % n
        a[:, 1:4] = st.pos[slots]
        a[:, 4:7] = st.vel[slots]
        a[:, 7] = st.heading[slots]
        a[:, 8] = st.online[slots]
        a[:, 9] = st.group[slots]
        if sc is None:
            a[:, 10:] = np.nan  # step 0 (after a reset): no reward, flags or infos
        else:
            term = sc.terminated[slots]
            a[:, 10] = sc.rewards[slots]
            a[:, 11] = term
            a[:, 12] = ~term & (step >= self._max_steps) if self._max_steps is not None else 0.0
            for j, key in enumerate(keys):
                a[:, 13 + j] = np.asarray(sc.info[key])[slots] if key in sc.info else np.nan
        cols = "run, episode, step, world, agent, x, y, z, vx, vy, vz, heading, online, grp, reward, terminated"
        head = f"INSERT INTO steps ({cols}, truncated{''.join(', info_' + k for k in keys)}) "
        ep = self._episode[w]
        if world.n_worlds == 1:  # one world: run, episode, step and world are the same in every row
            _insert_flat(con, head, 13 + len(keys), a.ravel().tolist(), (self.run, int(ep[0]), int(step[0]), 0))
        else:
            lead = np.column_stack([np.full(slots.size, self.run if self.run is not None else 0), ep, step, w])
            _insert_flat(con, head, 17 + len(keys), np.hstack([lead, a]).ravel().tolist())

    def _where(self, slot: np.ndarray) -> tuple[list[int], list[int]]:
        """Episode and world of each slot (-1 slots: world 0)."""
        w = np.where(slot >= 0, slot // self._n, 0)
        return self._episode[w].tolist(), w.tolist()

    @staticmethod
    def _tick_shift(world: World, w: list[int]) -> np.ndarray:
        """Per row, what turns a global tick (message timestamps) into its world's step number.

        The step that ends with ``step_count[w] = s`` ran at tick ``world.tick - 1``, so tick ``t`` is step
        ``t + 1 + step_count[w] - world.tick`` of world ``w``'s episode (negative: before its latest reset).
        """
        return world.step_count[np.asarray(w, dtype=np.int64)] + 1 - world.tick

    def _write_messages(self, con: sqlite3.Connection, world: World, ev: StepEvents) -> None:
        c = ev.comms
        if c is None:
            return
        n = self._n
        rows: list[tuple[Any, ...]] = []
        if c.bus is not None:
            for name, log in (
                ("sent", c.bus.sent),
                ("delivered", c.bus.delivered),
                ("dropped", c.bus.dropped),
            ):
                if not len(log):
                    continue
                anchor = np.where(log.sender >= 0, log.sender, log.receiver)
                ep, w = self._where(anchor)
                shift = self._tick_shift(world, w)
                recv = np.where(log.receiver >= 0, log.receiver % n, -1)
                send = np.where(log.sender >= 0, log.sender % n, -1)
                # target: a group id for GROUP messages, else a receiver slot, stored as its agent index
                target = np.where((log.kind != GROUP) & (log.target >= 0), log.target % n, log.target)
                reasons = [_REASONS.get(r, str(r)) for r in log.reason.tolist()]
                rows += zip(
                    repeat(self.run),
                    ep,
                    w,
                    (log.step + shift).tolist(),
                    repeat(name),
                    log.msg.tolist(),
                    log.kind.tolist(),
                    send.tolist(),
                    target.tolist(),
                    recv.tolist(),
                    repeat(None),
                    (log.created + shift).tolist(),
                    reasons,
                    repeat(None),
                )
        o = c.overlay
        if o is not None and len(o):
            ep, w = self._where(o.receiver)
            shift = self._tick_shift(world, w)
            step = world.step_count[np.asarray(w, dtype=np.int64)].tolist()
            rows += zip(
                repeat(self.run),
                ep,
                w,
                step,
                repeat("overlay"),
                o.flood.tolist(),
                repeat(None),
                (o.origin % n).tolist(),
                repeat(None),
                (o.receiver % n).tolist(),
                o.hops.tolist(),
                (o.created + shift).tolist(),
                repeat(None),
                [json.dumps(p) for p in o.payload.tolist()],
            )
        if rows:
            _insert(con, "INSERT INTO messages ", 14, rows)

    def _write_events(self, con: sqlite3.Connection, world: World, ev: StepEvents) -> None:
        n = self._n
        rows: list[tuple[Any, ...]] = []
        col = ev.collisions
        if len(col):
            ep, w = self._where(col.agent)
            step = world.step_count[np.asarray(w, dtype=np.int64)].tolist()
            other = np.where(col.other_agent >= 0, col.other_agent % n, -1)
            obj = world.scene.index_in_world(col.obj)  # numbered within the world, as a single env numbers it
            rows += zip(
                repeat(self.run),
                ep,
                w,
                step,
                repeat("collision"),
                (col.agent % n).tolist(),
                other.tolist(),
                obj.tolist(),
                repeat(None),
                repeat(None),
            )
        if ev.timed_out.size:
            ep, w = self._where(ev.timed_out)
            step = world.step_count[np.asarray(w, dtype=np.int64)].tolist()
            rows += zip(
                repeat(self.run),
                ep,
                w,
                step,
                repeat("offline"),
                (ev.timed_out % n).tolist(),
                repeat(None),
                repeat(None),
                repeat(None),
                repeat(None),
            )
        if ev.lost.size:  # agents of a shard that stopped answering (distributed runs)
            ep, w = self._where(ev.lost)
            step = world.step_count[np.asarray(w, dtype=np.int64)].tolist()
            rows += zip(
                repeat(self.run),
                ep,
                w,
                step,
                repeat("shard_offline"),
                (ev.lost % n).tolist(),
                repeat(None),
                repeat(None),
                repeat(None),
                repeat(None),
            )
        g = ev.groups
        if g is not None and len(g):
            ep, w = self._where(g.slot)
            step = world.step_count[np.asarray(w, dtype=np.int64)].tolist()
            rows += zip(
                repeat(self.run),
                ep,
                w,
                step,
                repeat("group"),
                (g.slot % n).tolist(),
                repeat(None),
                repeat(None),
                g.old.tolist(),
                g.new.tolist(),
            )
        if rows:
            _insert(con, "INSERT INTO events ", 10, rows)

    def _write_sensors(self, con: sqlite3.Connection, world: World, ev: StepEvents) -> None:
        p = ev.payloads
        if p is None or world.payloads is None:
            return
        objs = world.payloads.objects
        n = self._n
        if p.released.size:
            i = objs.index_of(p.released)
            wid = objs.get("world")[i]
            owner = objs.get("owner")[i]
            rp = objs.get("release_pos")[i]
            ep = self._episode[wid].tolist()
            step = world.step_count[wid].tolist()
            con.executemany(
                "INSERT INTO sensors (run, episode, world, sensor, uav, zone, release_step, release_x, release_y, "
                "release_z, release_t) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                zip(
                    repeat(self.run),
                    ep,
                    wid.tolist(),
                    p.released.tolist(),
                    (owner % n).tolist(),
                    objs.get("zone")[i].tolist(),
                    step,
                    *rp.T.tolist(),
                    objs.get("release_t")[i].tolist(),
                ),
            )
            con.executemany(
                "INSERT INTO events VALUES (?, ?, ?, ?, 'release', ?, NULL, ?, NULL, NULL)",
                zip(repeat(self.run), ep, wid.tolist(), step, (owner % n).tolist(), p.released.tolist()),
            )
        if p.landed.size:
            i = objs.index_of(p.landed)
            wid = objs.get("world")[i]
            lxy = objs.get("land_xy")[i]
            ep = self._episode[wid].tolist()
            step = world.step_count[wid].tolist()
            con.executemany(
                "UPDATE sensors SET land_step = ?, land_x = ?, land_y = ?, land_t = ? "
                "WHERE run = ? AND world = ? AND episode = ? AND sensor = ?",
                zip(
                    step,
                    *lxy.T.tolist(),
                    objs.get("land_t")[i].tolist(),
                    repeat(self.run),
                    wid.tolist(),
                    ep,
                    p.landed.tolist(),
                ),
            )
            owner = objs.get("owner")[i]
            con.executemany(
                "INSERT INTO events VALUES (?, ?, ?, ?, 'landing', ?, NULL, ?, NULL, NULL)",
                zip(repeat(self.run), ep, wid.tolist(), step, (owner % n).tolist(), p.landed.tolist()),
            )


__all__ = ["Recorder", "package_versions"]
