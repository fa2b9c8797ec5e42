"""skrl's MAPPO on ``navigation`` through skrl's own PettingZoo wrapper: a Gaussian policy per agent acting on its
own observation, a value model per agent on the global state (``env.state()``), skrl's ``SequentialTrainer``.

This is skrl's multi-agent recipe (``wrap_env(env, wrapper="pettingzoo")``, ``RandomMemory`` per agent,
``MAPPO_CFG``, ``MAPPO(possible_agents=..., models=..., memories=..., observation_spaces=...,
state_spaces=..., action_spaces=...)``, ``SequentialTrainer(cfg={"timesteps": ..., "headless": True})``) with
the environment line changed. What the environment needs from skrl's side and what skrl needs from it:

- ``ended_agents="stay"``: skrl's trainer records a transition for every possible agent each step and resets
  the environment only when ``env.agents`` is empty; with PettingZoo's default (an agent that ended leaves
  the dicts) MAPPO raises ``KeyError`` on the first agent that arrives or collides. With ``"stay"`` an ended
  agent keeps observing zeros with reward 0 until the episode ends.
- The wrapper reads the ParallelEnv's public ``observation_spaces`` / ``action_spaces`` dicts and its
  ``state_space`` / ``state()`` (the global state for the centralised value).
- skrl 2.1.1's per-agent keyword arguments: ``MAPPO_CFG`` expands every setting to one per agent, but an empty
  dict (the default of ``learning_rate_scheduler_kwargs``, ``*_preprocessor_kwargs``) is read as a per-agent
  mapping that names no agent and raises ``ValueError: Specified keys (set()) do not match possible agents``;
  each of those is given as ``{agent: {} for agent in possible_agents}`` here.

Run (its own environment: ``pip install "agentsim-env[skrl]"``)::

    python examples/skrl_mappo.py --frames 400 --rollouts 100 --out outputs/skrl
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import torch
from skrl.envs.wrappers.torch import wrap_env
from skrl.memories.torch import RandomMemory
from skrl.models.torch import DeterministicMixin, GaussianMixin, Model
from skrl.multi_agents.torch.mappo import MAPPO, MAPPO_CFG
from skrl.trainers.torch import SequentialTrainer
from skrl.utils import set_seed
from torch import nn

import agentsim_env


class Policy(GaussianMixin, Model):
    """A Gaussian policy on the agent's own observation, with a state-independent log-std."""

    def __init__(self, observation_space: Any, action_space: Any, device: Any) -> None:
        Model.__init__(self, observation_space=observation_space, action_space=action_space, device=device)
        GaussianMixin.__init__(self, clip_actions=True, clip_log_std=True, min_log_std=-20, max_log_std=2)
        self.net = nn.Sequential(
            nn.Linear(self.num_observations, 64),
            nn.ELU(),
            nn.Linear(64, 64),
            nn.ELU(),
            nn.Linear(64, self.num_actions),
        )
        self.log_std_parameter = nn.Parameter(torch.zeros(self.num_actions))

    def compute(self, inputs: dict[str, Any], role: str = "") -> tuple[torch.Tensor, dict[str, Any]]:
        """Mean action and log-std for ``inputs["observations"]``."""
        return self.net(inputs["observations"]), {"log_std": self.log_std_parameter}


class Value(DeterministicMixin, Model):
    """A value model on the global state (centralised critic: MAPPO)."""

    def __init__(self, state_space: Any, action_space: Any, device: Any) -> None:
        Model.__init__(self, state_space=state_space, action_space=action_space, device=device)
        DeterministicMixin.__init__(self, clip_actions=False)
        self.net = nn.Sequential(
            nn.Linear(self.num_states, 64), nn.ELU(), nn.Linear(64, 64), nn.ELU(), nn.Linear(64, 1)
        )

    def compute(self, inputs: dict[str, Any], role: str = "") -> tuple[torch.Tensor, dict[str, Any]]:
        """The value of ``inputs["states"]``."""
        return self.net(inputs["states"]), {}


def train(frames: int, rollouts: int, agents: int, max_steps: int, seed: int, out: str) -> None:
    """Train MAPPO for ``frames`` environment steps, updating every ``rollouts`` steps."""
    set_seed(seed)
    env = agentsim_env.make(
        "navigation",
        n_agents=agents,
        max_steps=max_steps,
        obs_format="flat",
        action_format="flat",
        ended_agents="stay",
    )
    env = wrap_env(env, wrapper="pettingzoo")
    device = env.device

    memories = {
        name: RandomMemory(memory_size=rollouts, num_envs=env.num_envs, device=device) for name in env.possible_agents
    }
    models = {
        name: {
            "policy": Policy(env.observation_space(name), env.action_space(name), device),
            "value": Value(env.state_space(name), env.action_space(name), device),
        }
        for name in env.possible_agents
    }

    # skrl 2.1.1: an empty kwargs dict must be given per agent (see the module docstring)
    per_agent: dict[str, Any] = {name: {} for name in env.possible_agents}
    cfg = MAPPO_CFG(
        rollouts=rollouts,
        learning_epochs=4,
        mini_batches=4,
        discount_factor=0.99,
        gae_lambda=0.95,
        learning_rate=3e-4,
        learning_rate_scheduler_kwargs=dict(per_agent),
        observation_preprocessor_kwargs=dict(per_agent),
        state_preprocessor_kwargs=dict(per_agent),
        value_preprocessor_kwargs=dict(per_agent),
        grad_norm_clip=1.0,
        entropy_loss_scale=1e-3,
    )
    cfg.experiment.directory = out
    cfg.experiment.write_interval = max(1, frames // 4)
    cfg.experiment.checkpoint_interval = frames

    agent = MAPPO(
        possible_agents=env.possible_agents,
        models=models,
        memories=memories,
        cfg=cfg,
        observation_spaces=env.observation_spaces,
        state_spaces=env.state_spaces,
        action_spaces=env.action_spaces,
        device=device,
    )
    trainer = SequentialTrainer(
        cfg={"timesteps": frames, "headless": True, "disable_progressbar": True}, env=env, agents=agent
    )
    start = time.perf_counter()
    trainer.train()
    print(
        f"trained skrl MAPPO on navigation ({agents} agents) for {frames} frames "
        f"in {time.perf_counter() - start:.1f} s; experiment under {out}"
    )


def main() -> None:
    """Parse the arguments and train."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=20_000, help="environment steps in all")
    p.add_argument("--rollouts", type=int, default=256, help="environment steps per MAPPO update")
    p.add_argument("--agents", type=int, default=4)
    p.add_argument("--max-steps", type=int, default=100, help="episode length")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="outputs/skrl", help="skrl's experiment folder (TensorBoard, checkpoints)")
    a = p.parse_args()
    train(a.frames, min(a.rollouts, a.frames), a.agents, a.max_steps, a.seed, a.out)


if __name__ == "__main__":
    main()
