"""What a reader takes from a store is checked first: the file is opened read-only, its schema and the values it
is about to use are checked, and a damaged store gives one :class:`StoreError` naming the store, the table and
the column (never a raw ``sqlite3`` error, a traceback from the drawing code or a wrong picture).

A store can be damaged after the recorder wrote it: a table dropped by hand, a value edited by another tool, a
copy from another version. Every reader (``read.open_store``, ``read.export``, ``replay``, ``web_replay``) opens
the file with :func:`open_read` and checks the rows it reads with :func:`check_values`; the run's config is
validated by the scenario's own config classes (:func:`stored_config`).

Read-only stores: a file this process may not write, or one in a folder it may not write, is opened with SQLite's
``mode=ro``; when that cannot open it because the folder cannot be written (SQLite needs to create ``NAME-shm``
next to a WAL store: read-only media), it is opened ``immutable=1``, which reads the main file alone. A store whose
write-ahead log ``NAME-wal`` holds committed rows but has no
``NAME-shm`` cannot be read that way (the rows in the log would be missed): it is refused, saying so.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import socket
import sqlite3
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agentsim_env.recorder.schema import _DDL, SCHEMA_VERSION, STATUSES, StoreError, _pid_alive, connect

POSITION_LIMIT = 1e7
"""Largest coordinate (m) a replay accepts in ``steps`` and ``sensors``: ten times the largest map a config
can make (1e6 m), and where a float32 position is already 1 m coarse."""
TIME_LIMIT = 253_402_214_400.0
"""Latest ``runs.started`` / ``runs.ended`` accepted (Unix seconds): 9999-12-31 00:00 UTC, a date in every time
zone."""

Rule = tuple[str, str]
"""A column rule: SQL that is true for a bad value (``{c}`` stands for the quoted column) and what is expected."""


def _q(name: str) -> str:
    """``name`` quoted as an SQL identifier (column names of a damaged store can be anything)."""
    return '"' + name.replace('"', '""') + '"'


# ------------------------------------------------------------------------------------------------ opening
def _read_only_folder(folder: Path) -> bool:
    """Whether nothing can be created in ``folder`` (permissions, or a read-only file system)."""
    try:
        if os.statvfs(folder).f_flag & os.ST_RDONLY:
            return True
    except (AttributeError, OSError):  # pragma: no cover - platforms without statvfs
        pass
    return not os.access(folder, os.W_OK)


def _connect_reader(p: Path, timeout: float) -> tuple[sqlite3.Connection, bool]:
    """A connection to ``p`` for reading, and whether it is ``immutable`` (read-only media, see the module).

    A store this process may write is opened as the writer opens it (``mode=rw``, made ``query_only`` by the
    caller), so that SQLite removes ``NAME-wal`` and ``NAME-shm`` when the last connection closes; a read-only
    connection would leave them behind.
    """
    uri = p.resolve().as_uri()  # percent-encodes '?', '#' and '%' in the name
    mode = "rw" if os.access(p, os.W_OK) and not _read_only_folder(p.parent) else "ro"
    try:
        con = sqlite3.connect(f"{uri}?mode={mode}", uri=True, timeout=timeout)
        con.execute("SELECT count(*) FROM sqlite_master").fetchone()  # opening is lazy: this opens it
        return con, False
    except sqlite3.OperationalError as exc:
        if "unable to open" not in str(exc) or not _read_only_folder(p.parent):
            raise StoreError(f"{p}: cannot open the store: {exc}") from None
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{p}: cannot open the store: {exc}") from None
    wal = p.with_name(p.name + "-wal")
    if wal.is_file() and wal.stat().st_size > 0:
        raise StoreError(
            f"{p}: the store is on read-only media and its write-ahead log {wal.name} holds rows that SQLite reads "
            f"only with {p.name}-shm beside it; copy {p.name} and {wal.name} to a writable folder and read the copy"
        )
    try:
        con = sqlite3.connect(f"{uri}?mode=ro&immutable=1", uri=True, timeout=timeout)
        con.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except sqlite3.DatabaseError as exc:
        raise StoreError(f"{p}: cannot open the store: {exc}") from None
    return con, True


def open_read(path: str | os.PathLike[str], *, timeout: float = 30.0) -> sqlite3.Connection:
    """Open the store at ``path`` for reading only, and check its schema version and its tables and columns.

    Runs left ``running`` by a process of this host that no longer exists are marked ``incomplete`` when the
    file can be written (the one write a reader makes, as the writer would on its next open); on read-only
    media they are read as they are.

    Args:
        path: The SQLite file written by the recorder.
        timeout: Seconds to wait for a writer's lock.

    Returns:
        A connection that cannot write (``query_only``; ``mode=ro`` where the file or its folder is read-only).

    Raises:
        StoreError: Missing file, not an SQLite file, not a store, another schema version, a table or column
            missing, or a store on read-only media that cannot be read whole.
    """
    p = Path(path)
    if not p.is_file():
        raise StoreError(f"{p}: no such store (an SQLite file written by the recorder)")
    con, immutable = _connect_reader(p, timeout)
    try:
        con.execute("PRAGMA query_only = ON")
        _check_version(con, p)
        check_schema(con, p)
        if not immutable and _stale_runs(con):
            try:  # the writer's own recovery; a file this process may not write is read as it is
                connect(p, create=False, timeout=timeout).close()
            except (ValueError, sqlite3.Error):
                pass
    except sqlite3.DatabaseError as exc:
        con.close()
        raise StoreError(f"{p}: cannot read the store: {exc}") from None
    except BaseException:
        con.close()
        raise
    return con


def _check_version(con: sqlite3.Connection, p: Path) -> None:
    """Refuse an SQLite file that is not a store, or a store of another schema version."""
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    other = sorted(tables - {"meta", "sqlite_sequence", "sqlite_stat1"})
    if "meta" not in tables and other:
        raise StoreError(
            f"{p}: not an agentsim store (an SQLite file with other tables: {', '.join(other[:5])}); "
            "record to a new file"
        )
    row = con.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone() if "meta" in tables else None
    if row is None or row[0] != str(SCHEMA_VERSION):
        found = "none" if row is None else row[0]
        raise StoreError(
            f"{p}: store schema version {found}, but this agentsim-env reads and writes version {SCHEMA_VERSION}; "
            "export it with the agentsim-env version that wrote it, or record to a new file"
        )


def _stale_runs(con: sqlite3.Connection) -> bool:
    """Whether a run is left ``running`` by a process of this host that no longer exists."""
    host = socket.gethostname()
    rows = con.execute(
        "SELECT pid FROM runs WHERE status = 'running' AND host = ? AND typeof(pid) = 'integer'", (host,)
    ).fetchall()
    return any(not _pid_alive(int(pid)) for (pid,) in rows)


@functools.lru_cache(maxsize=1)
def expected_columns() -> dict[str, dict[str, str]]:
    """Table -> column -> declared type of a store of this schema version (``info_*`` columns come on top)."""
    con = sqlite3.connect(":memory:")
    try:
        con.executescript(_DDL)
        names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY rowid")]
        return {t: {r[1]: str(r[2]).upper() for r in con.execute(f"PRAGMA table_info({_q(t)})")} for t in names}
    finally:
        con.close()


def check_schema(con: sqlite3.Connection, path: str | os.PathLike[str]) -> None:
    """Every table and column of the schema is there, with its declared type.

    Raises:
        StoreError: Naming the store and the first table or column missing (or of another type).
    """
    for table, cols in expected_columns().items():
        have = {r[1]: str(r[2]).upper() for r in con.execute(f"PRAGMA table_info({_q(table)})")}
        if not have:
            raise StoreError(
                f"{path}: table {table} is missing: the store is damaged (tables of schema version "
                f"{SCHEMA_VERSION}: {', '.join(expected_columns())})"
            )
        for col, decl in cols.items():
            if col not in have:
                raise StoreError(f"{path}: column {table}.{col} is missing: the store is damaged")
            if have[col] != decl:
                raise StoreError(
                    f"{path}: column {table}.{col} is declared {have[col] or 'without a type'}, "
                    f"but a store declares it {decl}: the store is damaged"
                )
        for col in have:
            if table == "steps" and col.startswith("info_") and have[col] != "REAL":
                raise StoreError(f"{path}: column steps.{col} is declared {have[col]}, but info columns are REAL")


# ------------------------------------------------------------------------------------------------ values
def number_within(limit: float = sys.float_info.max) -> Rule:
    """The rule of a REAL column whose values must lie in ``[-limit, limit]`` (NULL allowed; by default: finite,
    as ``abs(v) > max float`` holds only for infinities)."""
    what = "a finite number" if limit == sys.float_info.max else f"a number within ±{limit:g}"
    return f"typeof({{c}}) NOT IN ('integer', 'real', 'null') OR abs({{c}}) > {limit!r}", what


def integer_within(low: int, high: int | None = None) -> Rule:
    """The rule of an INTEGER column whose values must lie in ``[low, high]`` (NULL allowed)."""
    hi = f" OR {{c}} > {int(high)}" if high is not None else ""
    what = f"an integer in {low}..{high}" if high is not None else f"an integer >= {low}"
    return f"typeof({{c}}) NOT IN ('integer', 'null') OR {{c}} < {int(low)}{hi}", what


def unix_time() -> Rule:
    """The rule of a REAL column holding a time in Unix seconds, 0..:data:`TIME_LIMIT` (NULL allowed)."""
    return (
        f"typeof({{c}}) NOT IN ('integer', 'real', 'null') OR {{c}} < 0 OR {{c}} > {TIME_LIMIT!r}",
        f"a time in Unix seconds, 0..{TIME_LIMIT:.0f} (up to the year 9999)",
    )


_BY_TYPE: dict[str, Rule] = {
    "INTEGER": ("typeof({c}) NOT IN ('integer', 'null')", "an integer"),
    "REAL": ("typeof({c}) NOT IN ('integer', 'real', 'null')", "a number"),
    "TEXT": ("typeof({c}) NOT IN ('text', 'null')", "text"),
}
_KEYS = ("run", "episode", "step", "world", "agent")


def check_values(
    con: sqlite3.Connection,
    path: str | os.PathLike[str],
    table: str,
    where: str = "1",
    params: Sequence[Any] = (),
    rules: Mapping[str, Rule] | None = None,
) -> None:
    """Check the rows of ``table`` that ``where`` selects: every column holds a value of its declared type, and
    the columns of ``rules`` follow their rule (one pass over the rows).

    Args:
        con: An open store (its schema checked).
        path: The store, for the message.
        table: One of the schema's tables (never user text: it is put into the SQL).
        where: An SQL condition with ``?`` placeholders (the caller's own text, never user input).
        params: The placeholders' values.
        rules: Column -> :data:`Rule` replacing the declared type's rule (e.g. :func:`number_within`).

    Raises:
        StoreError: Naming the store, ``table.column``, the value, the row and what is expected.
    """
    cols = expected_columns()[table]
    if table == "steps":
        cols = {**cols, **{c: "REAL" for c in _info_columns(con)}}
    rules = rules or {}
    checks = {c: rules.get(c) or _BY_TYPE[decl] for c, decl in cols.items() if c in rules or decl in _BY_TYPE}
    bads = [f"({rule[0].format(c=_q(c))})" for c, rule in checks.items()]
    try:
        row = con.execute(
            f"SELECT rowid, {', '.join(bads)} FROM {_q(table)} WHERE ({where}) AND ({' OR '.join(bads)}) LIMIT 1",
            list(params),
        ).fetchone()
        if row is None:
            return
        col = next(c for c, bad in zip(checks, row[1:]) if bad)
        value, place = _show(con, table, col, row[0]), _where(con, table, row[0])
    except sqlite3.DatabaseError as exc:  # a damaged page, not a damaged value
        raise StoreError(f"{path}: cannot read table {table}: {exc}") from None
    raise StoreError(
        f"{path}: {table}.{col} holds {value} in {place}, but it must be {checks[col][1]}: the store is damaged"
    )


def _info_columns(con: sqlite3.Connection) -> list[str]:
    return [r[1] for r in con.execute("PRAGMA table_info(steps)") if str(r[1]).startswith("info_")]


def _show(con: sqlite3.Connection, table: str, col: str, rowid: int) -> str:
    """The value in a message: its type and at most 40 characters of it."""
    kind, value = con.execute(
        f"SELECT typeof({_q(col)}), CASE WHEN typeof({_q(col)}) IN ('text', 'blob') THEN "
        f"substr(CAST({_q(col)} AS TEXT), 1, 41) ELSE {_q(col)} END FROM {_q(table)} "
        "WHERE rowid = ?",
        (rowid,),
    ).fetchone()
    if kind == "text":
        return f"text {value[:40]!r}{'...' if len(value) > 40 else ''}"
    if kind == "blob":
        return "a blob"
    if kind == "null":
        return "NULL"
    return f"{value!r}" if kind == "integer" else f"{value:g}"


def _where(con: sqlite3.Connection, table: str, rowid: int) -> str:
    """``"the row of run 1, episode 0, step 3, agent 2"`` (its key columns, as far as they are integers)."""
    keys = [k for k in _KEYS if k in expected_columns()[table]]
    if not keys:
        return f"row {rowid}"
    values = con.execute(
        f"SELECT {', '.join(_q(k) for k in keys)} FROM {_q(table)} WHERE rowid = ?", (rowid,)
    ).fetchone()
    named = [f"{k} {v}" for k, v in zip(keys, values) if isinstance(v, int)]
    return f"the row of {', '.join(named)}" if named else f"row {rowid}"


RUN_RULES: dict[str, Rule] = {
    "started": unix_time(),
    "ended": unix_time(),
    "n_worlds": integer_within(1),
    "n_agents": integer_within(1),
    "status": (f"{{c}} NOT IN ({', '.join(repr(s) for s in STATUSES)})", f"one of {', '.join(STATUSES)}"),
}
"""Rules of the ``runs`` columns every reader uses (times that can be printed, counts >= 1, a known status)."""


# ------------------------------------------------------------------------------------------------ config
def _known(cls: type, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` without the keys config class ``cls`` (and its sub-configs) does not declare."""
    fields = {f.name for f in dataclasses.fields(cls)}
    nested: dict[str, type] = getattr(cls, "nested", {})
    out = {}
    for key, value in values.items():
        if key in fields:
            sub = nested.get(key)
            out[key] = _known(sub, value) if sub is not None and isinstance(value, dict) else value
    return out


def stored_config(path: str | os.PathLike[str], run: int, scenario: str, text: Any) -> tuple[dict[str, Any], Any]:
    """The run's config (``runs.config``) validated by the scenario's config class.

    Keys this version of the scenario does not declare are left out (a store written by another version); a
    run of a scenario not registered here (or of a bare ``World``) is validated by the fields every scenario
    shares (``ScenarioConfig``).

    Returns:
        The config as a dict of the keys kept, and the validated config instance.

    Raises:
        StoreError: When the text is not a JSON object, or a value is one the config class refuses (naming the
            field and the allowed values).
    """
    from agentsim_env.core.validation import build_config
    from agentsim_env.scenarios.config import ScenarioConfig
    from agentsim_env.scenarios.registry import scenario_class

    where = f"{path}: runs.config of run {run}"
    try:
        raw = json.loads(text) if isinstance(text, str) else None
    except (ValueError, RecursionError) as exc:
        raise StoreError(f"{where} is not JSON ({exc}): the store is damaged") from None
    if not isinstance(raw, dict):
        raise StoreError(f"{where} is not a JSON object: the store is damaged")
    try:
        cls: type = scenario_class(scenario).config_cls
    except ValueError:  # not registered here: check what every scenario shares
        cls = ScenarioConfig
    config = _known(cls, raw)
    try:
        return config, build_config(cls, config)
    except (ValueError, TypeError, OverflowError, RecursionError) as exc:
        raise StoreError(f"{where}: {exc}") from None


__all__ = [
    "POSITION_LIMIT",
    "RUN_RULES",
    "TIME_LIMIT",
    "Rule",
    "check_schema",
    "check_values",
    "expected_columns",
    "integer_within",
    "number_within",
    "open_read",
    "stored_config",
    "unix_time",
]
