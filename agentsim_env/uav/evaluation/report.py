"""Reports of a batch evaluation: ``sensors.csv``, ``runs.csv`` and a Markdown ranking (``summary.md``).

The composite score, the ranking and the statistics are those of ``scoring`` (re-exported here); this
module adds the CSV files, the Markdown tables and ``write_outputs``.

Files are written only after every run succeeded, each through a temporary file renamed into place, so a
failed or interrupted evaluation leaves no partial file that looks complete (files of an earlier evaluation in
the same folder are left as they were; ``summary.md`` lists the files of its own evaluation).

When the missions were recorded (``agentsim evaluate --record run.db``), ``write_outputs(..., store=con)`` reads
the flown missions' sensor rows back from the store's open connection (``store_rows``): ``sensors`` joined with ``runs``
gives
every released sensor with its UAV, zone, release point and time and landing point and time. The store does
not record a sensor's release velocity or target point, so ``vx_rel, vy_rel, x_target, y_target`` are joined
in from the evaluation by sensor id. The store holds no table for the evaluation's metrics either: the
``runs.csv`` rows are the evaluation's, checked against the store (``steps`` = the run's last recorded step,
``sensors_released`` / ``sensors_landed`` = its rows of ``sensors``). Any disagreement between the store and the
evaluation is an error, and nothing is written. The teleport reference is not flown: its rows are the
evaluation's. (The store is read with SQL through the connection the caller opened, e.g. with
``agentsim_env.recorder.read.open_store``, which checks its schema version: this package sits beside the
recorder and does not import it.)
"""

from __future__ import annotations

import csv
import io
import math
import os
import sqlite3
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.uav.evaluation.scoring import (
    SCORE_TERMS,
    StrategySummary,
    composite_score,
    mean_std,
    rank_strategies,
    run_rows,
)

__all__ = [
    "SCORE_TERMS",
    "SENSOR_COLUMNS",
    "TABLE_METRICS",
    "StrategySummary",
    "composite_score",
    "store_rows",
    "format_mean_std",
    "mean_std",
    "rank_strategies",
    "ranking_table",
    "run_rows",
    "summary_markdown",
    "write_csv",
    "write_outputs",
]

#: ``sensors.csv`` columns: the run's keys, then the per-sensor schema of domain reference 2.6.
SENSOR_COLUMNS: tuple[str, ...] = (
    "zones",
    "strategy",
    "seed",
    "sensor_id",
    "uav_id",
    "zone_id",
    "t_release",
    "x_rel",
    "y_rel",
    "z_rel",
    "vx_rel",
    "vy_rel",
    "x_target",
    "y_target",
    "x_land",
    "y_land",
    "t_land",
)

#: Columns of the ranking table: (runs.csv key, header, decimals, scale).
TABLE_METRICS: tuple[tuple[str, str, int, float], ...] = (
    ("score", "Score", 3, 1.0),
    ("coverage_weighted", "C_φ", 3, 1.0),
    ("lcc_fraction", "LCC", 3, 1.0),
    ("fnd_vs_oracle", "FND/FND_B8", 2, 1.0),
    ("w1_mean", "W1", 3, 1.0),
    ("containment", "Contain.", 3, 1.0),
    ("landing_error_mean", "Miss (m)", 1, 1.0),
    ("energy_j", "Energy (kJ)", 1, 1e-3),
    ("mission_time_s", "Time (s)", 0, 1.0),
)


# ------------------------------------------------------------------------------------------ numbers
def format_mean_std(values: Iterable[Any], digits: int = 3, scale: float = 1.0) -> str:
    """``"mean ± std"`` with ``digits`` decimals (``"n/a"`` without finite values).

    Args:
        values: Numbers over seeds.
        digits: Decimals.
        scale: Factor applied first (e.g. 1e-3 for J -> kJ).

    Returns:
        The formatted text, e.g. ``"0.812 ± 0.034"``.
    """
    m, s = mean_std(values)
    if not math.isfinite(m):
        return "n/a"
    return f"{m * scale:.{digits}f} ± {s * abs(scale):.{digits}f}"


