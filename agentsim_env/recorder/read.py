"""Reading a store back: pandas DataFrames in long format, and export of its tables to CSV or Parquet.

>>> from agentsim_env.recorder.read import open_store
>>> with open_store("run.db") as store:                          # doctest: +SKIP
...     store.runs()                                             # one row per run, with row counts
...     steps = store.steps(run=1)                               # indexed by (run, episode, step, world, agent)
...     steps.groupby(level="episode")["reward"].mean()

pandas is an optional dependency (the ``store`` extra: ``pip install "agentsim-env[store]"``); it is imported
by the methods that return DataFrames, so ``export`` to CSV, :meth:`Store.run_rows` and the ``agentsim runs`` /
``agentsim export`` commands work without it. Parquet export needs pyarrow (same extra).

Every frame has one row per table row. The typed methods set the key columns as a (sorted) index and convert
columns by their declared SQL type: ``INTEGER`` -> nullable ``Int64``, ``REAL`` -> ``float64``, ``TEXT`` ->
strings (pandas' default string type, missing values NA); the 0/1 flags ``online``, ``terminated`` and
``truncated`` -> nullable ``boolean`` (NA in the step-0 rows, which follow a reset and carry no reward).
:meth:`Store.table` returns a table as stored
(ordered by rowid, default index, pandas' own type inference), which is what :func:`export` writes.
The schema and example SQL queries are in ``docs/store.md``.
"""

from __future__ import annotations

import csv
import json
import operator
import os
import sqlite3
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, TypeAlias

from agentsim_env.outdirs import prepare_out
from agentsim_env.recorder.checks import RUN_RULES, check_values, open_read
from agentsim_env.recorder.export_files import remove_stale, temp_path
from agentsim_env.recorder.schema import StoreError

if TYPE_CHECKING:  # pragma: no cover - typing only
    import pandas as pd

INSTALL_HINT = 'pip install "agentsim-env[store]"'
"""How to install the optional dependencies of the reading API (pandas, pyarrow)."""

TABLES: tuple[str, ...] = (
    "meta",
    "runs",
    "episodes",
    "steps",
    "messages",
    "events",
    "sensors",
    "observations",
)
"""Every table of a store, in export order."""

FORMATS: tuple[str, ...] = ("csv", "parquet")
"""Export formats."""

INDEX: dict[str, tuple[str, ...]] = {
    "runs": ("run",),
    "episodes": ("run", "episode", "world"),
    "steps": ("run", "episode", "step", "world", "agent"),
    "messages": ("run", "episode", "step", "world"),
    "events": ("run", "episode", "step", "world", "agent"),
    "sensors": ("run", "episode", "world", "sensor"),
    "observations": ("run", "episode", "step", "world", "agent"),
}
"""Index columns of each typed frame (``world`` is part of every key: batched runs hold several worlds)."""

_ORDER: dict[str, str] = {
    "runs": "run",
    "episodes": "run, episode, world",
    "steps": "run, episode, step, world, agent",
    "messages": "run, episode, step, world, rowid",  # recording order within a step: sent, delivered, ...
    # a step's events are recorded by stage (collisions, timeouts, groups...), not by agent: follow the index,
    # each agent's own events in recording order
    "events": "run, episode, step, world, agent, rowid",
    "sensors": "run, episode, world, sensor",
    "observations": "run, episode, step, world, agent",
}
_FLAGS = ("online", "terminated", "truncated")
_COUNTS = (
    ("episodes", "episodes"),
    ("step_rows", "steps"),
    ("messages", "messages"),
    ("events", "events"),
    ("sensors", "sensors"),
)
_BATCH = 65536

IdFilter: TypeAlias = "int | Sequence[int] | None"
"""A filter on an id column: one id, several, or ``None`` (all)."""


def _pandas() -> Any:
    """The pandas module, or an ImportError naming the extra that installs it."""
    try:
        import pandas
    except ImportError:
        raise ImportError(
            f"reading a store as DataFrames needs pandas, which is not installed: {INSTALL_HINT}"
        ) from None
    return pandas


def _pyarrow() -> tuple[Any, Any]:
    """The pyarrow and pyarrow.parquet modules, or an ImportError naming the extra that installs them."""
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise ImportError(f"Parquet export needs pyarrow, which is not installed: {INSTALL_HINT}") from None
    return pyarrow, pyarrow.parquet


