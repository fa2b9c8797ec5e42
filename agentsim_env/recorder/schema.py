"""The store's SQLite schema, its version check and the recovery of runs left ``running`` by a dead process.

One file holds any number of runs. Tables (documented with example queries in ``docs/store.md``):

- ``meta(key, value)``: ``schema_version``.
- ``runs``: one row per recorded run: scenario, config (JSON), seed, worlds, agents per world, package versions
  (JSON), label, start and end time (Unix seconds), status (``running`` / ``complete`` / ``incomplete``), the
  writer's pid and host, and the last committed step.
- ``episodes``: one row per (run, world, episode): its seed and first step.
- ``steps``: long format, one row per (run, episode, step, world, agent) of every agent that acted in the step
  (and step 0 after each reset): position, velocity, heading, online, group, reward, terminated, truncated, and
  one ``info_<key>`` column per scenario info field (added when a scenario first records).
- ``messages``: bus events (``event`` = ``sent`` / ``delivered`` / ``dropped`` with ``reason``) and overlay
  deliveries (``event`` = ``overlay``): message id, kind, sender, target (receiver slot or group id), receiver,
  hops, created and event step; ``payload`` as JSON where the event carries one.
- ``events``: ``collision`` (agent, other agent or object id), ``offline`` (heartbeat timeout), ``group``
  (old -> new group), ``release`` and ``landing`` (sensor id).
- ``sensors``: one row per released object: UAV, zone, release and landing coordinates and times.
- ``observations`` (off by default): the flat observation of chosen agents, as JSON.

Agents are numbered within their world (``agent``: 0..N-1); a slot of a batched run is ``world * N + agent``.
"""

from __future__ import annotations

import os
import socket
import sqlite3
import time
from pathlib import Path

SCHEMA_VERSION = 1
"""Version of the layout below; a file of another version is refused (no silent migration)."""

