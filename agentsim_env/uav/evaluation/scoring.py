"""Scores and statistics of a batch evaluation, shared by ``report`` (CSV, Markdown) and ``plots`` (PNG).

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

This module imports no other module of the evaluation package.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "DELIVERED_KEY",
    "ENERGY_KEY",
    "SCORE_TERMS",
    "StrategySummary",
    "composite_score",
    "mean_std",
    "rank_strategies",
    "run_rows",
    "to_float",
]

#: Quality terms of the composite score: (runs.csv key, how it enters, weight).
SCORE_TERMS: tuple[tuple[str, str, float], ...] = (
    ("coverage_weighted_vs_oracle", "ratio", 2.0),
    ("lcc_fraction_vs_oracle", "ratio", 1.0),
    ("fnd_vs_oracle", "ratio", 1.0),
    ("w1_mean", "one_minus", 1.0),
    ("containment", "value", 1.0),
)
#: runs.csv key of the fleet's battery fraction used (subtracted from the score).
ENERGY_KEY = "energy_fraction"
#: runs.csv key of the share of the required sensors that landed (scales the quality terms).
DELIVERED_KEY = "delivered_fraction"


def to_float(value: Any) -> float:
    """``value`` as a float; NaN for missing or non-numeric values.

    Args:
        value: A number, a numeric string (a CSV cell), ``None`` or anything else.

    Returns:
        The float, or NaN.
    """
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
        v = to_float(row.get(key))
        if how == "ratio":
            v = min(v, 1.0)
        elif how == "one_minus":
            v = 1.0 - v
        total += weight * (float(np.clip(v, 0.0, 1.0)) if math.isfinite(v) else 0.0)
    energy = to_float(row.get(ENERGY_KEY))
    delivered = to_float(row.get(DELIVERED_KEY))
    delivered = float(np.clip(delivered, 0.0, 1.0)) if math.isfinite(delivered) else 0.0
    quality = total / sum(w for _, _, w in SCORE_TERMS)
    return delivered * quality - (energy if math.isfinite(energy) else 0.0)


def _row_score(row: Mapping[str, Any]) -> float:
    """The row's ``score`` when present, else its composite score."""
    return to_float(row["score"]) if "score" in row else composite_score(row)


def mean_std(values: Iterable[Any]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof = 1) of the finite values.

    Args:
        values: Numbers (NaN and non-numbers are skipped).

    Returns:
        ``(mean, std)``; std is 0 for a single value, both NaN for none.
    """
    arr = np.array([to_float(v) for v in values], dtype=np.float64)
    arr = arr[np.isfinite(arr)]
    if arr.size == 0:
        return math.nan, math.nan
    return float(arr.mean()), float(arr.std(ddof=1)) if arr.size > 1 else 0.0


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
        return [to_float(r.get(key)) for r in self.rows]

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
    return sorted(out, key=lambda x: (-(x.score_mean if math.isfinite(x.score_mean) else -math.inf), x.strategy))


def run_rows(runs: Iterable[Any]) -> list[dict[str, Any]]:
    """``runs.csv`` rows of ``RunResult`` objects: zones, strategy, seed, score, then every metric.

    Args:
        runs: Objects with a ``row()`` method (``runner.RunResult``).

    Returns:
        One dict per run, in order.
    """
    out = []
    for run in runs:
        row = run.row()
        out.append(
            {
                "zones": row.pop("zones"),
                "strategy": row.pop("strategy"),
                "seed": row.pop("seed"),
                "score": composite_score(row),
                **row,
            }
        )
    return out
