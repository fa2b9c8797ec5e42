"""RLlib PPO on ``navigation`` with one policy shared by every agent (RLlib's new API stack).

``agentsim_env.env.rllib.ppo_config`` gives a ``PPOConfig`` over ``AgentSimRLlibEnv`` (RLlib's
``ParallelPettingZooEnv`` around the ParallelEnv): Dict observations flattened by RLlib's
``FlattenObservations`` connector, flat Box actions, every agent mapped to the policy ``"shared"``. This script
shrinks the batches so that a few hundred environment steps finish quickly, trains a few iterations on one CPU
(sampling and learning in this process) and prints what each iteration did.

Run (needs ``pip install "agentsim-env[rllib]"``)::

    python examples/rllib_ppo_shared.py --frames 400 --iterations 2
"""

from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

import ray

from agentsim_env.env.rllib import SHARED_POLICY, ppo_config


def _get(result: dict, *path: str) -> object:
    """A nested entry of RLlib's result dict, or ``nan`` when this ray version files it elsewhere."""
    for key in path:
        if not isinstance(result, dict) or key not in result:
            return float("nan")
        result = result[key]
    return result


def main() -> None:
    """Parse the arguments, build PPO and train."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=400, help="environment steps in all")
    p.add_argument("--iterations", type=int, default=2, help="PPO iterations (frames are split evenly)")
    p.add_argument("--agents", type=int, default=4)
    p.add_argument("--max-steps", type=int, default=100, help="episode length")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    batch = max(32, a.frames // a.iterations)
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, configure_logging=False)
    config = (
        ppo_config("navigation", n_agents=a.agents, max_steps=a.max_steps)
        .training(train_batch_size_per_learner=batch, minibatch_size=min(64, batch), num_epochs=2, lr=3e-4)
        .env_runners(rollout_fragment_length="auto")
        .debugging(seed=a.seed)
        .reporting(metrics_num_episodes_for_smoothing=1)
    )
    start = time.perf_counter()
    algo = config.build_algo()
    print(f"built PPO in {time.perf_counter() - start:.1f} s; policies: {sorted(algo.config.policies)}")
    for it in range(a.iterations):
        res = algo.train()
        steps = _get(res, "env_runners", "num_env_steps_sampled_lifetime")
        ret = _get(res, "env_runners", "episode_return_mean")
        loss = _get(res, "learners", SHARED_POLICY, "total_loss")
        print(
            f"iteration {it}: {steps} env steps sampled in all, episode return mean {ret}, "
            f"'{SHARED_POLICY}' total loss {loss}"
        )
    module = algo.get_module(SHARED_POLICY)
    params = sum(p.numel() for p in module.parameters())
    print(
        f"trained one shared policy ({params} parameters) for {a.iterations} iterations "
        f"in {time.perf_counter() - start:.1f} s"
    )
    logdir = Path(algo.logdir)
    algo.stop()
    ray.shutdown()
    # RLlib makes a log folder under ~/ray_results that this script leaves empty: remove it
    with contextlib.suppress(OSError):
        logdir.rmdir()


if __name__ == "__main__":
    main()
