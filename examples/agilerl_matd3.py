"""AgileRL's MATD3 with evolutionary hyperparameter optimisation on ``navigation``: a population of MATD3 agents
sharing one replay buffer over vectorised ParallelEnvs, trained by ``train_multi_agent_off_policy`` with
tournament selection and mutations.

This is AgileRL's multi-agent off-policy recipe (its "Multi-Agent Training" guide and MATD3 Speaker-Listener
tutorial: ``AsyncPettingZooVecEnv``, ``create_population``, ``HyperparameterConfig``, a shared replay buffer,
``TournamentSelection``, ``Mutations``, ``train_multi_agent_off_policy``) with the environment line changed:
``agentsim_env.make("navigation", obs_format="flat", action_format="flat", ended_agents="stay")``. With
PettingZoo's default an agent that ended leaves the dicts and AgileRL's vector env fills its observations and
rewards with NaN until the copy resets: 2.58's trainer counts those rewards as 0, but a custom loop as in the
tutorial sums them into NaN scores, and the agent's observations in the transitions are NaN placeholders.
With ``"stay"`` an ended agent observes zeros with reward 0 until the episode ends.

What AgileRL 2.58 itself needs, against its own tutorial:

- ``MultiAgentReplayBuffer`` is gone (``agilerl.components.multi_agent_replay_buffer`` and the name in
  ``agilerl.components.replay_buffer``): the multi-agent trainer takes the plain ``ReplayBuffer(max_size,
  device=...)`` and stores ``MultiAgentTransition`` tensordicts in it.
- ``create_population`` takes ``(algo, net_config, INIT_HP, observation_space=..., action_space=...,
  hp_config=...)``; the tutorial's positional ``(algo, observation_spaces, action_spaces, NET_CONFIG, INIT_HP,
  hp_config)`` binds the spaces to the wrong parameters, so every argument is passed by name here.
- ``train_multi_agent_off_policy`` takes ``init_hp=`` (not ``INIT_HP=``) and no ``net_config=``.
- ``num_envs`` must reach ``create_population``: it becomes MATD3's ``vect_noise_dim``, the number of rows of
  Ornstein-Uhlenbeck noise; left at its default of 1 the noise has one row for ``num_envs`` observations.
- ``create_population`` and the ``tournament=`` argument still work in 2.58 but warn that they are deprecated
  (``MATD3.population(...)`` and ``selection_strategy=`` replace them); the tutorial's calls are kept.
- ``import agilerl.algorithms`` imports ``peft`` (an LLM dependency that AgileRL does not install), so the
  ``agilerl`` extra adds it.

Run (its own environment: ``pip install "agentsim-env[agilerl]"``)::

    python examples/agilerl_matd3.py --frames 400 --envs 2 --out outputs/agilerl
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from agilerl.algorithms.core.registry import HyperparameterConfig, RLParameter
from agilerl.components.replay_buffer import ReplayBuffer
from agilerl.hpo.mutation import Mutations
from agilerl.hpo.tournament import TournamentSelection
from agilerl.training.train_multi_agent_off_policy import train_multi_agent_off_policy
from agilerl.utils.utils import create_population
from agilerl.vector.pz_async_vec_env import AsyncPettingZooVecEnv

import agentsim_env


def make_env(agents: int, max_steps: int) -> Any:
    """One ``navigation`` ParallelEnv with flat spaces, ended agents kept until the episode ends."""
    return agentsim_env.make(
        "navigation",
        n_agents=agents,
        max_steps=max_steps,
        obs_format="flat",
        action_format="flat",
        ended_agents="stay",
    )


def train(frames: int, envs: int, agents: int, max_steps: int, pop_size: int, seed: int, out: Path) -> None:
    """Train a population of ``pop_size`` MATD3 agents for ``frames`` environment steps (all copies)."""
    torch.manual_seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - AgileRL's tournament selection draws from NumPy's global generator
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")

    net_config = {"encoder_config": {"hidden_size": [64, 64]}, "head_config": {"hidden_size": [64]}}
    init_hp: dict[str, Any] = {
        "POP_SIZE": pop_size,  # population size
        "ALGO": "MATD3",
        "BATCH_SIZE": 64,  # batch size
        "O_U_NOISE": True,  # Ornstein-Uhlenbeck action noise
        "EXPL_NOISE": 0.1,  # action noise scale
        "MEAN_NOISE": 0.0,  # mean action noise
        "THETA": 0.15,  # rate of mean reversion in OU noise
        "DT": 0.01,  # timestep for OU noise
        "LR_ACTOR": 1e-3,  # actor learning rate
        "LR_CRITIC": 1e-3,  # critic learning rate
        "GAMMA": 0.95,  # discount factor
        "MEMORY_SIZE": 100_000,  # replay buffer size
        "LEARN_STEP": 100,  # learning frequency (steps of all copies)
        "TAU": 0.01,  # soft update of the target networks
        "POLICY_FREQ": 2,  # policy update frequency
    }

    # the only environment-specific line: AgileRL vectorises the ParallelEnv in worker processes
    env = AsyncPettingZooVecEnv([lambda: make_env(agents, max_steps) for _ in range(envs)])
    env.reset(seed=seed)
    observation_spaces = [env.single_observation_space(agent) for agent in env.agents]
    action_spaces = [env.single_action_space(agent) for agent in env.agents]
    init_hp["AGENT_IDS"] = env.agents

    hp_config = HyperparameterConfig(
        lr_actor=RLParameter(min=1e-4, max=1e-2),
        lr_critic=RLParameter(min=1e-4, max=1e-2),
        batch_size=RLParameter(min=8, max=512, dtype=int),
        learn_step=RLParameter(min=20, max=200, dtype=int, grow_factor=1.5, shrink_factor=0.75),
    )
    # AgileRL 2.58: keywords (its positional order differs from the tutorial's); num_envs -> vect_noise_dim
    pop = create_population(
        algo=init_hp["ALGO"],
        net_config=net_config,
        INIT_HP=init_hp,
        observation_space=observation_spaces,
        action_space=action_spaces,
        hp_config=hp_config,
        population_size=init_hp["POP_SIZE"],
        num_envs=envs,
        device=str(device),
    )
    memory = ReplayBuffer(max_size=init_hp["MEMORY_SIZE"], device=device)
    tournament = TournamentSelection(tournament_size=2, elitism=True, population_size=init_hp["POP_SIZE"])
    mutations = Mutations(
        no_mutation=0.2,  # probability of no mutation
        architecture=0.2,  # probability of an architecture mutation
        new_layer_prob=0.2,  # probability of a new layer
        parameters=0.2,  # probability of a parameter mutation
        activation=0,  # probability of an activation function mutation
        rl_hp=0.2,  # probability of an RL hyperparameter mutation
        mutation_sd=0.1,  # mutation strength
        rand_seed=seed,
        device=str(device),
    )

    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    # AgileRL 2.58: init_hp= (the tutorial's INIT_HP= and net_config= are refused)
    trained_pop, fitnesses = train_multi_agent_off_policy(
        env=env,
        env_name="agentsim_navigation",
        algo=init_hp["ALGO"],
        pop=pop,
        memory=memory,
        init_hp=init_hp,
        max_steps=frames,
        evo_steps=min(frames, 10_000),  # evolution frequency
        eval_steps=None,  # evaluate until the episodes end
        eval_loop=1,  # evaluation episodes
        learning_delay=0,
        tournament=tournament,
        mutation=mutations,
        wb=False,
        verbose=False,
    )
    elite = trained_pop[0]
    elite.save_checkpoint(str(out / "MATD3_elite.pt"))
    env.close()
    last = [float(np.asarray(f[-1] if isinstance(f, list | tuple) else f).mean()) for f in fitnesses]
    if not np.all(np.isfinite(last)):
        raise SystemExit(f"non-finite fitness {last}: episode scores should be finite with ended_agents='stay'")
    print(
        f"trained AgileRL MATD3 (population {pop_size}) on navigation ({agents} agents, {envs} copies) for "
        f"{frames} frames in {time.perf_counter() - start:.1f} s; fitnesses {np.round(last, 2).tolist()}; "
        f"elite saved to {out / 'MATD3_elite.pt'}"
    )


def main() -> None:
    """Parse the arguments and train."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=200_000, help="environment steps in all (every copy)")
    p.add_argument("--envs", type=int, default=8, help="vectorised copies (worker processes)")
    p.add_argument("--agents", type=int, default=4)
    p.add_argument("--max-steps", type=int, default=100, help="episode length")
    p.add_argument("--population", type=int, default=4, help="agents in the evolving population")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("outputs/agilerl"), help="where the elite is saved")
    a = p.parse_args()
    train(a.frames, a.envs, a.agents, a.max_steps, a.population, a.seed, a.out)


if __name__ == "__main__":
    main()
