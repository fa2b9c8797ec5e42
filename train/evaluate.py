"""Evaluate a trained model against every scripted baseline of its scenario, over fixed seeds.

Each policy plays ``eval.seeds`` episodes (seeds ``eval.first_seed`` ...) in the ParallelEnv: the trained
model deterministically, in the env built from ``env`` + ``eval.env``; the baselines in that env with
``eval.baseline_env`` on top. Per policy the table gives the mean return per agent (and its standard deviation
over episodes), the scenario's event counters per agent (``Scenario.event_keys``: ``arrived``, ``collided``,
``released`` ...), its outcomes at the end of an episode (``Scenario.final_keys``: ``uav_release``'s weighted
coverage), and for ``relay`` the share of groups brought to their target and the episodes in which every group
got there.
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.train.config import TrainConfig
from agentsim_env.wrappers.metrics import final_values, outcome

__all__ = ["baselines_of", "evaluate_policies", "format_table", "write_table"]


def baselines_of(cfg: TrainConfig) -> list[str]:
    """The scripted baselines ``cfg.eval.baselines`` selects (``all``, ``default``: the scenario's default
    baseline, ``none`` or a comma list); a scenario's plug-in policies (``register_policy``, entry points) count."""
    from agentsim_env.policies.registry import check_plugin, scenario_policies

    known = scenario_policies(cfg.scenario)
    sel = cfg.eval.baselines.strip()
    if sel == "all":
        return known
    if sel == "default":
        return known[:1]  # the registry lists the default first
    if sel in ("none", ""):
        return []
    names = [s.strip() for s in sel.split(",") if s.strip()]
    bad = [n for n in names if n not in known]
    if bad:
        check_plugin(cfg.scenario, bad[0])  # a plug-in that cannot be used: its own error
        raise ValueError(
            f"eval.baselines: {bad[0]!r} is not a baseline of {cfg.scenario!r}; "
            f"choose 'all', 'default', 'none' or from {known}"
        )
    return names


def _play(
    env: Any,
    policy: Any,
    name: str,
    kind: str,
    seeds: Sequence[int],
    bar: Any,
    first: Callable[[float], None] | None = None,
) -> dict[str, Any]:
    """Play ``seeds``; ``first`` is told the first episode's wall time (s)."""
    from agentsim_env.policies.rollout import run_episode

    n = len(env.possible_agents)
    returns, sums, extras = [], [], []
    events, finals = set(env.scenario.event_keys), env.scenario.final_keys
    last: dict[str, float] = {}

    def note_finals(_env: Any, infos: dict[str, dict[str, Any]]) -> None:
        last.update(final_values(infos, finals))

    for s in seeds:
        last.clear()
        t0 = time.perf_counter()
        ep = run_episode(env, policy, s, on_step=note_finals if finals else None)
        if first is not None:
            first(time.perf_counter() - t0)
            first = None
        returns.append(float(np.mean(list(ep.returns.values()))))
        sums.append({k: v / n for k, v in ep.info_sums.items() if k in events})
        extras.append({**last, **outcome(env)})
        if bar is not None:
            bar.update(1)
    row: dict[str, Any] = {
        "policy": name,
        "kind": kind,
        "episodes": len(seeds),
        "mean_return": float(np.mean(returns)),
        "std_return": float(np.std(returns)),
    }
    for key in sorted({k for d in sums for k in d}):
        row[f"{key}_per_agent"] = float(np.mean([d.get(key, 0.0) for d in sums]))
    for key in sorted({k for d in extras for k in d}):
        row[key] = float(np.mean([d.get(key, 0.0) for d in extras]))
    return row


def _secs(t: float) -> str:
    """Seconds to two significant digits or so (0.4, 3.2, 87, 1240)."""
    return f"{t:.1f}" if t < 10 else f"{t:.0f}"


