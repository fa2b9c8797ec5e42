"""Train a shared PPO policy on a scenario with stable-baselines3, and evaluate it.

Every agent of every world is one entry of an SB3 ``VecEnv`` (``AgentSimVecEnv``), so one network is trained on
all agents (parameter sharing). Usage::

    python -m agentsim_env.train.ppo navigation --timesteps 200000 --worlds 16 --out outputs/ppo_navigation

The model is saved as ``<out>/model.zip`` with ``<out>/config.json``; ``evaluate`` rolls it out in the
ParallelEnv with flat observations and reports the mean return and the scenario's success counters.
``--record run.db`` records the training env (every world, every step, automatic resets as new episodes) to an
SQLite store (``agentsim_env.recorder``) as one run; it is marked ``complete`` when training ends.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np


def train(
    scenario: str,
    *,
    timesteps: int,
    worlds: int = 16,
    seed: int = 0,
    out: str | Path | None = None,
    config: dict[str, Any] | None = None,
    ppo_kwargs: dict[str, Any] | None = None,
    progress: bool = False,
    record: str | Path | None = None,
) -> Any:
    """Train PPO on ``scenario`` and return the SB3 model (saved under ``out`` when given).

    Args:
        scenario: Scenario name.
        timesteps: Agent-steps to train for (summed over all agents of all worlds).
        worlds: Worlds stepped together.
        seed: Seed of the envs and of the network initialisation.
        out: Folder for ``model.zip`` and ``config.json``.
        config: Scenario config keys.
        ppo_kwargs: Extra keyword arguments of ``stable_baselines3.PPO``.
        progress: Show a tqdm progress bar (on stderr) of the agent-steps done.
        record: An SQLite store to record the training env to (one run; ``agentsim_env.recorder.record``).
    """
    import torch
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv
    from agentsim_env.train.progress import TqdmProgressBar

    torch.set_num_threads(1)
    vec = AgentSimVecEnv(scenario, worlds, seed=seed, **(config or {}))
    recorded: Any = None
    if record is not None:  # the VecEnv steps the recorded BatchedEnv (every attribute is the wrapped env's)
        from agentsim_env.recorder import record as record_env

        recorded = record_env(vec.batch, record, label=f"train.ppo {scenario} worlds={worlds} seed={seed}")
        vec.batch = recorded
    kw: dict[str, Any] = {
        "n_steps": 64,
        "batch_size": 512,
        "learning_rate": 3e-4,
        "gamma": 0.98,
        "ent_coef": 0.0,
        "verbose": 0,
    }
    kw.update(ppo_kwargs or {})
    try:
        model = PPO("MlpPolicy", vec, seed=seed, device="cpu", **kw)
        model.learn(total_timesteps=timesteps, callback=TqdmProgressBar(desc=scenario) if progress else None)
    except BaseException:
        if recorded is not None:
            recorded.recorder.finish("incomplete")
        raise
    if recorded is not None:
        recorded.close()  # the run is complete
    if out is not None:
        path = Path(out)
        path.mkdir(parents=True, exist_ok=True)
        model.save(path / "model.zip")
        meta = {
            "scenario": scenario,
            "config": config or {},
            "timesteps": timesteps,
            "worlds": worlds,
            "seed": seed,
        }
        (path / "config.json").write_text(json.dumps(meta, indent=2))
    return model


def evaluate(
    model: Any, scenario: str, seeds: list[int], config: dict[str, Any] | None = None
) -> dict[str, float]:
    """Roll out ``model`` deterministically in the flat-format ParallelEnv over ``seeds``.

    Returns:
        Mean return per agent and, per integer info key (e.g. ``arrived``), the fraction of agents.
    """
    import agentsim_env

    env = agentsim_env.make(scenario, obs_format="flat", action_format="flat", **(config or {}))
    returns: list[float] = []
    counts: dict[str, int] = {}
    for s in seeds:
        obs, _ = env.reset(seed=s)
        total = dict.fromkeys(env.possible_agents, 0.0)
        while env.agents:
            live = list(env.agents)
            act, _ = model.predict(np.stack([obs[a] for a in live]), deterministic=True)
            obs, rew, _, _, infos = env.step(dict(zip(live, act)))
            for a, r in rew.items():
                total[a] += r
            for info in infos.values():
                for k, v in info.items():
                    if isinstance(v, int):
                        counts[k] = counts.get(k, 0) + v
        returns.append(float(np.mean(list(total.values()))))
    n = len(seeds) * len(env.possible_agents)
    return {"mean_return": float(np.mean(returns)), **{k: v / n for k, v in counts.items()}}


def main(argv: list[str] | None = None) -> int:
    """Command line: train, save, evaluate, print a summary."""
    p = argparse.ArgumentParser(prog="python -m agentsim_env.train.ppo", description=__doc__.splitlines()[0])
    p.add_argument("scenario")
    p.add_argument("--timesteps", type=int, default=200_000)
    p.add_argument("--worlds", type=int, default=16)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-seeds", type=int, default=10)
    p.add_argument("--out", default=None)
    p.add_argument("--record", default=None, metavar="PATH",
                   help="record the training env to this SQLite store (one run)")  # fmt: skip
    args = p.parse_args(argv)
    from agentsim_env.recorder import StoreError

    try:
        model = train(args.scenario, timesteps=args.timesteps, worlds=args.worlds, seed=args.seed, out=args.out,
                      progress=True, record=args.record)  # fmt: skip
    except StoreError as exc:
        p.error(f"--record {exc}")  # raised before training: a write failing later only stops the recording
    if args.record is not None:
        print(f"training env recorded to {args.record}")
    res = evaluate(model, args.scenario, list(range(1000, 1000 + args.eval_seeds)))
    print("| metric | value |\n|---|---|")
    for k, v in res.items():
        print(f"| {k} | {v:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
