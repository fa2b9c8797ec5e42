"""The learning-curve figure of a training run (mean return against agent-steps, with the baselines' level) and
the curriculum figure (the promotion metric against agent-steps, stage by stage)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["plot_curriculum", "plot_learning_curve"]


def plot_learning_curve(
    curve: Sequence[dict[str, float]],
    path: str | Path,
    *,
    title: str = "",
    eval_rows: Sequence[dict[str, Any]] = (),
) -> Path:
    """Draw the learning curve and, as horizontal lines, each evaluated policy's mean return.

    Args:
        curve: Rows of ``curve.csv`` (``timesteps``, ``mean_return``, ``wall_s`` ...).
        path: PNG to write.
        title: Figure title.
        eval_rows: Rows of the final evaluation (``policy``, ``kind``, ``mean_return``).

    Returns:
        The PNG path.
    """
    import matplotlib.pyplot as plt  # the backend is the caller's (Agg when headless; inline in notebooks)

    pts = [(r["timesteps"], r["mean_return"]) for r in curve if not math.isnan(r["mean_return"])]
    fig, ax = plt.subplots(figsize=(7.5, 4.2), dpi=110)
    if pts:
        xs, ys = zip(*pts)
        ax.plot(xs, ys, color="tab:blue", lw=1.6, label="training (stochastic policy, last 100 episodes)")
    styles = ["--", ":", "-."]
    others = [
        "tab:green",
        "tab:purple",
        "tab:orange",
        "tab:brown",
        "tab:pink",
        "tab:gray",
        "tab:olive",
        "tab:cyan",
    ]
    for i, r in enumerate(eval_rows):
        colour = "tab:red" if r.get("kind") == "learned" else others[i % len(others)]
        ax.axhline(
            float(r["mean_return"]),
            color=colour,
            ls=styles[i % 3],
            lw=1.2,
            label=f"{r['policy']} ({r.get('kind', '')}, evaluation): {float(r['mean_return']):.2f}",
        )
    ax.set_xlabel("agent-steps")
    ax.set_ylabel("mean episode return per agent")
    if pts and curve:
        last = curve[-1]
        budget = f"{int(last['timesteps']):,} agent-steps, {last['wall_s']:.0f} s wall, {last['cpu_s']:.0f} s CPU"
        title = f"{title}\n{budget}" if title else budget
    if title:
        ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_curriculum(cur: Any, state: dict[str, Any], path: str | Path) -> Path:
    """The metric against agent-steps, one colour per stage, stage boundaries and thresholds marked.

    Args:
        cur: The ``agentsim_env.train.curriculum.Curriculum``.
        state: Its run's state (``curriculum_state.json``).
        path: PNG to write.

    Returns:
        The PNG path.
    """
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2), dpi=110)
    evals, starts = state["evals"], [0] + [p["timesteps"] for p in state["promotions"]]
    end = max(int(state["timesteps"]), 1)
    for k in range(int(state["stage"]) + 1):
        pts = [(e["timesteps"], e["value"]) for e in evals if e["stage"] == k]
        st = cur.spec.stages[k]
        hi = starts[k + 1] if k + 1 < len(starts) else end
        colour = f"C{k % 10}"
        if pts:
            xs, ys = zip(*pts)
            ax.plot(xs, ys, "o-", color=colour, ms=3, lw=1.4, label=f"{k + 1} {st.name}")
        if st.threshold is not None:
            ax.hlines(st.threshold, starts[k], hi, colors=colour, linestyles=":", lw=1)
        if k > 0:
            how = state["promotions"][k - 1]["how"]
            ax.axvline(starts[k], color="grey", ls="--" if how == "promoted" else "-.", lw=0.8)
    ax.set_xlim(0, end * 1.02)
    ax.set_ylim(-0.03, 1.03)
    ax.set_xlabel("agent-steps")
    ax.set_ylabel(f"{cur.spec.metric} ({cur.spec.eval_seeds} held-out seeds)")
    ax.set_title(
        f"{cur.base.scenario} curriculum, seed {cur.base.seed}: {int(state['timesteps']):,} agent-steps, "
        f"{float(state['cpu_s']):.0f} s CPU\n(dotted: thresholds; dashed: promotions; dash-dot: budget advances)",
        fontsize=9,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best", title="stage", title_fontsize=7)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out
