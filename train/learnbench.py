"""The learning benchmark: every scenario, several algorithms and training seeds, evaluated against the baselines.

For every selected scenario the config ``train/configs/bench/<scenario>.yaml`` gives the agent-step budget (the
same for every algorithm), the training env and the evaluation (held-out seeds, scripted baselines). Per
algorithm and training seed (0, 1, ...) one run trains for the budget and its policy is then played on the
evaluation seeds; every scripted baseline of the scenario is played once per scenario on the same seeds.

==========  ==============================================================================================
``ppo``     stable-baselines3 PPO with parameter sharing over the native batched VecEnv (this environment)
``mappo``   BenchMARL MAPPO (centralised critic on ``state()``), in BenchMARL's own environment
``ippo``    BenchMARL IPPO (independent critics), same
``masac``   BenchMARL MASAC (off-policy, continuous actions), same
==========  ==============================================================================================

The BenchMARL algorithms run in a subprocess of ``benchmarl_python`` (``train/benchmarl_worker.py`` with the
checkout on ``PYTHONPATH``); when that Python is missing their rows say so and carry no numbers. Their
evaluation is the deterministic policy's mean return per agent on the same held-out seeds through the TorchRL
env, and its success metric from the same episodes' infos (``agentsim_env.wrappers.EpisodeMetrics``).
``agentsim_env.train.learnbench_report`` writes the files.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agentsim_env.train.config import CONFIG_DIR, TrainConfig, load_config
from agentsim_env.train.learnbench_report import BenchResult, write_all

__all__ = [
    "ALGORITHMS",
    "BENCHMARL_ALGORITHMS",
    "BENCH_DIR",
    "DEFAULT_BENCHMARL_PYTHON",
    "MISSING_BENCHMARL",
    "SUCCESS_METRIC",
    "BenchOptions",
    "BenchResult",
    "bench_config",
    "bench_scenarios",
    "run_benchmark",
]

#: Per-scenario benchmark configs (``<scenario>.yaml``).
BENCH_DIR = CONFIG_DIR / "bench"
#: Every algorithm the benchmark knows, in table order.
ALGORITHMS: tuple[str, ...] = ("ppo", "mappo", "ippo", "masac")
#: The algorithms run through BenchMARL.
BENCHMARL_ALGORITHMS: tuple[str, ...] = ("mappo", "ippo", "masac")
#: The BenchMARL Python used when none is given (``make test-ecosystem-benchmarl`` builds it).
DEFAULT_BENCHMARL_PYTHON = Path(".venv-eco/benchmarl/bin/python")
#: Status of a BenchMARL row when its environment is missing.
MISSING_BENCHMARL = "not run: BenchMARL environment missing (make test-ecosystem-benchmarl builds it)"
#: Each scenario's main success metric: a column of ``evaluate_policies``' rows.
SUCCESS_METRIC: dict[str, str] = {
    "navigation": "arrived_per_agent",
    "relay": "groups_reached",
    "rendezvous": "met_per_agent",
    "uav_release": "coverage_weighted",
}
#: ``--quick``: small envs, tiny budgets, two evaluation seeds (a smoke test of the pipeline, not a result).
QUICK: dict[str, dict[str, Any]] = {
    "navigation": {"env": {"n_agents": 2, "max_steps": 50}},
    "relay": {"env": {"n_groups": 1, "group_size": 2, "max_steps": 50}},
    "rendezvous": {"env": {"n_agents": 2, "max_steps": 50}},
    "uav_release": {"env": {"max_steps": 300}, "worlds": 1},  # an episode ends within the budget,
}
QUICK_BUDGET = 2000
QUICK_EVAL_SEEDS = 2
QUICK_SEEDS = 2
QUICK_ALGORITHMS = ("ppo", "mappo")
_WORKER = Path(__file__).resolve().parent / "benchmarl_worker.py"


def bench_scenarios() -> list[str]:
    """The scenarios with a benchmark config, in name order."""
    return sorted(p.stem for p in BENCH_DIR.glob("*.yaml"))


@dataclass(frozen=True)
class BenchOptions:
    """What one benchmark invocation runs.

    Attributes:
        scenarios: Scenarios to run (each needs ``train/configs/bench/<name>.yaml``); empty: all of them.
        algorithms: Algorithms from ``ALGORITHMS``; empty: all (``--quick``: ``QUICK_ALGORITHMS``).
        seeds: Training seeds per algorithm (0 .. seeds - 1), >= 1.
        budget: Agent-steps per run over the configs' ``timesteps`` (``None``: the configs'), > 0.
        eval_seeds: Evaluation episodes per policy over the configs' (``None``: the configs'), >= 1.
        quick: Small envs, tiny budgets (``QUICK``), 2 seeds unless given.
        out: Output folder.
        benchmarl_python: The BenchMARL environment's Python.
        progress: Show a progress bar over runs.
        command: The command line, written into ``summary.md``.
    """

    scenarios: tuple[str, ...] = ()
    algorithms: tuple[str, ...] = ()
    seeds: int | None = None
    budget: int | None = None
    eval_seeds: int | None = None
    quick: bool = False
    out: Path = Path("outputs/bench_learning")
    benchmarl_python: Path = DEFAULT_BENCHMARL_PYTHON
    progress: bool = True
    command: str = ""

    def __post_init__(self) -> None:
        known = bench_scenarios()
        for name in self.scenarios:
            if name not in known:
                raise ValueError(f"scenario must be one of {known}, got {name!r}")
        for name in self.algorithms:
            if name not in ALGORITHMS:
                raise ValueError(f"algorithm must be one of {list(ALGORITHMS)}, got {name!r}")
        if self.seeds is not None and (isinstance(self.seeds, bool) or self.seeds < 1):
            raise ValueError(f"seeds must be an integer >= 1, got {self.seeds!r}")
        if self.budget is not None and (isinstance(self.budget, bool) or self.budget <= 0):
            raise ValueError(f"budget must be a number of agent-steps > 0, got {self.budget!r}")
        if self.eval_seeds is not None and (isinstance(self.eval_seeds, bool) or self.eval_seeds < 1):
            raise ValueError(f"eval_seeds must be an integer >= 1, got {self.eval_seeds!r}")

    def selected_scenarios(self) -> list[str]:
        """The scenarios to run."""
        return list(self.scenarios) or bench_scenarios()

    def selected_algorithms(self) -> list[str]:
        """The algorithms to run, in table order."""
        chosen = self.algorithms or (QUICK_ALGORITHMS if self.quick else ALGORITHMS)
        return [a for a in ALGORITHMS if a in chosen]

    def n_seeds(self) -> int:
        """Training seeds per algorithm (3 by default, 2 with ``quick``)."""
        return self.seeds if self.seeds is not None else (QUICK_SEEDS if self.quick else 3)


def bench_config(scenario: str, opts: BenchOptions) -> TrainConfig:
    """The training config of ``scenario``'s runs: its bench YAML with ``opts``' overrides (seed 0)."""
    overrides: dict[str, Any] = {"checkpoint_every": 0}
    if opts.quick:
        overrides.update(timesteps=QUICK_BUDGET, worlds=4, ppo={"n_steps": 64, "batch_size": 128, "n_epochs": 2})
        overrides.update(QUICK[scenario])
        overrides["eval"] = {"seeds": QUICK_EVAL_SEEDS}
    if opts.budget is not None:
        overrides["timesteps"] = int(opts.budget)
    if opts.eval_seeds is not None:
        overrides["eval"] = {**overrides.get("eval", {}), "seeds": int(opts.eval_seeds)}
    return load_config(BENCH_DIR / f"{scenario}.yaml", overrides)


def _success(scenario: str, cfg: TrainConfig, row: dict[str, Any]) -> float:
    """The scenario's success metric of an evaluation row (an event counter that never fired counts 0)."""
    from agentsim_env.scenarios.registry import make_scenario

    key = SUCCESS_METRIC.get(scenario, "")
    if key in row:
        return float(row[key])
    events = make_scenario(scenario, **cfg.eval_env()).event_keys
    return 0.0 if key.removesuffix("_per_agent") in events else math.nan


