"""PNG plots of a batch evaluation (matplotlib, 120 dpi; written to files, the backend is the caller's).

Per zone file:

- ``landing_<zones>_seed<s>.png``: one panel per strategy (the teleport reference first) for the first seed:
  the target areal density of each zone as a shaded background (expected sensors per 100 m²), the zone
  circles, the UAV base, the landed sensors as dots and, optionally, the release points.
- ``metrics_<zones>.png``: one horizontal bar chart per key metric, a bar per strategy (best score on top),
  error bars = sample standard deviation across seeds.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch

from agentsim_env.uav.evaluation.scoring import composite_score, mean_std, rank_strategies, run_rows
from agentsim_env.uav.zones import ZoneSet

__all__ = ["BAR_METRICS", "DPI", "density_raster", "plot_landing_maps", "plot_metric_bars", "write_plots"]

DPI = 120
REFERENCE = "B8_teleport"
#: Bar-chart panels: (runs.csv key, title, scale, "higher" / "lower" is better).
BAR_METRICS: tuple[tuple[str, str, float, str], ...] = (
    ("score", "Composite score", 1.0, "higher"),
    ("coverage_weighted", "Weighted coverage C_φ", 1.0, "higher"),
    ("lcc_fraction", "Largest component fraction", 1.0, "higher"),
    ("fnd_vs_oracle", "Lifetime FND / FND of B8", 1.0, "higher"),
    ("w1_mean", "Radial W1 to target profile", 1.0, "lower"),
    ("containment", "Containment (landed in zone)", 1.0, "higher"),
    ("landing_error_mean", "Mean landing error (m)", 1.0, "lower"),
    ("energy_j", "UAV energy, fleet (kJ)", 1e-3, "lower"),
    ("mission_time_s", "Mission time (s)", 1.0, "lower"),
)
_DOT = "#16325c"
_REL = "#2a9d8f"
_REF_BAR = "#9e9e9e"
_BAR = "#3b75af"


def density_raster(zones: ZoneSet, pixels: int = 240) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Target areal density over the map: ``sum_k N_k rho_k(|q - c_k|)`` inside each disc, x 100 m².

    Args:
        zones: The zones.
        pixels: Raster cells along the longer map side.

    Returns:
        ``(raster (ny, nx), extent (x0, x1, y0, y1))``; NaN outside every zone.
    """
    w, h = zones.map_size
    cell = max(w, h) / pixels
    xs = np.arange(cell / 2, w, cell)
    ys = np.arange(cell / 2, h, cell)
    gx, gy = np.meshgrid(xs, ys)
    total = np.zeros(gx.shape)
    inside = np.zeros(gx.shape, dtype=bool)
    for z in zones.zones:
        r = np.hypot(gx - z.centre[0], gy - z.centre[1])
        m = r <= z.radius
        # half a cell keeps a power profile's r^-alpha peak finite at the centre
        total[m] += z.n_sensors * z.radial_profile().density(np.maximum(r[m], cell / 2)) * 100.0
        inside |= m
    total[~inside] = np.nan
    return total, (0.0, w, 0.0, h)


def _grid_shape(n: int) -> tuple[int, int]:
    cols = min(4, n)
    return math.ceil(n / cols), cols


def plot_landing_maps(
    sensors: Sequence[Mapping[str, Any]],
    zones: ZoneSet,
    strategies: Sequence[str],
    path: str | os.PathLike[str],
    title: str,
    scores: Mapping[str, float] | None = None,
    show_release: bool = True,
) -> Path:
    """One map panel per strategy: density background, zone circles, landed sensors, release points.

    Args:
        sensors: ``sensors.csv`` rows of one zone file and one seed.
        zones: That zone file's zones.
        strategies: Panel order.
        path: PNG destination.
        title: Figure title.
        scores: Optional score per strategy, shown in the panel titles.
        show_release: Draw the release points too.

    Returns:
        The path written.
    """
    raster, extent = density_raster(zones)
    finite = raster[np.isfinite(raster)]
    vmax = float(np.percentile(finite, 99)) if finite.size else 1.0
    w, h = zones.map_size
    nrows, ncols = _grid_shape(len(strategies))
    pw = 4.2
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(pw * ncols + 1.2, (pw * h / w + 0.6) * nrows + 1.0),
        squeeze=False,
        constrained_layout=True,
    )
    image = None
    for ax, name in zip(axes.flat, strategies, strict=False):
        mine = [s for s in sensors if s["strategy"] == name]
        image = ax.imshow(
            raster,
            origin="lower",
            extent=extent,
            cmap="Oranges",
            vmin=0.0,
            vmax=vmax,
            interpolation="bilinear",
        )
        for z in zones.zones:
            ax.add_patch(Circle(z.centre, z.radius, fill=False, ls="--", lw=1.0, ec="#444444"))
            if z.name:
                ax.text(
                    z.centre[0],
                    z.centre[1] + z.radius + 0.02 * h,
                    z.name,
                    ha="center",
                    va="bottom",
                    fontsize=8,
                    color="#333333",
                )
        if zones.base is not None:
            ax.plot(*zones.base, marker="^", ms=8, color="black", ls="none")
        if show_release:
            rel = np.array([[s["x_rel"], s["y_rel"]] for s in mine], dtype=float).reshape(-1, 2)
            rel = rel[np.isfinite(rel).all(axis=1)]
            ax.scatter(rel[:, 0], rel[:, 1], s=10, marker="x", lw=0.7, color=_REL, alpha=0.7)
        land = np.array([[s["x_land"], s["y_land"]] for s in mine], dtype=float).reshape(-1, 2)
        land = land[np.isfinite(land).all(axis=1)]
        ax.scatter(land[:, 0], land[:, 1], s=9, color=_DOT, edgecolors="white", linewidths=0.3, zorder=3)
        score = None if scores is None else scores.get(name)
        sub = f"{len(land)} landed" + (f", score {score:.3f}" if score is not None and math.isfinite(score) else "")
        ax.set_title(f"{name}\n{sub}", fontsize=10)
        ax.set_xlim(0, w)
        ax.set_ylim(0, h)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
    for ax in list(axes.flat)[len(strategies) :]:
        ax.axis("off")
    if image is not None:
        cb = fig.colorbar(image, ax=axes, shrink=0.6, pad=0.01)
        cb.set_label("target density (sensors per 100 m²)")
    handles = [
        Line2D([], [], marker="o", ls="none", color=_DOT, label="landed sensor"),
        Line2D([], [], marker="^", ls="none", color="black", label="UAV base"),
        Patch(fill=False, ls="--", ec="#444444", label="zone boundary"),
    ]
    if show_release:
        handles.insert(1, Line2D([], [], marker="x", ls="none", color=_REL, label="release point"))
    fig.legend(handles=handles, loc="outside lower center", ncol=len(handles), fontsize=9, frameon=False)
    fig.suptitle(title, fontsize=13)
    return _save(fig, path)


