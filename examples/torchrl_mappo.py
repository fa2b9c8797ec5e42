"""MAPPO on ``navigation`` with TorchRL: a collector, a shared actor, a centralised critic and the clipped PPO loss.

The environment is ``agentsim_env.env.torchrl.torchrl_env``: one group ``"agents"`` of every agent, flat
observations and actions, ``use_mask=True`` (agents that ended are masked) and ``done_on_any=False``. The actor
is one ``MultiAgentMLP`` shared by all agents, acting on each agent's own observation (decentralised); the
critic is a ``MultiAgentMLP`` with ``centralised=True`` (it sees every agent's observation): MAPPO. Rewards and
dones are per agent; agent-steps after an agent ended (mask False) are given zero advantage and their own value
as target, so they do not move the networks.

Run (needs ``pip install "agentsim-env[torchrl]"``)::

    python examples/torchrl_mappo.py --frames 600 --frames-per-batch 200
"""

from __future__ import annotations

import argparse
import inspect
import time

import torch
from tensordict.nn import TensorDictModule
from tensordict.nn.distributions import NormalParamExtractor
from torch import nn
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers.samplers import SamplerWithoutReplacement
from torchrl.envs import RewardSum, TransformedEnv
from torchrl.modules import MultiAgentMLP, ProbabilisticActor, TanhNormal
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from agentsim_env.env.torchrl import GROUP, torchrl_env

try:  # TorchRL >= 0.12 names the single-process collector ``Collector``
    from torchrl.collectors import Collector
except ImportError:  # pragma: no cover - older TorchRL
    from torchrl.collectors import SyncDataCollector as Collector

COLLECTOR_ARGS = inspect.signature(Collector.__init__).parameters


def build(n_agents: int, max_steps: int, seed: int) -> tuple[TransformedEnv, ProbabilisticActor, ClipPPOLoss]:
    """The environment, the shared stochastic actor and the PPO loss with a centralised critic."""
    base = torchrl_env("navigation", seed=seed, n_agents=n_agents, max_steps=max_steps)
    env = TransformedEnv(base, RewardSum(in_keys=[base.reward_key], out_keys=[(GROUP, "episode_reward")]))
    obs_dim = env.observation_spec[GROUP, "observation"].shape[-1]
    act_spec = env.full_action_spec_unbatched[env.action_key]
    act_dim = act_spec.shape[-1]
    actor_net = nn.Sequential(
        MultiAgentMLP(
            obs_dim,
            2 * act_dim,
            n_agents,
            centralised=False,
            share_params=True,
            depth=2,
            num_cells=64,
            activation_class=nn.Tanh,
        ),
        NormalParamExtractor(),
    )
    actor = ProbabilisticActor(
        TensorDictModule(actor_net, in_keys=[(GROUP, "observation")], out_keys=[(GROUP, "loc"), (GROUP, "scale")]),
        spec=env.full_action_spec_unbatched,
        in_keys=[(GROUP, "loc"), (GROUP, "scale")],
        out_keys=[env.action_key],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": act_spec.space.low, "high": act_spec.space.high},
        return_log_prob=True,
    )
    critic_net = MultiAgentMLP(
        obs_dim,
        1,
        n_agents,
        centralised=True,
        share_params=True,
        depth=2,
        num_cells=64,
        activation_class=nn.Tanh,
    )
    critic = TensorDictModule(critic_net, in_keys=[(GROUP, "observation")], out_keys=[(GROUP, "state_value")])
    loss = ClipPPOLoss(actor, critic, clip_epsilon=0.2, entropy_coeff=1e-3, normalize_advantage=False)
    loss.set_keys(
        reward=base.reward_key,
        action=env.action_key,
        value=(GROUP, "state_value"),
        advantage=(GROUP, "advantage"),
        value_target=(GROUP, "value_target"),
        done=(GROUP, "done"),
        terminated=(GROUP, "terminated"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
    return env, actor, loss


def train(frames: int, frames_per_batch: int, n_agents: int, max_steps: int, epochs: int, seed: int) -> None:
    """Collect ``frames`` environment steps in batches and run ``epochs`` PPO epochs on each batch."""
    torch.manual_seed(seed)
    env, actor, loss = build(n_agents, max_steps, seed)
    # the policy needs no environment transform; TorchRL >= 0.14 asks to be told so (a FutureWarning otherwise)
    quiet = {"auto_register_policy_transforms": False} if "auto_register_policy_transforms" in COLLECTOR_ARGS else {}
    collector = Collector(env, actor, frames_per_batch=frames_per_batch, total_frames=frames, **quiet)
    minibatch = max(1, frames_per_batch // 4)
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(frames_per_batch), sampler=SamplerWithoutReplacement(), batch_size=minibatch
    )
    optim = torch.optim.Adam(loss.parameters(), lr=3e-4)
    start = time.perf_counter()
    done_frames = 0
    for it, data in enumerate(collector):
        with torch.no_grad():
            loss.value_estimator(
                data, params=loss.critic_network_params, target_params=loss.target_critic_network_params
            )
            # agent-steps after an agent ended carry no signal: zero advantage, value target = own value
            acted = data[GROUP, "mask"].unsqueeze(-1)
            data[GROUP, "advantage"] = torch.where(acted, data[GROUP, "advantage"], 0.0)
            data[GROUP, "value_target"] = torch.where(acted, data[GROUP, "value_target"], data[GROUP, "state_value"])
        buffer.extend(data.reshape(-1))
        for _ in range(epochs):
            for _ in range(frames_per_batch // minibatch):
                out = loss(buffer.sample())
                total = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
                total.backward()
                torch.nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
                optim.step()
                optim.zero_grad()
        collector.update_policy_weights_()
        done_frames += data.numel()
        acted = data[GROUP, "mask"]
        reward = data["next", GROUP, "reward"].squeeze(-1)[acted].mean().item()
        print(
            f"iteration {it}: {done_frames} frames, {int(data['next', 'done'].sum())} episodes ended, "
            f"mean reward per agent-step {reward:+.4f}, loss {total.item():+.4f}"
        )
    collector.shutdown()
    print(
        f"trained MAPPO on navigation ({n_agents} agents) for {done_frames} frames "
        f"in {time.perf_counter() - start:.1f} s"
    )


def main() -> None:
    """Parse the arguments and train."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=600, help="environment steps in all")
    p.add_argument("--frames-per-batch", type=int, default=200, help="environment steps per PPO iteration")
    p.add_argument("--agents", type=int, default=4)
    p.add_argument("--max-steps", type=int, default=100, help="episode length")
    p.add_argument("--epochs", type=int, default=4, help="PPO epochs per batch")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    train(a.frames, min(a.frames_per_batch, a.frames), a.agents, a.max_steps, a.epochs, a.seed)


if __name__ == "__main__":
    main()