def _run_row(scenario: str, algorithm: str, seed: int, cfg: TrainConfig, status: str = "ok") -> dict[str, Any]:
    return {
        "scenario": scenario,
        "algorithm": algorithm,
        "seed": seed,
        "status": status,
        "budget_agent_steps": cfg.timesteps,
        "agent_steps": "",
        "wall_s": "",
        "cpu_s": "",
        "final_train_return": "",
        "eval_return": "",
        "eval_return_std": "",
        "success_metric": SUCCESS_METRIC.get(scenario, ""),
        "success": "",
        "eval_seeds": f"{cfg.eval.first_seed}-{cfg.eval.first_seed + cfg.eval.seeds - 1}",
    }


def _run_ppo(scenario: str, cfg: TrainConfig, seed: int, folder: Path, result: BenchResult) -> None:
    """Train PPO (the model and its curve go to ``folder``), evaluate it, add its row and curve."""
    from agentsim_env.train.evaluate import evaluate_policies
    from agentsim_env.train.runner import train

    run_cfg = cfg.replace(seed=seed)
    trained = train(run_cfg, folder)
    curve = trained.curve
    model_row = evaluate_policies(run_cfg.replace(eval={"baselines": "none"}), trained.model, name="ppo")[0]
    row = _run_row(scenario, "ppo", seed, run_cfg)
    finite = [p for p in curve if math.isfinite(p["mean_return"])]
    row.update(
        agent_steps=trained.timesteps,
        wall_s=round(trained.wall_s, 3),
        cpu_s=round(trained.cpu_s, 3),
        final_train_return=finite[-1]["mean_return"] if finite else "",
        eval_return=model_row["mean_return"],
        eval_return_std=model_row["std_return"],
        success=_success(scenario, run_cfg, model_row),
    )
    result.runs.append(row)
    for p in finite:
        result.curves.append(
            {"scenario": scenario, "algorithm": "ppo", "seed": seed, "agent_steps": int(p["timesteps"]),
             "mean_return": p["mean_return"]}
        )  # fmt: skip