def plot_metric_bars(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike[str], title: str) -> Path:
    """Bar charts of the key metrics, one bar per strategy, mean ± std across seeds.

    Args:
        rows: ``runs.csv`` rows of one zone file.
        path: PNG destination.
        title: Figure title.

    Returns:
        The path written.
    """
    ranked = rank_strategies(rows)
    names = [s.strategy for s in ranked]
    y = np.arange(len(names))
    n_seeds = max((len(s.rows) for s in ranked), default=0)
    ncols, nrows = 3, math.ceil(len(BAR_METRICS) / 3)
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(15, 0.32 * len(names) * nrows + 1.6 * nrows + 0.8),
        squeeze=False,
        constrained_layout=True,
    )
    colors = [_REF_BAR if n == REFERENCE else _BAR for n in names]
    for i, (ax, (key, label, scale, better)) in enumerate(zip(axes.flat, BAR_METRICS, strict=False)):
        stats = [mean_std(s.scores() if key == "score" else s.values(key)) for s in ranked]
        mean = np.array([m for m, _ in stats]) * scale
        std = np.array([sd for _, sd in stats]) * abs(scale)
        m0, sd0 = np.nan_to_num(mean), np.nan_to_num(std)
        # every metric here is >= 0: the lower whisker stops at 0 instead of suggesting negative values
        err = np.vstack([np.minimum(sd0, np.maximum(m0, 0.0)), sd0])
        ax.barh(y, m0, xerr=err, color=colors, ecolor="#222222", capsize=2, height=0.7)
        ax.set_yticks(y, names if i % ncols == 0 else [""] * len(names), fontsize=8)
        ax.invert_yaxis()  # best score on top
        ax.set_title(f"{label} ({better} is better)", fontsize=10)
        ax.tick_params(axis="x", labelsize=8)
        ax.grid(axis="x", alpha=0.3)
        ax.margins(x=0.18)  # room for the value labels
        for yy, m, sd in zip(y, mean, std, strict=True):
            text = f" {m:.3g}" if math.isfinite(m) else " n/a"
            ax.text(
                max(np.nan_to_num(m), 0.0) + np.nan_to_num(sd),
                yy,
                text,
                va="center",
                fontsize=7,
                color="#333333" if math.isfinite(m) else "#777777",
            )
    for ax in list(axes.flat)[len(BAR_METRICS) :]:
        ax.axis("off")
    handles = [
        Patch(color=_BAR, label="flown strategy"),
        Patch(color=_REF_BAR, label="B8 teleport reference"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize=9, frameon=False)
    fig.suptitle(f"{title} (error bars: std over {n_seeds} seed(s))", fontsize=13)
    return _save(fig, path)


def _save(fig: Any, path: str | os.PathLike[str]) -> Path:
    """Save at ``DPI`` through a temporary file renamed into place, and close the figure."""
    p = Path(path)
    tmp = p.with_name(f".{p.stem}.partial.png")
    try:
        fig.savefig(tmp, dpi=DPI)
    finally:
        plt.close(fig)
    os.replace(tmp, p)
    return p


def write_plots(grid: Any, out_dir: str | os.PathLike[str]) -> list[Path]:
    """Landing maps (first seed) and metric bar charts for every zone file of a ``runner.GridResult``.

    Args:
        grid: The evaluation.
        out_dir: Existing output folder.

    Returns:
        The PNG paths written.
    """
    out = Path(out_dir)
    rows = run_rows(grid.runs)
    seed = grid.seeds[0]
    order = [REFERENCE, *grid.strategies]
    paths = []
    for src in grid.sources:
        sensors = [s for run in grid.runs if run.zones == src.label and run.seed == seed for s in run.sensors]
        scores = {r["strategy"]: composite_score(r) for r in rows if r["zones"] == src.label and r["seed"] == seed}
        title = f"Landed sensors, zone file '{src.label}', seed {seed}"
        png = out / f"landing_{src.label}_seed{seed}.png"
        paths.append(plot_landing_maps(sensors, src.zones, order, png, title, scores))
        mine = [r for r in rows if r["zones"] == src.label]
        paths.append(plot_metric_bars(mine, out / f"metrics_{src.label}.png", f"Key metrics, zone file '{src.label}'"))
    return paths
