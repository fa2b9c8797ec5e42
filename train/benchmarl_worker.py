"""Train BenchMARL algorithms on scenarios for the learning benchmark, in BenchMARL's own environment.

Run by ``agentsim_env.train.learnbench`` as a subprocess of the BenchMARL Python (``make test-ecosystem-benchmarl``
builds that environment) with the repository on ``PYTHONPATH``::

    python train/benchmarl_worker.py JOBS.json RESULTS.jsonl

``JOBS.json`` holds ``{"runs": [...]}``, one object per run: ``scenario``, ``algorithm`` (``mappo``, ``ippo``,
``masac``), ``seed``, ``frames`` (environment steps; one step moves every agent), ``env`` (scenario config keys),
``eval_seeds`` (held-out episode seeds), ``hidden`` (widths of the MLPs) and ``out`` (BenchMARL's experiment
folder). Each finished run appends one JSON line to ``RESULTS.jsonl``: the learning curve (``[frames, mean episode
return per agent]`` per collected batch in which an episode ended), the wall and CPU seconds of training, and the
deterministic policy's mean return per agent over ``eval_seeds`` (each an episode of the TorchRL environment reset
with that seed) with each episode's metrics (``eval_metrics``: ``agentsim_env.wrappers.EpisodeMetrics``, whose
success counters the TorchRL loop does not show). A run that raises writes its error instead, and the next run goes on.

This file imports only ``agentsim_env.env`` and ``agentsim_env.wrappers`` (and BenchMARL / TorchRL), never the
training package, so that it
runs against the checkout on ``PYTHONPATH`` whatever the BenchMARL environment has installed.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from pathlib import Path
from typing import Any

from benchmarl.experiment.callback import Callback

ALGORITHMS = ("mappo", "ippo", "masac")


def _algorithm(name: str) -> Any:
    from benchmarl.algorithms import IppoConfig, MappoConfig, MasacConfig

    classes = {"mappo": MappoConfig, "ippo": IppoConfig, "masac": MasacConfig}
    if name not in classes:
        raise ValueError(f"algorithm must be one of {list(classes)}, got {name!r}")
    return classes[name].get_from_yaml()


class CurveCallback(Callback):  # type: ignore[misc]
    """A BenchMARL callback appending ``[frames so far, mean episode return per agent]`` to ``curve`` after each
    collected batch in which an episode ended (a module-level class: BenchMARL pickles its callbacks)."""

    def __init__(self, curve: list[list[float]]) -> None:
        super().__init__()
        self.curve = curve
        self.frames = 0

    def on_batch_collected(self, batch: Any) -> None:
        """Count the batch's frames and note the mean return of the episodes it ended."""
        self.frames += int(batch.numel())
        done = batch.get(("next", "done")).squeeze(-1)
        ret = batch.get(("next", "agents", "episode_reward")).mean(dim=(-2, -1))
        if bool(done.any()):
            self.curve.append([float(self.frames), float(ret[done].mean())])


def _experiment(job: dict[str, Any], curve: list[list[float]]) -> Any:
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    from agentsim_env.env.benchmarl import agentsim_task

    frames = int(job["frames"])
    config = ExperimentConfig.get_from_yaml()
    envs = int(job.get("envs", 4))
    per_batch = max(envs, min(frames, int(job.get("frames_per_batch", 2000))))
    config.max_n_frames = max(per_batch, frames)
    config.on_policy_collected_frames_per_batch = per_batch
    config.on_policy_n_envs_per_worker = envs
    config.on_policy_minibatch_size = min(256, per_batch)
    config.on_policy_n_minibatch_iters = 4
    config.off_policy_collected_frames_per_batch = per_batch
    config.off_policy_n_envs_per_worker = envs
    config.off_policy_train_batch_size = min(256, per_batch)
    config.off_policy_n_optimizer_steps = max(1, per_batch // 100)
    config.off_policy_memory_size = max(10_000, per_batch)
    config.lr = 3e-4
    config.evaluation = False
    config.render = False
    config.loggers = []
    config.create_json = False
    config.checkpoint_at_end = False
    config.sampling_device = config.train_device = config.buffer_device = "cpu"
    out = Path(job["out"])
    out.mkdir(parents=True, exist_ok=True)
    config.save_folder = str(out)
    model = MlpConfig.get_from_yaml()
    model.num_cells = list(job.get("hidden", [64, 64]))
    return Experiment(
        task=agentsim_task(job["scenario"], **job["env"]),
        algorithm_config=_algorithm(job["algorithm"]),
        model_config=model,
        critic_model_config=model,
        seed=int(job["seed"]),
        config=config,
        callbacks=[CurveCallback(curve)],
    )


def _evaluate(exp: Any, job: dict[str, Any]) -> tuple[list[float], list[dict[str, float]]]:
    """The deterministic policy's mean return per agent on each held-out seed, and each episode's metrics
    (``EpisodeMetrics.summary``: event counters per agent, final values, the scenario's outcome)."""
    import torch
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    from agentsim_env.env.torchrl import torchrl_env
    from agentsim_env.wrappers.metrics import EpisodeMetrics

    returns, metrics = [], []
    for seed in job["eval_seeds"]:
        env = torchrl_env(job["scenario"], seed=int(seed), return_state=True, wrap=EpisodeMetrics, **job["env"])
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            td = env.rollout(exp.max_steps, policy=exp.policy, break_when_any_done=True)
        returns.append(float(td.get(("next", "agents", "reward")).sum(dim=0).mean()))
        metrics.append(env._env.summary())  # the EpisodeMetrics that TorchRL wraps
        env.close()
    return returns, metrics


def run_job(job: dict[str, Any]) -> dict[str, Any]:
    """Train and evaluate one run; returns its result record (see the module docstring)."""
    import torch

    torch.set_num_threads(1)
    curve: list[list[float]] = []
    t0, c0 = time.perf_counter(), time.process_time()
    exp = _experiment(job, curve)
    exp.run()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    returns, metrics = _evaluate(exp, job)
    return {
        "id": job["id"],
        "frames_done": int(exp.total_frames),
        "wall_s": wall,
        "cpu_s": cpu,
        "curve": curve,
        "eval_returns": returns,
        "eval_metrics": metrics,
    }


def main(argv: list[str]) -> int:
    """Run every job of ``argv[0]``, appending results to ``argv[1]``."""
    if len(argv) != 2:
        print("usage: benchmarl_worker.py JOBS.json RESULTS.jsonl", file=sys.stderr)
        return 2
    jobs = json.loads(Path(argv[0]).read_text(encoding="utf-8"))["runs"]
    for job in jobs:
        try:
            record = run_job(job)
        except Exception as exc:  # one failed run is reported in its row; the others still run
            traceback.print_exc()
            record = {"id": job["id"], "error": f"{type(exc).__name__}: {exc}"}
        with open(argv[1], "a", encoding="utf-8") as f:
            f.write(json.dumps(record) + "\n")
        print(f"done {job['id']}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