# ------------------------------------------------------------------------------------------ ranking
def ranking_table(ranked: Sequence[StrategySummary]) -> str:
    """The Markdown ranking table (mean ± std over the runs of each strategy).

    Args:
        ranked: Output of ``rank_strategies``.

    Returns:
        Table text (header, separator, one line per strategy).
    """
    head = ["Rank", "Strategy", *(h for _, h, _, _ in TABLE_METRICS), "Landed / needed"]
    lines = [
        "| " + " | ".join(head) + " |",
        "|" + "|".join(["---:", ":---"] + ["---:"] * (len(head) - 2)) + "|",
    ]
    for i, s in enumerate(ranked, 1):
        cells = [str(i), f"`{s.strategy}`"]
        for key, _, digits, scale in TABLE_METRICS:
            vals = s.scores() if key == "score" else s.values(key)
            cells.append(format_mean_std(vals, digits, scale))
        landed, _ = mean_std(s.values("sensors_landed"))
        need, _ = mean_std(s.values("sensors_required"))
        cells.append(f"{landed:.1f} / {need:.0f}" if math.isfinite(landed) and math.isfinite(need) else "n/a")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------ files
def _cell(value: Any) -> str:
    """CSV text of one value: floats with 10 significant digits, NaN as ``nan``, None as empty."""
    if value is None:
        return ""
    if isinstance(value, (float, np.floating)):
        return "nan" if math.isnan(value) else format(float(value), ".10g")
    return str(value)


