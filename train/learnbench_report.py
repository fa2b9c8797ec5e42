"""The learning benchmark's files: ``runs.csv``, ``curves.csv``, ``baselines.csv``, a PNG per scenario and
``summary.md``; every file is written whole or not at all (a temporary file beside it, then ``os.replace``).

``runs.csv`` has one row per scenario x algorithm x seed (``RUN_FIELDS``; a row that did not run keeps its
status and empty numbers). ``curves.csv`` has one row per learning-curve point (``CURVE_FIELDS``): the mean
episode return per agent of the training (stochastic) policy. ``summary.md`` is the table: per scenario and
algorithm the mean ± std over training seeds of the evaluation return and of the scenario's success metric, each
scripted baseline's value beside, and the exact command.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from agentsim_env.train.checkpoints import write_atomic

if TYPE_CHECKING:
    from agentsim_env.train.config import TrainConfig

__all__ = [
    "BASELINE_FIELDS",
    "CURVE_FIELDS",
    "BenchResult",
    "RUN_FIELDS",
    "csv_text",
    "mean_std",
    "plot_scenario",
    "summary_markdown",
    "write_all",
    "write_text_atomic",
]

#: Columns of ``runs.csv``.
RUN_FIELDS = (
    "scenario",
    "algorithm",
    "seed",
    "status",
    "budget_agent_steps",
    "agent_steps",
    "wall_s",
    "cpu_s",
    "final_train_return",
    "eval_return",
    "eval_return_std",
    "success_metric",
    "success",
    "eval_seeds",
)
#: Columns of ``curves.csv``.
CURVE_FIELDS = ("scenario", "algorithm", "seed", "agent_steps", "mean_return")
#: Columns of ``baselines.csv``.
BASELINE_FIELDS = (
    "scenario",
    "policy",
    "status",
    "episodes",
    "mean_return",
    "std_return",
    "success_metric",
    "success",
)


@dataclass
class BenchResult:
    """Everything one benchmark produced.

    Attributes:
        runs: One row per scenario x algorithm x seed (see ``RUN_FIELDS``).
        curves: Learning-curve points: scenario, algorithm, seed, agent_steps, mean_return.
        baselines: Per scenario, the baselines' evaluation rows (``evaluate_policies``).
    """

    runs: list[dict[str, Any]] = field(default_factory=list)
    curves: list[dict[str, Any]] = field(default_factory=list)
    baselines: dict[str, list[dict[str, Any]]] = field(default_factory=dict)


def write_text_atomic(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` whole or not at all (UTF-8)."""
    return write_atomic(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


def csv_text(rows: Sequence[Mapping[str, Any]], fields: Sequence[str]) -> str:
    """``rows`` as CSV with the header ``fields`` (missing cells empty, extra keys refused).

    Raises:
        ValueError: A row with a key outside ``fields`` (named).
    """
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(fields), lineterminator="\n")
    w.writeheader()
    for row in rows:
        extra = sorted(set(row) - set(fields))
        if extra:
            raise ValueError(f"row field {extra[0]!r} is not a column; columns: {list(fields)}")
        w.writerow(row)
    return buf.getvalue()


def mean_std(values: Sequence[Any]) -> str:
    """``mean ± std`` (population std) of the finite numbers among ``values``, 3 significant decimals; ``-``
    when there are none."""
    nums = [float(v) for v in values if v != "" and v is not None and math.isfinite(float(v))]
    if not nums:
        return "-"
    return f"{np.mean(nums):.3f} ± {np.std(nums):.3f}"


def _cell(value: Any) -> str:
    return "-" if value == "" or value is None or not math.isfinite(float(value)) else f"{float(value):.3f}"