def _ids(name: str, value: IdFilter) -> list[int] | None:
    """Validate an id filter: None, an integer >= 0 or a sequence (or 1-D array) of them."""
    if value is None:
        return None
    bad = ValueError(f"{name} must be an integer >= 0, a list of them or None, got {value!r}")
    if isinstance(value, bool):
        raise bad
    try:
        items: list[Any] = [operator.index(value)]  # type: ignore[arg-type]
    except TypeError:
        if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
            raise bad from None
        items = list(value)
    out = []
    for v in items:
        try:
            i = operator.index(v)
        except TypeError:
            raise bad from None
        if isinstance(v, bool) or i < 0:
            raise bad
        out.append(i)
    return out


def _check_tables(tables: Iterable[str] | None) -> list[str]:
    """The tables to export (all by default), each one of :data:`TABLES`."""
    if tables is None:
        return list(TABLES)
    if isinstance(tables, str):
        tables = [tables]
    chosen = list(dict.fromkeys(tables))
    bad = [t for t in chosen if t not in TABLES]
    if bad or not chosen:
        raise ValueError(f"tables must be among {', '.join(TABLES)}; got {', '.join(map(repr, bad)) or 'none'}")
    return chosen


def _check_table(name: str) -> str:
    """``name`` when it is one of :data:`TABLES` (the only names ever put into SQL text here)."""
    if name not in TABLES:
        raise ValueError(f"table must be one of {', '.join(TABLES)}, got {name!r}")
    return name