def _cost_line(cfg: TrainConfig, with_model: bool, n_baselines: int, n_seeds: int) -> str:
    """What the evaluation will play, e.g. ``evaluating the model and 10 baselines (--eval-baselines all) x
    10 seeds = 110 episodes``."""
    sel = cfg.eval.baselines.strip()
    how = f"--eval-baselines {sel}" if sel in ("none", "default", "all") else f"eval.baselines={sel}"
    played = f"{n_baselines} baseline{'' if n_baselines == 1 else 's'} ({how})"
    n = (n_baselines + int(with_model)) * n_seeds
    line = f"evaluating {'the model and ' if with_model else ''}{played} x {n_seeds} seeds = {n} episodes"
    return line + ("; --eval-baselines default or none for a quicker one" if n_baselines > 1 else "")


def evaluate_policies(
    cfg: TrainConfig,
    model: Any = None,
    *,
    name: str = "learned",
    record: str | Path | None = None,
    progress: bool = False,
    report: Callable[[str], None] | None = None,
) -> list[dict[str, Any]]:
    """Play the trained model (if given) and the selected baselines over ``cfg.eval``'s seeds.

    Args:
        cfg: The training config (scenario, env, eval).
        model: An SB3 model, a model folder / ``.zip``, or ``None`` (baselines only).
        name: The model's name in the table.
        record: An SQLite store to record every evaluation episode to (one run per policy).
        progress: Show a progress bar over episodes.
        report: Told what the evaluation costs, in three lines: the episodes it plays, an estimate of the time
            after the first episode (its time x the episodes; baselines differ, so it is rough), and the time
            taken. Evaluating every baseline can take far longer than a short training run.

    Returns:
        One row per policy (the model first), as described in the module docstring.
    """
    import agentsim_env
    from agentsim_env.policies.learned import LearnedPolicy, load_policy
    from agentsim_env.policies.registry import make_policy

    seeds = cfg.eval.seed_list()
    baselines = baselines_of(cfg)
    jobs: list[tuple[str, str, Any, dict[str, Any]]] = []
    if model is not None:
        jobs.append((name, "learned", model, cfg.eval_env()))
    jobs += [(b, "baseline", b, cfg.eval_env(baseline=True)) for b in baselines]
    total = len(jobs) * len(seeds)
    say = report if report is not None else (lambda _line: None)
    say(_cost_line(cfg, model is not None, len(baselines), len(seeds)))
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc=f"evaluate {cfg.scenario}", unit="episode")
    rows = []
    t0 = time.perf_counter()
    try:
        for i, (label, kind, what, env_cfg) in enumerate(jobs):
            env = agentsim_env.make(cfg.scenario, **env_cfg)
            if record is not None:
                from agentsim_env.recorder import record as record_env

                env = record_env(env, record, label=f"agentsim train evaluation: {label} seeds {seeds[0]}-{seeds[-1]}")
            if kind == "baseline":
                policy = make_policy(cfg.scenario, env, what)
            elif isinstance(what, (str, Path)):
                policy = load_policy(what, env)
            else:
                policy = LearnedPolicy(what, env, name=label)
            try:
                first = (
                    (lambda t: say(f"~{_secs(t * total)} s in all at the first episode's pace ({t:.2f} s)"))
                    if (i == 0)
                    else None
                )
                rows.append(_play(env, policy, label, kind, seeds, bar, first))
            except BaseException:
                if record is not None:
                    env.recorder.finish("incomplete")
                raise
            env.close()
    finally:
        if bar is not None:
            bar.close()
    say(f"evaluation: {total} episodes in {time.perf_counter() - t0:.1f} s")
    return rows


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    return cols


def format_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table (numbers to 3 decimals)."""
    cols = _columns(rows)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        cells = [f"{r[c]:.3f}" if isinstance(r.get(c), float) else str(r.get(c, "")) for c in cols]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_table(rows: list[dict[str, Any]], out: str | Path) -> tuple[Path, Path]:
    """Write ``eval.csv`` and ``eval.md`` into ``out``; returns both paths."""
    folder = Path(out)
    cols = _columns(rows)
    csv_path = folder / "eval.csv"
    with open(csv_path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)
    md_path = folder / "eval.md"
    md_path.write_text(format_table(rows) + "\n", encoding="utf-8")
    return csv_path, md_path
