"""The inbox encoder (``ppo.inbox_encoder``): offsets from the scenario, output shape, invariance to the order of
the inbox rows, empty and invalid rows ignored, and a trained model with it that saves and reloads as a policy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import torch  # noqa: E402
from gymnasium import spaces  # noqa: E402

from agentsim_env.train.config import load_config  # noqa: E402
from agentsim_env.train.inbox_encoder import POOLS, InboxEncoder, inbox_layout  # noqa: E402

TINY_RELAY = {
    "scenario": "relay",
    "timesteps": 256,
    "worlds": 2,
    "checkpoint_every": 0,
    "env": {"n_groups": 1, "group_size": 2, "obstacle_density": 0.0, "max_steps": 30},
    "ppo": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
    "eval": {"seeds": 1, "baselines": "none"},
}


def test_layout_comes_from_the_scenario() -> None:
    lay = inbox_layout("relay", {"comms": {"inbox_size": 3, "payload_dim": 2}})
    assert (lay.rows, lay.features) == (3, 13)
    import agentsim_env

    env = agentsim_env.make("relay", comms={"inbox_size": 3, "payload_dim": 2}, obs_format="flat")
    dict_env = agentsim_env.make("relay", comms={"inbox_size": 3, "payload_dim": 2})
    flat, _ = env.reset(seed=1)
    parts, _ = dict_env.reset(seed=1)
    a = env.possible_agents[0]
    assert flat[a].shape == (lay.obs_size,)
    np.testing.assert_array_equal(flat[a][lay.start : lay.start + 3 * 13], parts[a]["inbox"].ravel())
    with pytest.raises(ValueError, match="has no inbox"):
        inbox_layout("navigation", {})
    with pytest.raises(ValueError, match="ppo.inbox_encoder 'mean' needs an inbox"):
        load_config("navigation", {"ppo": {"inbox_encoder": "mean"}})
    with pytest.raises(ValueError, match="ppo.inbox_encoder must be one of"):
        load_config("relay", {"ppo": {"inbox_encoder": "sum"}})


def _encoder(pool: str) -> tuple[InboxEncoder, int, int, int, int]:
    lay = inbox_layout("relay", {})
    space = spaces.Box(-10.0, 10.0, (lay.obs_size,), np.float32)
    torch.manual_seed(0)
    enc = InboxEncoder(space, lay.start, lay.rows, lay.features, pool=pool, hidden=16)
    if pool == "attention":  # a query away from zero, so the weights are not uniform
        with torch.no_grad():
            enc.query.normal_()
    return enc, lay.start, lay.rows, lay.features, lay.obs_size


def _obs(rng: np.random.Generator, start: int, rows: int, feats: int, size: int, n_valid: int) -> np.ndarray:
    obs = rng.normal(size=(5, size)).astype(np.float32)
    inbox = obs[:, start : start + rows * feats].reshape(5, rows, feats)
    inbox[:, :, 0] = 0.0
    inbox[:, :n_valid, 0] = 1.0
    return obs


@pytest.mark.parametrize("pool", POOLS)
def test_shape_and_invariance_to_row_order(pool: str) -> None:
    enc, start, rows, feats, size = _encoder(pool)
    assert enc.features_dim == size - rows * feats + 16
    rng = np.random.default_rng(3)
    obs = _obs(rng, start, rows, feats, size, n_valid=5)
    out = enc(torch.as_tensor(obs))
    assert out.shape == (5, enc.features_dim)
    # the observation without the inbox passes through unchanged, in order
    rest = np.concatenate([obs[:, :start], obs[:, start + rows * feats :]], axis=1)
    np.testing.assert_array_equal(out[:, : rest.shape[1]].detach().numpy(), rest)
    # any order of the rows gives the same code
    perm = rng.permutation(rows)
    shuffled = obs.copy()
    block = shuffled[:, start : start + rows * feats].reshape(5, rows, feats)
    shuffled[:, start : start + rows * feats] = block[:, perm].reshape(5, -1)
    np.testing.assert_allclose(enc(torch.as_tensor(shuffled)).detach().numpy(), out.detach().numpy(), atol=1e-5)
    # what an invalid row holds does not matter
    noisy = obs.copy()
    noisy[:, start + 7 * feats + 1 : start + 8 * feats] += 5.0  # row 7 is not valid
    np.testing.assert_allclose(enc(torch.as_tensor(noisy)).detach().numpy(), out.detach().numpy(), atol=1e-6)
    # but a valid row does
    noisy[:, start + 1 : start + feats] += 5.0
    assert not np.allclose(enc(torch.as_tensor(noisy)).detach().numpy(), out.detach().numpy(), atol=1e-3)
    # an empty inbox gives a zero code
    empty = _obs(rng, start, rows, feats, size, n_valid=0)
    code = enc(torch.as_tensor(empty))[:, -16:].detach().numpy()
    assert np.isfinite(code).all() and np.allclose(code, 0.0)


def test_bad_encoder_arguments() -> None:
    space = spaces.Box(-1.0, 1.0, (20,), np.float32)
    with pytest.raises(ValueError, match="does not fit"):
        InboxEncoder(space, 10, 2, 6)
    with pytest.raises(ValueError, match="pool must be one of"):
        InboxEncoder(space, 0, 2, 5, pool="sum")


def test_default_keeps_the_plain_network(tmp_path: Path) -> None:
    from stable_baselines3.common.torch_layers import FlattenExtractor

    from agentsim_env.train.runner import make_model, make_vec_env

    cfg = load_config(TINY_RELAY)
    assert cfg.ppo.inbox_encoder == "none"
    vec = make_vec_env(cfg)
    model = make_model(cfg, vec)
    vec.close()
    assert isinstance(model.policy.features_extractor, FlattenExtractor)
    assert "features_extractor_class" not in model.policy_kwargs


@pytest.mark.parametrize("pool", ["max", "attention"])
def test_model_with_the_encoder_saves_and_reloads(pool: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import agentsim_env
    from agentsim_env.cli import main
    from agentsim_env.policies.learned import load_policy
    from agentsim_env.train.evaluate import evaluate_policies
    from agentsim_env.train.runner import train

    cfg = load_config({**TINY_RELAY, "ppo": {**TINY_RELAY["ppo"], "inbox_encoder": pool, "inbox_hidden": 8}})
    res = train(cfg, tmp_path / "run")
    assert isinstance(res.model.policy.features_extractor, InboxEncoder)
    env = agentsim_env.make("relay", **cfg.env, obs_format="flat", action_format="flat")
    policy = load_policy(tmp_path / "run", env)
    loaded = policy.model.policy.features_extractor
    assert isinstance(loaded, InboxEncoder) and loaded.pool == pool
    for a, b in zip(res.model.policy.state_dict().values(), policy.model.policy.state_dict().values()):
        assert torch.equal(a, b)
    obs, _ = env.reset(seed=2)
    batch = np.stack([obs[a] for a in env.agents])
    want, _ = res.model.predict(batch, deterministic=True)
    got = policy.act(obs)
    np.testing.assert_allclose(np.stack([got[a] for a in env.agents]), np.clip(want, -1, 1), atol=1e-6)
    rows = evaluate_policies(cfg, tmp_path / "run")  # the evaluate path loads it from the folder
    assert rows[0]["kind"] == "learned" and rows[0]["episodes"] == 1
    rc = main(["run", "relay", "--policy", str(tmp_path / "run"), "--episodes", "1", "--quiet", "--out", ""])
    assert rc == 0, capsys.readouterr().err