def _benchmarl_jobs(
    plan: Sequence[tuple[str, TrainConfig, str, int]], out: Path
) -> tuple[list[dict[str, Any]], dict[str, tuple[str, str, int, TrainConfig, int]]]:
    """The worker's job list and, per job id, what it runs (scenario, algorithm, seed, config, agents)."""
    from agentsim_env.scenarios.registry import make_scenario

    jobs, index = [], {}
    for scenario, cfg, algorithm, seed in plan:
        n_agents = int(make_scenario(scenario, **cfg.env).n_agents)
        job_id = f"{scenario}/{algorithm}/seed{seed}"
        jobs.append(
            {
                "id": job_id,
                "scenario": scenario,
                "algorithm": algorithm,
                "seed": seed,
                "frames": max(1, cfg.timesteps // n_agents),  # a frame moves every agent of one env
                "frames_per_batch": max(1, min(6000, cfg.timesteps // n_agents // 4)),
                "envs": min(4, cfg.worlds),  # BenchMARL's serial env copies
                "env": cfg.env,
                "eval_seeds": cfg.eval.seed_list(),
                "hidden": list(cfg.ppo.net_arch),
                "out": str(out / "runs" / scenario / algorithm / f"seed{seed}"),
            }
        )
        index[job_id] = (scenario, algorithm, seed, cfg, n_agents)
    return jobs, index


def _run_benchmarl(
    plan: Sequence[tuple[str, TrainConfig, str, int]], opts: BenchOptions, result: BenchResult, bar: Any
) -> None:
    """Run the BenchMARL jobs in one subprocess of ``opts.benchmarl_python`` and add their rows and curves."""
    if not plan:
        return
    python = Path(opts.benchmarl_python)
    if not python.is_file():
        for scenario, cfg, algorithm, seed in plan:
            result.runs.append(_run_row(scenario, algorithm, seed, cfg, MISSING_BENCHMARL))
            if bar is not None:
                bar.update(1)
        return
    opts.out.mkdir(parents=True, exist_ok=True)
    jobs, index = _benchmarl_jobs(plan, opts.out)
    root = str(Path(__file__).resolve().parent.parent)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)}
    with tempfile.TemporaryDirectory(dir=opts.out) as tmp:
        jobs_path, results_path = Path(tmp) / "jobs.json", Path(tmp) / "results.jsonl"
        jobs_path.write_text(json.dumps({"runs": jobs}), encoding="utf-8")
        with open(opts.out / "benchmarl.log", "w", encoding="utf-8") as log:
            proc = subprocess.Popen(
                [str(python), str(_WORKER), str(jobs_path), str(results_path)],
                stdout=subprocess.PIPE,
                stderr=log,
                text=True,
                env=env,
            )
            assert proc.stdout is not None
            for line in proc.stdout:
                if line.startswith("done ") and bar is not None:
                    bar.update(1)
            proc.wait()
        records = {}
        if results_path.exists():
            for line in results_path.read_text(encoding="utf-8").splitlines():
                rec = json.loads(line)
                records[rec["id"]] = rec
    for job_id, (scenario, algorithm, seed, cfg, n_agents) in index.items():
        rec = records.get(job_id)
        if rec is None or "error" in rec:
            why = rec["error"] if rec else f"the BenchMARL worker exited with {proc.returncode} (see benchmarl.log)"
            result.runs.append(_run_row(scenario, algorithm, seed, cfg, f"failed: {why}"))
            continue
        row = _run_row(scenario, algorithm, seed, cfg)
        curve = [(int(f * n_agents), float(r)) for f, r in rec["curve"] if math.isfinite(r)]
        returns = np.asarray(rec["eval_returns"], dtype=float)
        episodes = rec.get("eval_metrics") or []
        metric = SUCCESS_METRIC.get(scenario, "")
        if episodes:  # averaged as evaluate_policies does it: an episode whose counter never fired counts 0
            seen = [e for e in episodes if metric in e]
            mean = {metric: float(np.mean([e.get(metric, 0.0) for e in episodes]))} if seen else {}
            row["success"] = _success(scenario, cfg, mean)
        row.update(
            agent_steps=int(rec["frames_done"]) * n_agents,
            wall_s=round(float(rec["wall_s"]), 3),
            cpu_s=round(float(rec["cpu_s"]), 3),
            final_train_return=curve[-1][1] if curve else "",
            eval_return=float(returns.mean()),
            eval_return_std=float(returns.std()),
        )
        result.runs.append(row)
        result.curves += [
            {"scenario": scenario, "algorithm": algorithm, "seed": seed, "agent_steps": s, "mean_return": r}
            for s, r in curve
        ]


def _baselines(scenario: str, cfg: TrainConfig) -> list[dict[str, Any]]:
    """Every scripted baseline of ``scenario`` on the evaluation seeds, one at a time: one that cannot be built
    or played (a plugin's, half installed) keeps a row with its error instead of stopping the benchmark. When the
    plug-in policies cannot even be listed (one registered from code does not load, so the scenarios it serves
    are unknown; an installed one that does not load is left out by the registry with a warning), a row
    says so and each built-in baseline is still tried, with a row of its own (``make_policy`` lists the plug-ins
    too, so they may fail the same way)."""
    from agentsim_env.policies.registry import BASELINES
    from agentsim_env.train.evaluate import baselines_of, evaluate_policies

    rows: list[dict[str, Any]] = []
    try:
        names = baselines_of(cfg)
    except ValueError as exc:
        if cfg.eval.baselines.strip() != "all":
            raise
        print(f"benchmark-rl: the plug-in policies of {scenario!r} could not be listed: {exc}", file=sys.stderr)
        rows.append({"policy": "plug-in policies", "episodes": 0, "status": f"failed: {exc}"})
        names = list(BASELINES.get(scenario, {}))
    for name in names:
        try:
            (row,) = evaluate_policies(cfg.replace(eval={"baselines": name}), None)
        except (ValueError, ImportError) as exc:
            print(f"benchmark-rl: baseline {name!r} of {scenario!r} failed: {exc}", file=sys.stderr)
            rows.append({"policy": name, "episodes": 0, "status": f"failed: {exc}"})
            continue
        rows.append({**row, "status": "scripted", "success": _success(scenario, cfg, row)})
    for row in rows:
        row["success_metric"] = SUCCESS_METRIC.get(scenario, "")
    return rows


def run_benchmark(opts: BenchOptions) -> BenchResult:
    """Run the benchmark ``opts`` selects and write its files into ``opts.out``.

    Args:
        opts: The scenarios, algorithms, seeds, budgets and output folder.

    Returns:
        The rows, curves and baseline evaluations (also written: see ``learnbench_report.write_all``).
    """
    import torch
    from tqdm.auto import tqdm

    torch.set_num_threads(1)
    scenarios, algorithms, seeds = opts.selected_scenarios(), opts.selected_algorithms(), opts.n_seeds()
    configs = {s: bench_config(s, opts) for s in scenarios}
    result = BenchResult()
    total = len(scenarios) * len(algorithms) * seeds
    bar = tqdm(total=total, desc="benchmark-rl", unit="run", disable=not opts.progress, file=sys.stderr)
    benchmarl_plan = []
    try:
        for scenario, cfg in configs.items():
            result.baselines[scenario] = _baselines(scenario, cfg)
            for algorithm in algorithms:
                for seed in range(seeds):
                    if algorithm in BENCHMARL_ALGORITHMS:
                        benchmarl_plan.append((scenario, cfg, algorithm, seed))
                        continue
                    bar.set_postfix_str(f"{scenario} {algorithm} seed {seed}")
                    folder = opts.out / "runs" / scenario / algorithm / f"seed{seed}"
                    _run_ppo(scenario, cfg, seed, folder, result)
                    bar.update(1)
        bar.set_postfix_str("BenchMARL runs")
        _run_benchmarl(benchmarl_plan, opts, result, bar)
    finally:
        bar.close()
    order = {(s, a): i for i, (s, a) in enumerate((s, a) for s in scenarios for a in algorithms)}
    result.runs.sort(key=lambda r: (order[(r["scenario"], r["algorithm"])], r["seed"]))
    write_all(result, opts.out, configs, quick=opts.quick, command=opts.command)
    return result
