"""Train one PPO policy shared by every agent of ``navigation`` through SuperSuit and stable-baselines3.

The PettingZoo tutorial path: the ParallelEnv with flat observations and actions, SuperSuit's ``black_death``
(agents that ended observe zeros until their episode is over), ``pettingzoo_env_to_vec_env_v1`` (one vec-env
entry per agent, so one network serves all agents: parameter sharing) and ``concat_vec_envs_v1`` (several copies
side by side). ``agentsim_env.env.supersuit.supersuit_vec_env`` builds that chain and makes ``PPO(seed=...)``
reproducible. The model is saved, loaded back and evaluated in the plain ParallelEnv on a few seeds.

Run (needs ``pip install "agentsim-env[train]"``)::

    python examples/supersuit_sb3.py --timesteps 200000 --envs 8 --episodes 5 --out outputs/supersuit_sb3
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor

import agentsim_env
from agentsim_env.env.supersuit import supersuit_vec_env


def train(timesteps: int, envs: int, agents: int, seed: int, out: Path) -> Path:
    """Train PPO on ``envs`` copies of ``navigation`` with ``agents`` agents each; return the saved model's path."""
    venv = VecMonitor(supersuit_vec_env("navigation", envs, seed=seed, n_agents=agents))
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=256, seed=seed, device="cpu", verbose=0)
    model.learn(total_timesteps=timesteps)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "model.zip"
    model.save(path)
    venv.close()
    return path


def evaluate(path: Path, agents: int, seeds: list[int]) -> list[dict[str, float]]:
    """Roll the saved policy out deterministically, one episode per seed; one result row per episode."""
    model = PPO.load(path, device="cpu")
    env = agentsim_env.make("navigation", n_agents=agents, obs_format="flat", action_format="flat")
    rows = []
    for s in seeds:
        obs, _ = env.reset(seed=s)
        ret = dict.fromkeys(env.possible_agents, 0.0)
        arrived = collided = steps = 0
        while env.agents:
            live = list(env.agents)
            act, _ = model.predict(np.stack([obs[a] for a in live]), deterministic=True)
            obs, rew, _, _, infos = env.step(dict(zip(live, act)))
            steps += 1
            for a in live:
                ret[a] += rew[a]
                arrived += int(infos[a]["arrived"])
                collided += int(infos[a]["collided"])
        rows.append(
            {
                "seed": s,
                "mean return": float(np.mean(list(ret.values()))),
                "arrived": arrived,
                "collided": collided,
                "steps": steps,
            }
        )
    env.close()
    return rows


def table(rows: list[dict[str, float]], agents: int) -> str:
    """The evaluation as a Markdown table, with a mean row."""
    lines = ["| seed | mean return | arrived | collided | steps |", "|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['seed']} | {r['mean return']:.2f} | {r['arrived']}/{agents} | {r['collided']}/{agents} | "
            f"{r['steps']} |"
        )
    mean = {k: float(np.mean([r[k] for r in rows])) for k in ("mean return", "arrived", "collided", "steps")}
    lines.append(
        f"| mean | {mean['mean return']:.2f} | {mean['arrived']:.2f}/{agents} | "
        f"{mean['collided']:.2f}/{agents} | {mean['steps']:.0f} |"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Train, save, evaluate, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timesteps", type=int, default=200_000, help="agent-steps to train (all agents of all copies)")
    ap.add_argument("--envs", type=int, default=8, help="copies of the ParallelEnv")
    ap.add_argument("--agents", type=int, default=4, help="agents per copy")
    ap.add_argument("--episodes", type=int, default=5, help="evaluation episodes (seeds 1000, 1001, ...)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("outputs/supersuit_sb3"))
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    path = train(args.timesteps, args.envs, args.agents, args.seed, args.out)
    print(f"saved {path}")
    rows = evaluate(path, args.agents, [1000 + i for i in range(args.episodes)])
    print(table(rows, args.agents))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
