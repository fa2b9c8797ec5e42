"""The store subcommands of ``agentsim``: ``export`` (tables to CSV or Parquet) and ``runs`` (a Markdown table).

Registered by ``agentsim_env.cli.build_parser`` through :func:`add_store_commands`. Neither command needs pandas
(``export --format parquet`` needs pyarrow). Bad input (missing file, not a store, another schema version, an
unknown format or table, an unwritable ``--out``) raises ``ValueError``, which ``agentsim`` prints as one
``agentsim: error: ...`` line with exit code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import threading
import time
from collections.abc import Iterator
from types import FrameType
from typing import Any

EXPORT_EPILOG = """\
One file per table (TABLE.csv or TABLE.parquet) holding every row and column of the table, in rowid order.
CSV needs nothing more; Parquet needs pyarrow (pip install "agentsim-env[store]"). The schema and example SQL
queries are in docs/store.md.

examples:
  agentsim export run.db --out outputs/run_csv
  agentsim export run.db --format parquet --out outputs/run_parquet --tables steps messages"""
#: ``agentsim_env.recorder.read.FORMATS`` and ``TABLES`` (repeated for the help texts, so that building the
#: parser does not import the recorder; tests/test_store_read.py checks they agree).
FORMATS = ("csv", "parquet")
TABLES = ("meta", "runs", "episodes", "steps", "messages", "events", "sensors", "observations")
RUNS_COLUMNS = (
    "run",
    "scenario",
    "status",
    "started",
    "seconds",
    "worlds x agents",
    "episodes",
    "steps rows",
    "messages",
    "events",
    "sensors",
    "label",
)


def add_store_commands(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register ``export`` and ``runs`` on the ``agentsim`` subparsers ``sub`` (imports nothing heavy)."""
    x = sub.add_parser(
        "export",
        help="export a recorded store's tables to CSV or Parquet",
        description="Export the tables of a store written by agentsim_env.recorder.record to CSV or Parquet.",
        epilog=EXPORT_EPILOG,
    )
    x.add_argument("store", metavar="RUN.db", help="the SQLite store")
    x.add_argument("--format", default="csv", metavar="FORMAT", help=f"one of: {', '.join(FORMATS)}")
    x.add_argument("--out", required=True, metavar="DIR", help="output folder (created when missing)")
    x.add_argument(
        "--tables",
        nargs="+",
        default=None,
        metavar="TABLE",
        help=f"tables to export (default: all): {' '.join(TABLES)}",
    )
    x.set_defaults(func=cmd_export)
    r = sub.add_parser(
        "runs",
        help="list the runs of a recorded store (Markdown table)",
        description="Print one Markdown table row per run of a store: scenario, status, start time, duration,\n"
        "size and row counts.",
    )
    r.add_argument("store", metavar="RUN.db", help="the SQLite store")
    r.set_defaults(func=cmd_runs)


@contextlib.contextmanager
def _sigterm_exits() -> Iterator[None]:
    """While inside, SIGTERM ends the process with ``SystemExit(128 + SIGTERM)`` (exit status 143, as a shell
    reports it) instead of killing it at once, so the export's cleanup (its temporary files) runs first."""
    if threading.current_thread() is not threading.main_thread():  # only the main thread may set handlers
        yield
        return

    def stop(signum: int, frame: FrameType | None) -> None:
        raise SystemExit(128 + signum)

    old = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def cmd_export(args: argparse.Namespace) -> int:
    """Export the store's tables; print the files written (SIGTERM stops it without leaving temporary files)."""
    from agentsim_env.recorder.read import export

    try:
        with _sigterm_exits():
            paths = export(args.store, args.out, args.format, args.tables)
    except ImportError as exc:  # pyarrow missing: one error line naming the extra
        raise ValueError(str(exc)) from None
    for p in paths:
        print(p)
    return 0


def _cell(value: Any) -> str:
    """A Markdown table cell: '-' for missing values, pipes and line breaks escaped."""
    if value is None or value == "":
        return "-"
    return str(value).replace("|", "\\|").replace("\r", " ").replace("\n", " ")


def runs_table(rows: list[dict[str, Any]]) -> str:
    """The Markdown table of :meth:`agentsim_env.recorder.read.Store.run_rows` rows."""
    lines = ["| " + " | ".join(RUNS_COLUMNS) + " |", "|" + "---|" * len(RUNS_COLUMNS)]
    for r in rows:
        started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(r["started"]))
        seconds = None if r["seconds"] is None else f"{r['seconds']:.1f}"
        cells = (
            r["run"],
            r["scenario"],
            r["status"],
            started,
            seconds,
            f"{r['n_worlds']} x {r['n_agents']}",
            r["episodes"],
            r["step_rows"],
            r["messages"],
            r["events"],
            r["sensors"],
            r["label"],
        )
        lines.append("| " + " | ".join(map(_cell, cells)) + " |")
    return "\n".join(lines)


def cmd_runs(args: argparse.Namespace) -> int:
    """Print the store's runs as a Markdown table."""
    from agentsim_env.recorder.read import open_store

    with open_store(args.store) as store:
        rows = store.run_rows()
    print(runs_table(rows))
    if not rows:
        print(f"\n{args.store}: no runs recorded")
    return 0


__all__ = ["FORMATS", "TABLES", "add_store_commands", "cmd_export", "cmd_runs", "runs_table"]