class Store:
    """A store opened for reading (use :func:`open_store`); a context manager that closes it.

    The file is opened read-only (``mode=ro``; ``immutable=1`` on read-only media), and its schema is checked:
    see ``agentsim_env.recorder.checks.open_read``.

    Args:
        path: The SQLite file written by the recorder.

    Raises:
        StoreError: Missing file, not an SQLite store, a store of another schema version, or a damaged store (a
            table or column missing).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._con: sqlite3.Connection | None = open_read(self.path)

    # ------------------------------------------------------------------ basics
    @property
    def con(self) -> sqlite3.Connection:
        """The open (read-only) SQLite connection, for queries of your own."""
        if self._con is None:
            raise StoreError(f"{self.path}: the store is closed")
        return self._con

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if self._con is not None:
            self._con.close()
            self._con = None

    def __enter__(self) -> Store:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Store({str(self.path)!r}{', closed' if self._con is None else ''})"

    def columns(self, table: str) -> dict[str, str]:
        """Column name -> declared SQL type (``INTEGER``, ``REAL``, ``TEXT``) of ``table``, in table order."""
        _check_table(table)
        return {row[1]: str(row[2]).upper() for row in self.con.execute(f"PRAGMA table_info({table})")}

    def info_keys(self) -> list[str]:
        """The scenario info keys recorded in ``steps`` (its ``info_<key>`` columns)."""
        return [c[5:] for c in self.columns("steps") if c.startswith("info_")]

    # ------------------------------------------------------------------ without pandas
    def run_rows(self) -> list[dict[str, Any]]:
        """One dict per run (plain Python values, no pandas): the ``runs`` columns, ``seconds`` (ended - started;
        None while running or when incomplete) and the row counts ``episodes``, ``step_rows``, ``messages``,
        ``events``, ``sensors``.

        Raises:
            StoreError: A ``runs`` value of the wrong type, a start or end time that is no date (Unix seconds up
                to the year 9999), a count < 1 or an unknown status.
        """
        check_values(self.con, self.path, "runs", rules=RUN_RULES)
        joins = "".join(
            f" LEFT JOIN (SELECT run, COUNT(*) AS n FROM {table} GROUP BY run) AS c{i} ON c{i}.run = r.run"
            for i, (_, table) in enumerate(_COUNTS)
        )
        counts = "".join(f", COALESCE(c{i}.n, 0) AS {name}" for i, (name, _) in enumerate(_COUNTS))
        cur = self.con.execute(
            f"SELECT r.*, r.ended - r.started AS seconds{counts} FROM runs AS r{joins} ORDER BY r.run"
        )
        names = [d[0] for d in cur.description]
        return [dict(zip(names, row)) for row in cur]

    def iter_rows(self, table: str) -> Iterator[tuple[Any, ...]]:
        """The rows of ``table`` as stored, in rowid order (first the column names, as a tuple)."""
        _check_table(table)
        cur = self.con.execute(f"SELECT * FROM {table} ORDER BY rowid")
        yield tuple(d[0] for d in cur.description)
        while batch := cur.fetchmany(_BATCH):
            yield from batch

    # ------------------------------------------------------------------ DataFrames
    def table(self, name: str) -> pd.DataFrame:
        """Table ``name`` as stored: every column, ordered by rowid, default index (what :func:`export` writes)."""
        pd = _pandas()
        _check_table(name)
        return pd.read_sql_query(f"SELECT * FROM {name} ORDER BY rowid", self.con)

    def runs(self) -> pd.DataFrame:
        """One row per run, indexed by ``run``: see :meth:`run_rows` for the columns."""
        pd = _pandas()
        types = {**self.columns("runs"), "seconds": "REAL", **{name: "INTEGER" for name, _ in _COUNTS}}
        frame = pd.DataFrame.from_records(self.run_rows(), columns=list(types))
        return _typed(frame, types).set_index("run")

    def episodes(self, run: IdFilter = None, episode: IdFilter = None, world: IdFilter = None) -> pd.DataFrame:
        """One row per (run, world, episode): its ``seed`` (text) and ``first_step``."""
        return self._frame("episodes", run, episode, world)

    def steps(self, run: IdFilter = None, episode: IdFilter = None, world: IdFilter = None) -> pd.DataFrame:
        """Agent states, one row per (run, episode, step, world, agent) that acted (and step 0 after a reset).

        Columns: ``x y z`` (m), ``vx vy vz`` (m/s), ``heading`` (rad), ``online``, ``grp``, ``reward``,
        ``terminated``, ``truncated`` and one ``info_<key>`` column per scenario info field.
        """
        return self._frame("steps", run, episode, world)

    def messages(self, run: IdFilter = None, episode: IdFilter = None, world: IdFilter = None) -> pd.DataFrame:
        """Bus events (``sent`` / ``delivered`` / ``dropped`` with ``reason``) and ``overlay`` deliveries."""
        return self._frame("messages", run, episode, world)

    def events(self, run: IdFilter = None, episode: IdFilter = None, world: IdFilter = None) -> pd.DataFrame:
        """``collision``, ``offline``, ``shard_offline`` (sharded), ``group``, ``release``, ``landing`` events."""
        return self._frame("events", run, episode, world)

    def sensors(self, run: IdFilter = None, episode: IdFilter = None, world: IdFilter = None) -> pd.DataFrame:
        """One row per released sensor: UAV, zone, release and landing coordinates (m), steps and times (s)."""
        return self._frame("sensors", run, episode, world)

    def observations(self, run: IdFilter = None, episode: IdFilter = None, world: IdFilter = None) -> pd.DataFrame:
        """Recorded flat observations; ``obs`` holds one float64 NumPy array per row."""
        import numpy as np

        frame = self._frame("observations", run, episode, world)
        frame["obs"] = [np.asarray(json.loads(s), dtype=np.float64) for s in frame["obs"]]
        return frame

    def _frame(self, table: str, run: IdFilter, episode: IdFilter, world: IdFilter) -> pd.DataFrame:
        pd = _pandas()
        where, params = [], []
        for name, value in (("run", run), ("episode", episode), ("world", world)):
            ids = _ids(name, value)
            if ids is not None:
                where.append(f"{name} IN ({', '.join('?' * len(ids))})" if ids else "0")
                params += ids
        sql = f"SELECT * FROM {table}" + (" WHERE " + " AND ".join(where) if where else "")
        frame = pd.read_sql_query(f"{sql} ORDER BY {_ORDER[table]}", self.con, params=params)
        return _typed(frame, self.columns(table)).set_index(list(INDEX[table]))

    # ------------------------------------------------------------------ export
    def export(
        self, out_dir: str | os.PathLike[str], fmt: str = "csv", tables: Iterable[str] | None = None
    ) -> list[Path]:
        """Write one file per table (``steps.csv``, ``steps.parquet``...) from one snapshot of the store (a run
        being recorded meanwhile does not make the files disagree); see :func:`export`."""
        if fmt not in FORMATS:
            raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
        chosen = _check_tables(tables)
        pa = _pyarrow() if fmt == "parquet" else None
        out = Path(out_dir)
        snapshot = not self.con.in_transaction  # one read transaction: the tables agree while a writer goes on
        if snapshot:
            self.con.execute("BEGIN")
        temps: dict[Path, Path] = {}
        try:
            for table in chosen:  # every table is checked before any file is written
                check_values(self.con, self.path, table)
            prepare_out(out, "export folder")
            remove_stale(out, [f"{t}.{f}" for t in TABLES for f in FORMATS])
            for table in chosen:
                path = out / f"{table}.{fmt}"
                temps[path] = tmp = temp_path(path)
                try:
                    if pa is None:
                        self._write_csv(table, tmp)
                    else:
                        self._write_parquet(table, tmp, *pa)
                except OSError as exc:
                    raise ValueError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
            for path, tmp in temps.items():  # all tables written: now they replace earlier exports
                try:
                    os.replace(tmp, path)
                except OSError as exc:
                    raise ValueError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
        finally:
            for tmp in temps.values():  # an error, Ctrl-C or SIGTERM (see the CLI) leaves no temporary file
                tmp.unlink(missing_ok=True)
            if snapshot:
                self.con.rollback()  # nothing was written: ends the read transaction
        return list(temps)

    def _write_csv(self, table: str, path: Path) -> None:
        """Header, then rows; NULL is an empty field, floats keep every digit (``repr``)."""
        with path.open("w", newline="", encoding="utf-8") as f:
            csv.writer(f).writerows(self.iter_rows(table))

    def _write_parquet(self, table: str, path: Path, pa: Any, pq: Any) -> None:
        """Typed by the declared column types (INTEGER: int64, REAL: float64, TEXT: string), in row groups."""
        types = {"INTEGER": pa.int64(), "REAL": pa.float64(), "TEXT": pa.string()}
        cols = self.columns(table)
        schema = pa.schema([(name, types.get(decl, pa.string())) for name, decl in cols.items()])
        rows = self.iter_rows(table)
        next(rows)
        with pq.ParquetWriter(str(path), schema) as writer:
            batch: list[tuple[Any, ...]] = []
            written = False
            for row in rows:
                batch.append(row)
                if len(batch) == _BATCH:
                    writer.write_table(_arrow_table(pa, schema, batch, table))
                    batch, written = [], True
            if batch or not written:  # an empty table still gets its schema
                writer.write_table(_arrow_table(pa, schema, batch, table))


def _arrow_table(pa: Any, schema: Any, rows: list[tuple[Any, ...]], table: str) -> Any:
    """An Arrow table of ``rows`` with ``schema``; a value of the wrong type is an error naming the column."""
    arrays = []
    for i, field in enumerate(schema):
        values = [r[i] for r in rows]
        try:
            arrays.append(pa.array(values, type=field.type))
        except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
            raise StoreError(
                f"{table}.{field.name}: a value does not fit the column type {field.type}: {exc}"
            ) from None
    return pa.Table.from_arrays(arrays, schema=schema)


def _typed(frame: pd.DataFrame, types: dict[str, str]) -> pd.DataFrame:
    """Convert columns by declared type: INTEGER -> Int64 (flags -> boolean), REAL -> float64."""
    for col, decl in types.items():
        if col not in frame.columns:
            continue
        if decl == "INTEGER":
            frame[col] = frame[col].astype("boolean" if col in _FLAGS else "Int64")
        elif decl == "REAL":
            frame[col] = frame[col].astype("float64")
    return frame


def open_store(path: str | os.PathLike[str]) -> Store:
    """Open the store at ``path`` for reading.

    Args:
        path: The SQLite file written by the recorder (``agentsim_env.recorder.record``).

    Returns:
        A :class:`Store` (close it, or use it in a ``with`` block).

    Raises:
        StoreError: Missing file, not an SQLite store, a store of another schema version, or a damaged store (a
            table or column missing); a ValueError.
    """
    return Store(path)


def export(
    path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    fmt: str = "csv",
    tables: Iterable[str] | None = None,
) -> list[Path]:
    """Export the tables of the store at ``path`` to ``out_dir``, one file per table (``steps.csv``...).

    A file holds every row and column of its table in rowid order (the order :meth:`Store.table` returns).
    CSV: a header line, NULL as an empty field, floats with every digit; no pandas needed. Parquet: typed by
    the declared column types (INTEGER: int64, REAL: float64, TEXT: string), needs pyarrow.

    Every value of every exported table is checked against its column's declared type before any file is
    written. Each file is written to a temporary name (``.steps.csv.tmp-<pid>-<host>``) and all are renamed once
    every table is written, so an error or Ctrl-C leaves no file of this export and the files of an earlier one
    as they were; the temporary files of exports killed outright (their process gone) are removed first.

    Args:
        path: The store.
        out_dir: The folder (created when missing).
        fmt: ``"csv"`` or ``"parquet"``.
        tables: Tables to export (default: all of :data:`TABLES`).

    Returns:
        The files written, in table order.

    Raises:
        ValueError: An unknown format or table, or a folder that cannot be created or written.
        StoreError: Missing file, not a store, another schema version, or a damaged store: a table or column
            missing, a value not of its column's type (a ValueError).
        ImportError: Parquet without pyarrow (naming the ``store`` extra).
    """
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    chosen = _check_tables(tables)
    if fmt == "parquet":
        _pyarrow()
    with open_store(path) as store:
        return store.export(out_dir, fmt, chosen)


__all__ = ["FORMATS", "INDEX", "INSTALL_HINT", "TABLES", "IdFilter", "Store", "export", "open_store"]
