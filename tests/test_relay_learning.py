"""The learnable ``relay`` setting of ``train/configs/relay.yaml``, its channel-cut twin and the comm-traffic plot.

``relay.yaml`` trains PPO with the ``comm`` action; ``relay_nocomm.yaml`` is the same run with communication made
impossible (``comms: {loss: 1.0, overlay_range: 1e-3}``: the bus loses every message, the overlay reaches
nobody). These tests check the pair is what it claims: twins apart from the cut, a setting in which messages carry
the target (the scripted flood succeeds with the channel and falls to the silent level without it), and the
plotting helper's outputs. Training itself is not run here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

import agentsim_env
from agentsim_env.comms.stack import CHANNELS, COMM_HEADER
from agentsim_env.policies.registry import make_policy
from agentsim_env.policies.rollout import run_episode
from agentsim_env.train.comm_plot import plot_comm_traffic, record_comm_traffic
from agentsim_env.train.config import load_config

CONFIGS = Path(__file__).resolve().parents[1] / "train" / "configs"
CUT = {"loss": 1.0, "overlay_range": 1e-3}
SEEDS = range(1000, 1012)


def _yaml(name: str) -> dict[str, Any]:
    return yaml.safe_load((CONFIGS / f"{name}.yaml").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def envs() -> tuple[dict[str, Any], dict[str, Any]]:
    return _yaml("relay")["env"], _yaml("relay_nocomm")["env"]


def _episodes(policy: str, env_cfg: dict[str, Any], seeds: range = SEEDS) -> int:
    """Episodes in which every group's non-scouts all reached the target."""
    env = agentsim_env.make("relay", **env_cfg)
    pol = make_policy("relay", env, policy)
    wins = 0
    for seed in seeds:
        run_episode(env, pol, seed)
        wins += bool(env.scenario.group_success(env.world, fraction=1.0).all())
    return wins


def test_the_two_configs_are_twins_apart_from_the_cut() -> None:
    comm, cut = _yaml("relay"), _yaml("relay_nocomm")
    for key in set(comm) | set(cut):
        if key != "env":
            assert comm.get(key) == cut.get(key), key
    env, env_cut = dict(comm["env"]), dict(cut["env"])
    comms, comms_cut = dict(env.pop("comms", {})), dict(env_cut.pop("comms", {}))
    assert env == env_cut
    assert comms_cut == {**comms, **CUT}
    for cfg in (comm, cut):  # the runner's loader accepts both
        assert load_config(cfg).scenario == "relay"


def test_cut_silences_the_channel(envs: tuple[dict[str, Any], dict[str, Any]]) -> None:
    """With the cut nothing reaches an inbox from another agent, whatever is sent."""
    _, env_cut = envs
    env = agentsim_env.make("relay", **env_cut)
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        acts = {}
        for k, a in enumerate(env.agents):
            comm = np.zeros(COMM_HEADER + env.scenario.config.comms.payload_dim, dtype=np.float32)
            comm[0] = -1.0 + (2 * (1 + k % 4) + 1) / len(CHANNELS)  # group, nearest, named, overlay in turn
            comm[3:] = 0.5
            acts[a] = {"motion": np.zeros(3, dtype=np.float32), "comm": comm}
        obs, *_ = env.step(acts)
        if not env.agents:
            break
        assert not any(o["inbox"][:, 0].any() for o in obs.values())


def test_messages_carry_the_target_only_with_the_channel(envs: tuple[dict[str, Any], dict[str, Any]]) -> None:
    env, env_cut = envs
    flood, flood_cut, silent = (
        _episodes("flood", env),
        _episodes("flood", env_cut),
        _episodes("silent", env_cut),
    )
    assert flood >= 0.8 * len(SEEDS), f"flood reached the target in {flood}/{len(SEEDS)} episodes"
    assert flood_cut <= silent, f"flood with the channel cut {flood_cut} vs silent {silent}"


def _flat_offsets(env_cfg: dict[str, Any]) -> tuple[int, int]:
    """(start of the task part in the flat observation, start of the comm part in the flat action)."""
    c = agentsim_env.make("relay", **env_cfg).scenario.config
    return 9 + 2 * c.sensing.n_azimuth * len(c.sensing.elevations_deg), 3


def test_comm_traffic_tells_an_encoding_payload_from_a_constant(
    envs: tuple[dict[str, Any], dict[str, Any]], tmp_path: Path
) -> None:
    env, _ = envs
    task, comm = _flat_offsets(env)
    d = agentsim_env.make("relay", **env).scenario.config.comms.payload_dim

    def speaker(encode: bool) -> Any:
        def act(obs: np.ndarray) -> np.ndarray:
            a = np.zeros((len(obs), comm + COMM_HEADER + d), dtype=np.float32)
            a[:, comm] = 0.9  # overlay
            a[:, comm + COMM_HEADER : comm + COMM_HEADER + 2] = 4.0 * obs[:, task + 1 : task + 3] if encode else 0.3
            return a

        return act

    rec = record_comm_traffic(speaker(True), env, range(2))
    assert rec.sent.sum() == len(rec.sent)  # every live agent sent a message every step
    assert np.all(rec.channel == CHANNELS.index("overlay"))
    assert rec.decoding_r2() > 0.95
    assert record_comm_traffic(speaker(False), env, range(2)).decoding_r2() < 0.05
    png = plot_comm_traffic(speaker(True), env, range(2), tmp_path / "traffic.png", title="t")
    assert png.is_file() and png.stat().st_size > 1000