def _replace_into(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file renamed into place."""
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def write_csv(
    rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], columns: Sequence[str] | None = None
) -> Path:
    """Write rows as CSV (header line first; a key missing from a row gives an empty cell).

    Args:
        rows: Dicts.
        path: Destination (overwritten).
        columns: Column order; default: every key in first-seen order.

    Returns:
        The path written.
    """
    if columns is None:
        columns = list(dict.fromkeys(k for r in rows for k in r))
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])
    p = Path(path)
    _replace_into(p, buf.getvalue())
    return p


def summary_markdown(grid: Any, files: Sequence[str] = ()) -> str:
    """The ``summary.md`` text: settings, score definition, one ranking per zone file (and pooled).

    Args:
        grid: A ``runner.GridResult``.
        files: Names of the files written with it (listed at the end).

    Returns:
        Markdown text.
    """
    rows = run_rows(grid.runs)
    over = ", ".join(f"`{k}={v}`" for k, v in grid.overrides.items()) or "none"
    out = [
        "# UAV sensor release: strategy ranking",
        "",
        f"- Zone files: {', '.join(f'`{s.label}` ({s.path.name})' for s in grid.sources)}",
        f"- Strategies: {len(grid.strategies)} flown, plus the `B8_teleport` reference (oracle layout placed "
        "exactly, no flight)",
        f"- Seeds: {', '.join(map(str, grid.seeds))}",
        f"- Scenario overrides: {over}",
        "",
        "Score (per run, then mean ± sample std over seeds): the share of the sensors that landed times the "
        "weighted mean of min(C_φ/C_φ,B8, 1) (weight 2), min(LCC/LCC_B8, 1), min(FND/FND_B8, 1), "
        "1 − W1 and containment (weight 1 each), minus the fraction of the fleet's battery used. "
        "B8 values are those of the teleport reference, which scores about 1.",
        "",
    ]
    for src in grid.sources:
        z = src.zones
        head = f"## Zone file `{src.label}` ({len(z.zones)} zone(s), {z.n_sensors} sensors, "
        head += f"{z.map_size[0]:g} × {z.map_size[1]:g} m)"
        out += [head, "", ranking_table(rank_strategies(rows, src.label)), ""]
    if len(grid.sources) > 1:
        out += ["## All zone files pooled", "", ranking_table(rank_strategies(rows)), ""]
    out += [
        "Columns: C_φ weighted coverage; LCC largest connected component fraction; FND/FND_B8 "
        "first-node-dies lifetime over the reference's; W1 radial Wasserstein-1 distance to the target "
        "profile (/ R); Contain. fraction landed inside their zone; Miss mean landing error; Energy UAV "
        "propulsion energy of the fleet; "
        "Time mission time.",
        "",
    ]
    if files:
        out += ["Files: " + ", ".join(f"`{f}`" for f in files), ""]
    return "\n".join(out)


#: ``sensors.csv`` column <- ``sensors`` table column, for the values read back from a store.
_FROM_STORE: dict[str, str] = {
    "sensor_id": "sensor",
    "uav_id": "uav",
    "zone_id": "zone",
    "t_release": "release_t",
    "x_rel": "release_x",
    "y_rel": "release_y",
    "z_rel": "release_z",
    "x_land": "land_x",
    "y_land": "land_y",
    "t_land": "land_t",
}


def _same(a: Any, b: Any) -> bool:
    """Equal values, NaN and None (a missing number) counting as equal."""
    fa = math.nan if a is None else float(a)
    fb = math.nan if b is None else float(b)
    return fa == fb or (math.isnan(fa) and math.isnan(fb))


def store_rows(grid: Any, con: sqlite3.Connection) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """``sensors.csv`` and ``runs.csv`` rows of ``grid`` with the recorded values read from a store.

    See the module docstring for which values come from the store. Rows are in the order of ``grid.runs``.

    Args:
        grid: A ``runner.GridResult`` whose flown runs were recorded (``RunResult.store_run``).
        con: An open connection to the store they were recorded to.

    Returns:
        ``(sensor rows, run rows)``.

    Raises:
        ValueError: A flown run that is not in the store, not complete, labelled otherwise, or whose recorded
            sensors or counts differ from the evaluation's.
    """
    from agentsim_env.uav.evaluation.runner import TELEPORT, mission_label

    store = con.execute("PRAGMA database_list").fetchone()[2] or "the store"
    cols = ", ".join(f"s.{c}" for c in _FROM_STORE.values())
    sensors: list[dict[str, Any]] = []
    rows = run_rows(grid.runs)
    for run, row in zip(grid.runs, rows):
        if run.strategy == TELEPORT:
            sensors += run.sensors
            continue
        label = mission_label(run.zones, run.strategy, run.seed)
        rec = None
        if run.store_run is not None:
            sql = "SELECT label, status, last_step FROM runs WHERE run = ?"
            rec = con.execute(sql, (run.store_run,)).fetchone()
        if rec is None or rec[0] != label or rec[1] != "complete":
            got = "missing" if rec is None else f"run {run.store_run}: {rec[0]!r}, {rec[1]}"
            raise ValueError(f"{store}: the mission {label} is not recorded complete in the store ({got})")
        head = {"zones": run.zones, "strategy": run.strategy, "seed": run.seed}
        mine = {int(r["sensor_id"]): r for r in run.sensors}
        recorded = con.execute(
            f"SELECT {cols} FROM sensors AS s JOIN runs AS r ON r.run = s.run "
            "WHERE s.run = ? AND s.world = 0 AND s.episode = 0 ORDER BY s.sensor",
            (run.store_run,),
        ).fetchall()
        if sorted(mine) != [r[0] for r in recorded]:
            raise ValueError(
                f"{store}: run {run.store_run} ({label}) recorded sensors "
                f"{[r[0] for r in recorded]}, the evaluation {sorted(mine)}"
            )
        for values in recorded:
            # NULL (not landed) as NaN, as the evaluation writes it
            got_row = {k: math.nan if v is None else v for k, v in zip(_FROM_STORE, values)}
            ev = mine[int(got_row["sensor_id"])]
            bad = [k for k, v in got_row.items() if not _same(v, ev[k])]
            if bad:
                raise ValueError(
                    f"{store}: run {run.store_run} ({label}), sensor {got_row['sensor_id']}: "
                    f"the store and the evaluation disagree on {', '.join(bad)}"
                )
            extra = {k: ev[k] for k in SENSOR_COLUMNS if k not in got_row and k not in head}
            sensors.append({**head, **got_row, **extra})
        landed = sum(r[list(_FROM_STORE).index("x_land")] is not None for r in recorded)
        counts = {"steps": rec[2], "sensors_released": len(recorded), "sensors_landed": landed}
        for key, value in counts.items():
            if not _same(value, row[key]):
                raise ValueError(
                    f"{store}: run {run.store_run} ({label}): {key} is {value} in the store, "
                    f"{row[key]} in the evaluation"
                )
            row[key] = float(value)
    return sensors, rows


def write_outputs(
    grid: Any,
    out_dir: str | os.PathLike[str],
    plots: bool = True,
    store: sqlite3.Connection | None = None,
) -> tuple[list[Path], str]:
    """Write ``sensors.csv``, ``runs.csv``, ``summary.md`` and (optionally) the PNG plots.

    Args:
        grid: A ``runner.GridResult`` (all runs done).
        out_dir: Output folder (created).
        plots: Also draw the landing maps and metric bar charts.
        store: An open connection to the store the flown missions were recorded to: the CSV rows are read from
            it (``store_rows``).

    Returns:
        ``(paths written, the ranking Markdown)``.
    """
    if store is not None:
        sensors, rows = store_rows(grid, store)  # checked before anything is written
    else:
        sensors, rows = [s for run in grid.runs for s in run.sensors], run_rows(grid.runs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [
        write_csv(sensors, out / "sensors.csv", SENSOR_COLUMNS),
        write_csv(rows, out / "runs.csv"),
    ]
    if plots:
        from agentsim_env.uav.evaluation.plots import write_plots

        paths += write_plots(grid, out)
    text = summary_markdown(grid, [p.name for p in paths])
    summary = out / "summary.md"
    _replace_into(summary, text)
    paths.append(summary)
    return paths, text