def summary_markdown(
    result: BenchResult,
    command: str,
    *,
    quick: bool = False,
) -> str:
    """The summary table (Markdown) of ``result``.

    Args:
        result: Rows, curves and baselines of a benchmark.
        command: The command that produced it (shown verbatim).
        quick: Label the table as the quick profile (tiny budgets: not a result).

    Returns:
        The Markdown text: a heading, notes, one table row per scenario x algorithm and per baseline.
    """
    lines = ["# Learning benchmark" + (" (quick profile: tiny budgets, not a result)" if quick else ""), ""]
    lines += [f"Command: `{command}`", ""]
    lines += [
        "Evaluation return: mean episode return per agent of the deterministic policy on the held-out seeds, "
        "averaged per training seed; the cells give mean ± std over training seeds. Success: the scenario's "
        "main metric (navigation: arrivals per agent; rendezvous: agents that met, per agent; relay: share of "
        "groups at their target; "
        "uav_release: weighted coverage). BenchMARL rows: the return is measured through the TorchRL env on the "
        "same seeds, and the success metric from the same episodes' infos. Baseline rows: scripted policies on "
        "the same seeds (std over episodes). Rows that did not run say why.",
        "",
        "| scenario | algorithm | seeds | budget (agent-steps) | eval return | success | CPU s / seed | status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    keys: list[tuple[str, str]] = []
    for r in result.runs:
        if (r["scenario"], r["algorithm"]) not in keys:
            keys.append((r["scenario"], r["algorithm"]))
    scenarios = list(dict.fromkeys([s for s, _ in keys] + list(result.baselines)))
    for scenario in scenarios:
        metric = ""
        for scen, algo in (k for k in keys if k[0] == scenario):
            rows = [r for r in result.runs if r["scenario"] == scen and r["algorithm"] == algo]
            statuses = sorted({r["status"] for r in rows})
            metric = rows[0]["success_metric"]
            lines.append(
                f"| {scen} | {algo} | {len(rows)} | {rows[0]['budget_agent_steps']:,} | "
                f"{mean_std([r['eval_return'] for r in rows])} | {mean_std([r['success'] for r in rows])} | "
                f"{mean_std([r['cpu_s'] for r in rows])} | {'; '.join(statuses)} |"
            )
        for b in result.baselines.get(scenario, []):
            metric = metric or str(b.get("success_metric", ""))
            ret = "-" if "mean_return" not in b else f"{float(b['mean_return']):.3f} ± {float(b['std_return']):.3f}"
            lines.append(
                f"| {scenario} | baseline `{b['policy']}` | - | - | {ret} | {_cell(b.get('success', ''))} | - | "
                f"{b.get('status', 'scripted')} |"
            )
    lines.append("")
    return "\n".join(lines)


def _spread(points: Sequence[tuple[Any, float, float]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(seed, x, y)`` points as per-seed curves interpolated on the x range they share: x, mean, min, max."""
    by_seed: dict[Any, list[tuple[float, float]]] = {}
    for seed, x, y in points:
        by_seed.setdefault(seed, []).append((x, y))
    lo = max(min(x for x, _ in pts) for pts in by_seed.values())
    hi = min(max(x for x, _ in pts) for pts in by_seed.values())
    grid = np.linspace(lo, hi, 60) if hi > lo else np.asarray([hi])
    ys = np.stack([np.interp(grid, *np.asarray(sorted(pts), dtype=float).T) for pts in by_seed.values()])
    return grid, ys.mean(0), ys.min(0), ys.max(0)


def plot_scenario(
    scenario: str,
    curves: Sequence[Mapping[str, Any]],
    baselines: Sequence[Mapping[str, Any]],
    path: Path,
    *,
    title: str = "",
    runs: Sequence[Mapping[str, Any]] = (),
    baselines_elsewhere: bool = False,
) -> Path:
    """Draw one scenario's learning curves (mean and min-max spread over seeds per algorithm) and each baseline's
    evaluation return as a horizontal line.

    When the baselines play another env than the trained policies (``baselines_elsewhere``: the config's
    ``eval.baseline_env``, e.g. ``uav_release``'s strategies fly the default mode while the policy learns the
    autopilot mode), their returns are on another scale: they are left off the curves, and a second panel compares
    the success metric instead (each algorithm's mean and spread over seeds from ``runs``, each baseline's value).

    Args:
        scenario: The scenario (the rows of ``curves`` for it are drawn).
        curves: Rows of ``curves.csv``.
        baselines: The scenario's baseline rows (``policy``, ``mean_return``, ``success``).
        path: PNG to write (atomically).
        title: Figure title (default: the scenario).
        runs: Rows of ``runs.csv`` (for the success panel).
        baselines_elsewhere: Whether the baselines played another env (see above).

    Returns:
        ``path``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if baselines_elsewhere:
        fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5), dpi=110, gridspec_kw={"width_ratios": [3, 2]})
        _success_panel(bx, scenario, runs, baselines)
    else:
        fig, ax = plt.subplots(figsize=(8, 4.5), dpi=110)
    algos = list(dict.fromkeys(r["algorithm"] for r in curves if r["scenario"] == scenario))
    for i, algo in enumerate(algos):
        pts = [
            (r["seed"], float(r["agent_steps"]), float(r["mean_return"]))
            for r in curves
            if r["scenario"] == scenario and r["algorithm"] == algo
        ]
        seeds = len({p[0] for p in pts})
        x, mean, lo, hi = _spread(pts)
        colour = f"C{i}"
        ax.plot(x, mean, color=colour, lw=1.8, marker="o" if len(x) == 1 else None, label=f"{algo} ({seeds} seeds)")
        ax.fill_between(x, lo, hi, color=colour, alpha=0.2)
    styles = ["--", ":", "-."]
    for j, b in enumerate(b for b in baselines if "mean_return" in b and not baselines_elsewhere):
        ax.axhline(
            float(b["mean_return"]),
            color=plt.cm.Dark2(j % 8),
            ls=styles[j % 3],
            lw=1.0,
            label=f"{b['policy']} (scripted): {float(b['mean_return']):.2f}",
        )
    ax.set_xlabel("agent-steps")
    ax.set_ylabel("mean episode return per agent")
    ax.set_title(title or scenario, fontsize=10)
    ax.grid(alpha=0.3)
    if baselines_elsewhere:
        ax.legend(fontsize=7, loc="lower right")
    else:
        ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    write_atomic(path, lambda tmp: fig.savefig(tmp, format="png"))
    plt.close(fig)
    return path


def _number(v: Any) -> float:
    """A CSV cell as a float (NaN when empty or not a number)."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _success_panel(
    ax: Any, scenario: str, runs: Sequence[Mapping[str, Any]], baselines: Sequence[Mapping[str, Any]]
) -> None:
    """Horizontal bars of the success metric: each algorithm (mean over seeds, min-max as an error bar), then each
    baseline, highest first within each kind."""
    labels, values, errs, colours = [], [], [], []
    algos = list(dict.fromkeys(r["algorithm"] for r in runs if r["scenario"] == scenario))
    for i, algo in enumerate(algos):
        vals = [_number(r["success"]) for r in runs if r["scenario"] == scenario and r["algorithm"] == algo]
        vals = [v for v in vals if math.isfinite(v)]
        if vals:
            m = sum(vals) / len(vals)
            labels.append(f"{algo} ({len(vals)} seeds)")
            values.append(m)
            errs.append((m - min(vals), max(vals) - m))
            colours.append(f"C{i}")
    rows = sorted(((b["policy"], _number(b.get("success", ""))) for b in baselines), key=lambda t: -t[1])
    for name, v in rows:  # a NaN sorts anywhere: it is skipped here
        if math.isfinite(v):
            labels.append(f"{name} (scripted)")
            values.append(v)
            errs.append((0.0, 0.0))
            colours.append("0.6")
    y = list(range(len(labels)))[::-1]
    n_alg = sum(1 for c in colours if c != "0.6")
    spread = list(zip(*errs[:n_alg])) if n_alg else None
    ax.barh(y[:n_alg], values[:n_alg], color=colours[:n_alg], xerr=spread, capsize=2)
    ax.barh(y[n_alg:], values[n_alg:], color="0.6")
    ax.set_yticks(y, labels, fontsize=7)
    metric = next((r.get("success_metric", "") for r in runs if r["scenario"] == scenario), "") or next(
        (b.get("success_metric", "") for b in baselines), ""
    )
    ax.set_xlabel(metric or "success")
    ax.set_title("success (the baselines play their own mode)", fontsize=9)
    ax.grid(alpha=0.3, axis="x")


def write_all(
    result: BenchResult,
    out: Path,
    configs: Mapping[str, TrainConfig],
    *,
    quick: bool = False,
    command: str = "",
) -> list[Path]:
    """Write every file of ``result`` into ``out``.

    Args:
        result: The benchmark's rows, curves and baselines.
        out: The output folder (created).
        configs: Each scenario's training config (budget and evaluation seeds for the plot titles).
        quick: Label the table and plots as the quick profile.
        command: The command line shown in ``summary.md``.

    Returns:
        The paths written.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    baseline_rows = [
        {
            "scenario": s,
            "policy": b["policy"],
            "status": b.get("status", "scripted"),
            "episodes": b["episodes"],
            "mean_return": b.get("mean_return", ""),
            "std_return": b.get("std_return", ""),
            "success_metric": b.get("success_metric", ""),
            "success": b.get("success", ""),
        }
        for s, rows in result.baselines.items()
        for b in rows
    ]
    paths = [
        write_text_atomic(out / "runs.csv", csv_text(result.runs, RUN_FIELDS)),
        write_text_atomic(out / "curves.csv", csv_text(result.curves, CURVE_FIELDS)),
        write_text_atomic(out / "baselines.csv", csv_text(baseline_rows, BASELINE_FIELDS)),
    ]
    for scenario, cfg in configs.items():
        label = " (quick profile: not a result)" if quick else ""
        title = f"{scenario}{label}: {cfg.timesteps:,} agent-steps per run, evaluation on {cfg.eval.seeds} seeds"
        paths.append(plot_scenario(scenario, result.curves, result.baselines.get(scenario, []), out / f"{scenario}.png",
                                   title=title, runs=result.runs,
                                   baselines_elsewhere=bool(cfg.eval.baseline_env)))  # fmt: skip
    paths.append(write_text_atomic(out / "summary.md", summary_markdown(result, command, quick=quick)))
    return paths
