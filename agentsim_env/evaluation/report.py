"""Reports of a batch evaluation: ``sensors.csv``, ``runs.csv`` and a Markdown ranking (``summary.md``).

Composite score of one run (every term is in [0, 1]; NaN terms count as 0)::

    score = delivered * ( 2 min(C_phi / C_phi_B8, 1) + min(LCC / LCC_B8, 1) + min(FND / FND_B8, 1)
                          + (1 - W1) + containment ) / 6  -  E_UAV / (n_uavs * battery_j)

``delivered`` is the share of the zone file's sensors that landed (capped at 1): the quality of what was
placed counts in proportion to how much of the deployment was placed, since a handful of sensors can look
well connected and long-lived. ``C_phi`` is the zone-weighted, density-weighted coverage, the primary
objective (domain reference 2.3), hence its double weight: clustered drops have short hops and so a long
FND, which must not make up for covering little. ``LCC`` is the
largest-connected-component fraction, ``FND`` the first-node-dies lifetime in rounds, ``W1`` the mean radial
Wasserstein-1 distance between the landed sensors and the target profile (over the zone radius),
``containment`` the fraction of sensors inside their zone, and the last term the fraction of the fleet's
battery the mission used. ``_B8`` values are those of the teleport reference on the same zone file (domain
reference 5.4), capped at 1 so that beating the reference on one term cannot buy off another; the reference
itself scores about 1. Strategies are ranked by the mean score over seeds (ties: by name); tables show
mean ± sample standard deviation (ddof = 1; 0 for a single run).

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

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

#: Quality terms of the composite score: (runs.csv key, how it enters, weight).
SCORE_TERMS: tuple[tuple[str, str, float], ...] = (
    ("coverage_weighted_vs_oracle", "ratio", 2.0),
    ("lcc_fraction_vs_oracle", "ratio", 1.0),
    ("fnd_vs_oracle", "ratio", 1.0),
    ("w1_mean", "one_minus", 1.0),
    ("containment", "value", 1.0),
)
ENERGY_KEY = "energy_fraction"
DELIVERED_KEY = "delivered_fraction"

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
def _num(value: Any) -> float:
    """``value`` as a float; NaN for missing or non-numeric values."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def composite_score(row: Mapping[str, Any]) -> float:
    """The composite score of one run (see the module docstring).

    Args:
        row: A ``runs.csv`` row (needs the ``SCORE_TERMS`` keys, ``delivered_fraction`` and
            ``energy_fraction``; a missing key counts as 0).

    Returns:
        The score; about 1 for the teleport reference, lower is worse.
    """
    total = 0.0
    for key, how, weight in SCORE_TERMS:
        v = _num(row.get(key))
        if how == "ratio":
            v = min(v, 1.0)
        elif how == "one_minus":
            v = 1.0 - v
        total += weight * (float(np.clip(v, 0.0, 1.0)) if math.isfinite(v) else 0.0)
    energy = _num(row.get(ENERGY_KEY))
    delivered = _num(row.get(DELIVERED_KEY))
    delivered = float(np.clip(delivered, 0.0, 1.0)) if math.isfinite(delivered) else 0.0
    quality = total / sum(w for _, _, w in SCORE_TERMS)
    return delivered * quality - (energy if math.isfinite(energy) else 0.0)


def _row_score(row: Mapping[str, Any]) -> float:
    """The row's ``score`` when present, else its composite score."""
    return _num(row["score"]) if "score" in row else composite_score(row)


def mean_std(values: Iterable[Any]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof = 1) of the finite values.

    Args:
        values: Numbers (NaN and non-numbers are skipped).

    Returns:
        ``(mean, std)``; std is 0 for a single value, both NaN for none.
    """
    arr = np.array([_num(v) for v in values], dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    if arr.size == 0:
        return math.nan, math.nan
    return float(arr.mean()), float(arr.std(ddof=1)) if arr.size > 1 else 0.0


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
@dataclass(frozen=True)
class StrategySummary:
    """One strategy's runs on one zone file (or pooled over zone files).

    Attributes:
        strategy: Strategy name.
        rows: Its ``runs.csv`` rows.
        score_mean: Mean composite score.
        score_std: Sample standard deviation of the score.
    """

    strategy: str
    rows: tuple[Mapping[str, Any], ...]
    score_mean: float
    score_std: float

    def values(self, key: str) -> list[float]:
        """The values of ``key`` over the runs."""
        return [_num(r.get(key)) for r in self.rows]

    def scores(self) -> list[float]:
        """The composite score of each run (the row's ``score``, computed when missing)."""
        return [_row_score(r) for r in self.rows]


def rank_strategies(rows: Sequence[Mapping[str, Any]], zones: str | None = None) -> list[StrategySummary]:
    """Group runs by strategy and sort by mean composite score, best first (ties: by name).

    Args:
        rows: ``runs.csv`` rows (``score`` is computed when missing).
        zones: Keep only this zone file's rows; ``None`` pools every zone file.

    Returns:
        One summary per strategy.
    """
    groups: dict[str, list[Mapping[str, Any]]] = {}
    for r in rows:
        if zones is None or r.get("zones") == zones:
            groups.setdefault(str(r["strategy"]), []).append(r)
    out = []
    for name, rs in groups.items():
        m, s = mean_std([_row_score(r) for r in rs])
        out.append(StrategySummary(name, tuple(rs), m, s))
    return sorted(
        out, key=lambda x: (-(x.score_mean if math.isfinite(x.score_mean) else -math.inf), x.strategy)
    )


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


def run_rows(runs: Iterable[Any]) -> list[dict[str, Any]]:
    """``runs.csv`` rows of ``RunResult`` objects: zones, strategy, seed, score, then every metric."""
    out = []
    for run in runs:
        row = run.row()
        out.append({"zones": row.pop("zones"), "strategy": row.pop("strategy"), "seed": row.pop("seed"),
                    "score": composite_score(row), **row})  # fmt: skip
    return out


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