_DDL = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    run INTEGER PRIMARY KEY, scenario TEXT NOT NULL, config TEXT NOT NULL, seed INTEGER,
    n_worlds INTEGER NOT NULL, n_agents INTEGER NOT NULL, versions TEXT NOT NULL, label TEXT,
    started REAL NOT NULL, ended REAL, status TEXT NOT NULL, pid INTEGER, host TEXT, last_step INTEGER
);
CREATE TABLE IF NOT EXISTS episodes (
    run INTEGER NOT NULL, world INTEGER NOT NULL, episode INTEGER NOT NULL, seed TEXT, first_step INTEGER,
    PRIMARY KEY (run, world, episode)
);
CREATE TABLE IF NOT EXISTS steps (
    run INTEGER NOT NULL, episode INTEGER NOT NULL, step INTEGER NOT NULL, world INTEGER NOT NULL,
    agent INTEGER NOT NULL, x REAL, y REAL, z REAL, vx REAL, vy REAL, vz REAL, heading REAL,
    online INTEGER, grp INTEGER, reward REAL, terminated INTEGER, truncated INTEGER
);
CREATE INDEX IF NOT EXISTS steps_key ON steps (run, episode, world, step);
CREATE TABLE IF NOT EXISTS messages (
    run INTEGER NOT NULL, episode INTEGER, world INTEGER, step INTEGER NOT NULL, event TEXT NOT NULL,
    msg INTEGER, kind INTEGER, sender INTEGER, target INTEGER, receiver INTEGER, hops INTEGER,
    created INTEGER, reason TEXT, payload TEXT
);
CREATE INDEX IF NOT EXISTS messages_key ON messages (run, step);
CREATE TABLE IF NOT EXISTS events (
    run INTEGER NOT NULL, episode INTEGER, world INTEGER, step INTEGER NOT NULL, event TEXT NOT NULL,
    agent INTEGER, other_agent INTEGER, object INTEGER, old INTEGER, new INTEGER
);
CREATE INDEX IF NOT EXISTS events_key ON events (run, step);
CREATE TABLE IF NOT EXISTS sensors (
    run INTEGER NOT NULL, episode INTEGER, world INTEGER, sensor INTEGER NOT NULL, uav INTEGER, zone INTEGER,
    release_step INTEGER, release_x REAL, release_y REAL, release_z REAL, release_t REAL,
    land_step INTEGER, land_x REAL, land_y REAL, land_t REAL
);
CREATE INDEX IF NOT EXISTS sensors_key ON sensors (run, world, sensor);
CREATE TABLE IF NOT EXISTS observations (
    run INTEGER NOT NULL, episode INTEGER, world INTEGER, step INTEGER NOT NULL, agent INTEGER NOT NULL,
    obs TEXT NOT NULL
);
"""

STATUSES = ("running", "complete", "incomplete")
"""Values of ``runs.status``."""


class StoreError(ValueError):
    """A store that cannot be opened or written: the message names the path and the reason."""


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` exists on this host."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def _wal(con: sqlite3.Connection, timeout: float) -> None:
    """Switch ``con``'s database to WAL journaling, retrying while another connection holds a lock.

    Switching a new file to WAL needs an exclusive lock, and SQLite answers "database is locked" at once, without
    its busy timeout, while another process reads or creates the same file: writers that start together would
    fail. A database already in WAL mode returns at once.
    """
    deadline = time.monotonic() + timeout
    while True:
        try:
            con.execute("PRAGMA journal_mode=WAL").fetchone()
            return
        except sqlite3.OperationalError as exc:
            if "locked" not in str(exc) or time.monotonic() >= deadline:
                raise
        time.sleep(0.005)


def connect(path: str | os.PathLike[str], *, create: bool = True, timeout: float = 30.0) -> sqlite3.Connection:
    """Open (and with ``create``, initialise) a store; check its schema version; recover dead runs.

    The connection uses WAL journaling and ``synchronous=NORMAL``: a crash loses at most the transaction in
    progress, and readers never block the writer. Runs left ``running`` by a process that no longer exists on
    this host are marked ``incomplete``.

    Args:
        path: The SQLite file.
        create: Create the file and the tables when missing (otherwise a missing file is an error).
        timeout: Seconds to wait for another writer's lock.

    Returns:
        The open connection (autocommit off; the caller commits).

    Raises:
        StoreError: Missing folder or file, unreadable or not an SQLite file, an SQLite file that is not a
            store, or another schema version. Nothing is written to a file that is refused.
    """
    p = Path(path)
    if not create and not p.is_file():
        raise StoreError(f"{p}: no such store (an SQLite file written by the recorder)")
    if create and not p.parent.is_dir():
        raise StoreError(f"{p}: the folder {str(p.parent)!r} does not exist")
    try:
        con = sqlite3.connect(str(p), timeout=timeout)
    except sqlite3.Error as exc:
        raise StoreError(f"{p}: cannot open the store: {exc}") from None
    version = "SELECT value FROM meta WHERE key = 'schema_version'"
    try:
        # nothing is written (not even the WAL switch in the header) before the file is known to be a new file
        # or a store of this version: a refused file is left exactly as it was
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        other = sorted(tables - {"meta", "sqlite_sequence", "sqlite_stat1"})
        if "meta" not in tables and other:
            con.close()
            raise StoreError(
                f"{p}: not an agentsim store (an SQLite file with other tables: {', '.join(other[:5])}); "
                "record to a new file"
            )
        row = con.execute(version).fetchone() if "meta" in tables else None
        if "meta" not in tables and create:
            _wal(con, timeout)
            # one transaction: a crash while creating leaves an empty file, never a half-made store
            con.executescript(
                f"BEGIN IMMEDIATE;\n{_DDL}\nINSERT OR IGNORE INTO meta VALUES ('schema_version', "
                f"'{SCHEMA_VERSION}');\nCOMMIT;"
            )
            row = con.execute(version).fetchone()
        if row is None or row[0] != str(SCHEMA_VERSION):
            con.close()
            found = "none" if row is None else row[0]
            raise StoreError(
                f"{p}: store schema version {found}, but this agentsim-env reads and writes version "
                f"{SCHEMA_VERSION}; export it with the agentsim-env version that wrote it, or record to a new file"
            )
        _wal(con, timeout)
        con.execute("PRAGMA synchronous=NORMAL")
    except sqlite3.DatabaseError as exc:
        con.close()
        raise StoreError(f"{p}: cannot open the store: {exc}") from None
    _recover(con)
    return con


def _recover(con: sqlite3.Connection) -> None:
    """Mark ``incomplete`` the runs left ``running`` by processes of this host that no longer exist."""
    host = socket.gethostname()
    stale = [
        run
        for run, pid, h in con.execute("SELECT run, pid, host FROM runs WHERE status = 'running'")
        if h == host and not _pid_alive(int(pid or 0))
    ]
    if stale:
        try:
            with con:
                con.executemany("UPDATE runs SET status = 'incomplete' WHERE run = ?", [(r,) for r in stale])
        except sqlite3.Error:  # a read-only or locked store is read as it is; the next writer recovers it
            pass


def info_columns(con: sqlite3.Connection) -> set[str]:
    """Names of the ``info_*`` columns the ``steps`` table has."""
    return {row[1] for row in con.execute("PRAGMA table_info(steps)") if row[1].startswith("info_")}


def add_info_columns(con: sqlite3.Connection, keys: list[str]) -> None:
    """Add an ``info_<key>`` REAL column to ``steps`` for every key it lacks."""
    have = info_columns(con)
    for key in keys:
        col = f"info_{key}"
        if not col.replace("_", "").isalnum():
            raise StoreError(f"info key {key!r} cannot be a column name (letters, digits and _ only)")
        if col not in have:
            try:
                con.execute(f"ALTER TABLE steps ADD COLUMN {col} REAL")
            except sqlite3.OperationalError as exc:  # another writer added it meanwhile
                if "duplicate column" not in str(exc):
                    raise
    con.commit()


__all__ = ["SCHEMA_VERSION", "STATUSES", "StoreError", "add_info_columns", "connect", "info_columns"]


def check_store_path(path: str | Path) -> None:
    """Fail early when ``path`` cannot be recorded to: a missing folder, a file that is not a store, or a store
    of another schema version (a missing file in an existing folder is fine: the first recording creates it).

    Raises:
        StoreError: Naming the path and the problem.
    """
    p = Path(path)
    if p.exists():
        connect(p, create=False).close()
    elif not p.parent.is_dir():
        raise StoreError(f"{p}: the folder {str(p.parent)!r} does not exist")
