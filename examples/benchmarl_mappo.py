"""BenchMARL MAPPO on ``navigation``: the scenario as a custom BenchMARL task, trained for one short run.

``agentsim_env.env.benchmarl.agentsim_task`` wraps the scenario as a BenchMARL ``TaskClass`` over TorchRL's
``PettingZooWrapper`` (one group ``"agents"``, masked agents, the global state for the centralised critic).
BenchMARL's default MAPPO and MLP configs are loaded, then shrunk so that ``--frames`` environment steps (one
iteration by default) finish quickly on one CPU: few copies of the environment, small minibatches, no
evaluation, no loggers, no videos. The experiment writes its folder under ``--out``.

Run (needs ``pip install "agentsim-env[benchmarl]"``)::

    python examples/benchmarl_mappo.py --frames 400 --iterations 1 --out outputs/benchmarl
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from benchmarl.algorithms import MappoConfig
from benchmarl.experiment import Experiment, ExperimentConfig
from benchmarl.models.mlp import MlpConfig

from agentsim_env.env.benchmarl import agentsim_task


def experiment(
    frames: int, iterations: int, envs: int, agents: int, max_steps: int, seed: int, out: Path
) -> Experiment:
    """A BenchMARL MAPPO experiment of ``iterations`` x ``frames / iterations`` environment steps."""
    config = ExperimentConfig.get_from_yaml()
    per_batch = max(envs, frames // iterations)
    config.max_n_frames = per_batch * iterations
    config.on_policy_collected_frames_per_batch = per_batch
    config.on_policy_n_envs_per_worker = envs
    config.on_policy_minibatch_size = min(100, per_batch)
    config.on_policy_n_minibatch_iters = 4
    config.lr = 3e-4
    config.evaluation = False
    config.render = False
    config.loggers = []
    config.create_json = False
    config.checkpoint_at_end = False
    config.sampling_device = config.train_device = config.buffer_device = "cpu"
    out.mkdir(parents=True, exist_ok=True)
    config.save_folder = str(out)
    model = MlpConfig.get_from_yaml()
    model.num_cells = [64, 64]
    return Experiment(
        task=agentsim_task("navigation", n_agents=agents, max_steps=max_steps),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=model,
        critic_model_config=model,
        seed=seed,
        config=config,
    )


def main() -> None:
    """Parse the arguments, build the experiment and run it."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=400, help="environment steps in all (over every copy)")
    p.add_argument("--iterations", type=int, default=1, help="MAPPO iterations (frames are split evenly)")
    p.add_argument("--envs", type=int, default=2, help="copies of the environment BenchMARL steps in series")
    p.add_argument("--agents", type=int, default=4)
    p.add_argument("--max-steps", type=int, default=100, help="episode length")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("outputs/benchmarl"), help="BenchMARL's experiment folder")
    a = p.parse_args()
    start = time.perf_counter()
    exp = experiment(a.frames, a.iterations, a.envs, a.agents, a.max_steps, a.seed, a.out)
    print(
        f"built the BenchMARL experiment in {time.perf_counter() - start:.1f} s: task {exp.task_name!r}, "
        f"groups { ({g: len(v) for g, v in exp.group_map.items()}) }, algorithm MAPPO"
    )
    exp.run()
    print(
        f"ran {exp.n_iters_performed} MAPPO iteration(s), {exp.total_frames} frames, in "
        f"{time.perf_counter() - start:.1f} s; experiment folder {exp.folder_name}"
    )


if __name__ == "__main__":
    main()
