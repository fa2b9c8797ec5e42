"""Reports of a batch evaluation: ``sensors.csv``, ``runs.csv`` and a Markdown ranking (``summary.md``).

The composite score, the ranking and the statistics are those of ``scoring`` (re-exported here); this
module adds the CSV files, the Markdown tables and ``write_outputs``.

Files are written only after every run succeeded, each through a temporary file renamed into place, so a
failed or interrupted evaluation leaves no partial file that looks complete (files of an earlier evaluation in
the same folder are left as they were; ``summary.md`` lists the files of its own evaluation).
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.evaluation.scoring import (
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
    "zones", "strategy", "seed",
    "sensor_id", "uav_id", "zone_id", "t_release", "x_rel", "y_rel", "z_rel", "vx_rel", "vy_rel",
    "x_target", "y_target", "x_land", "y_land", "t_land",
)  # fmt: skip

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


def write_outputs(grid: Any, out_dir: str | os.PathLike[str], plots: bool = True) -> tuple[list[Path], str]:
    """Write ``sensors.csv``, ``runs.csv``, ``summary.md`` and (optionally) the PNG plots.

    Args:
        grid: A ``runner.GridResult`` (all runs done).
        out_dir: Output folder (created).
        plots: Also draw the landing maps and metric bar charts.

    Returns:
        ``(paths written, the ranking Markdown)``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [
        write_csv([s for run in grid.runs for s in run.sensors], out / "sensors.csv", SENSOR_COLUMNS),
        write_csv(run_rows(grid.runs), out / "runs.csv"),
    ]
    if plots:
        from agentsim_env.evaluation.plots import write_plots

        paths += write_plots(grid, out)
    text = summary_markdown(grid, [p.name for p in paths])
    summary = out / "summary.md"
    _replace_into(summary, text)
    paths.append(summary)
    return paths, text
