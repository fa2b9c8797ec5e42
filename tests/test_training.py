"""Training: configs, the runner (files, reproducibility, checkpoints and resume), learned policies beside the
baselines, the `agentsim train` command; slow: PPO learns navigation clearly better than the random policy."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")

from agentsim_env.train.config import TrainConfig, load_config, save_config, shipped_configs  # noqa: E402

TINY = {
    "timesteps": 2048,
    "worlds": 2,
    "checkpoint_every": 1024,
    "ppo": {"n_steps": 64, "batch_size": 256},
    "eval": {"seeds": 2},
}


def test_sb3_vecenv_shapes_and_dones() -> None:
    from agentsim_env.env.sb3 import AgentSimVecEnv

    vec = AgentSimVecEnv("navigation", 3, seed=0, n_agents=4, max_steps=20)
    obs = vec.reset()
    assert obs.shape == (12, vec.observation_space.shape[0])
    dones_seen = 0
    for _ in range(45):
        obs, rew, dones, infos = vec.step(np.random.default_rng(0).uniform(-1, 1, (12, 3)))
        assert obs.shape[0] == 12 and rew.shape == (12,) and dones.shape == (12,)
        for d, info in zip(dones, infos):
            if d:
                dones_seen += 1
                assert "terminal_observation" in info
    assert dones_seen >= 12 * 2  # every agent's episode ended at least twice (time limit 20)


# ------------------------------------------------------------------------------------------------ configs
def test_shipped_configs_load_and_round_trip(tmp_path: Path) -> None:
    shipped = shipped_configs()
    assert {"navigation", "relay", "uav_release"} <= set(shipped), shipped
    from agentsim_env.train.curriculum import has_curriculum, load_curriculum

    for name in shipped:
        if has_curriculum(name):  # a curriculum config: its plain data loads again as the same curriculum
            cur = load_curriculum(name)
            assert load_curriculum(yaml.safe_load(yaml.safe_dump(cur.to_dict()))) == cur
            continue
        cfg = load_config(name)
        again = load_config(save_config(cfg, tmp_path / f"{name}.yaml"))
        assert again == cfg
    assert load_config(None, scenario="navigation") == load_config("navigation")


@pytest.mark.parametrize(
    ("overrides", "needle"),
    [
        ({"timestep": 5}, "unknown key timestep"),
        ({"ppo": {"lr": 1e-3}}, "unknown key ppo.lr"),
        ({"eval": {"seed": 3}}, "unknown key eval.seed"),
        ({"timesteps": 0}, "timesteps"),
        ({"timesteps": 1.5}, "timesteps"),
        ({"worlds": 10_000}, "worlds"),
        ({"vec": "dummy"}, "vec must be one of ['native', 'supersuit']"),
        ({"scenario": "nope"}, "scenario must be one of"),
        ({"ppo": {"learning_rate": 0}}, "ppo.learning_rate"),
        ({"ppo": {"gamma": 1.5}}, "ppo.gamma"),
        ({"ppo": {"activation": "gelu"}}, "ppo.activation must be one of ['tanh', 'relu']"),
        ({"ppo": {"net_arch": []}}, "ppo.net_arch"),
        ({"ppo": {"lr_schedule": "cosine"}}, "ppo.lr_schedule"),
        ({"ppo": "fast"}, "ppo must be a mapping"),
        ({"env": {"n_agents": 0}}, "env: "),
        ({"env": {"no_such_key": 1}}, "no_such_key"),
        ({"env": [1, 2]}, "env must be a mapping"),
        ({"eval": {"seeds": 0}}, "eval.seeds"),
        ({"eval": {"env": {"max_steps": -1}}}, "eval.env"),
        ({"checkpoint_every": -1}, "checkpoint_every"),
    ],
)
def test_bad_config_values_are_named(overrides: dict, needle: str) -> None:
    with pytest.raises(ValueError, match=None) as err:
        load_config("navigation", overrides)
    assert needle in str(err.value), str(err.value)


def test_bad_config_files(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("scenario: navigation\nppo: [1, 2\n")
    with pytest.raises(ValueError, match="not valid YAML"):
        load_config(bad)
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(ValueError, match="must hold a mapping"):
        load_config(bad)
    with pytest.raises(ValueError, match="not found; shipped configs"):
        load_config(tmp_path / "missing.yaml")
    with pytest.raises(ValueError, match="is for scenario 'navigation', not 'relay'"):
        load_config("navigation", scenario="relay")


def test_set_pairs_are_typed_by_their_config() -> None:
    from agentsim_env.train.cli import parse_overrides

    got = parse_overrides(
        "relay",
        ["timesteps=5000", "ppo.learning_rate=1e-4", "env.comms.loss=0.5", "env.gap=12,20", "eval.seeds=3"],
    )
    assert got == {
        "timesteps": 5000,
        "ppo": {"learning_rate": 1e-4},
        "eval": {"seeds": 3},
        "env": {"comms": {"loss": 0.5}, "gap": (12.0, 20.0)},
    }
    with pytest.raises(ValueError, match="timesteps"):
        parse_overrides("relay", ["timesteps=2e6"])
    cfg = load_config({"scenario": "relay"}, got)
    assert cfg.env["comms"]["loss"] == 0.5 and cfg.ppo.learning_rate == 1e-4


# ------------------------------------------------------------------------------------------------- runner
def _params(model) -> list[np.ndarray]:  # type: ignore[no-untyped-def]
    return [p.detach().numpy().copy() for p in model.policy.parameters()]


def test_runner_writes_the_run_folder_and_reproduces(tmp_path: Path) -> None:
    from agentsim_env.train.runner import train

    cfg = load_config("navigation", TINY)
    a = train(cfg, tmp_path / "a")
    for name in ("model.zip", "config.json", "config.yaml", "curve.csv", "checkpoints/step_1024.zip"):
        assert (tmp_path / "a" / name).exists(), name
    meta = json.loads((tmp_path / "a" / "config.json").read_text())
    assert meta["scenario"] == "navigation" and meta["timesteps_done"] == 2048 and meta["train"] == cfg.to_dict()
    assert len(a.curve) == 2048 // (64 * 2 * 4) and a.curve[-1]["timesteps"] == 2048
    b = train(cfg, None)
    assert all(np.array_equal(x, y) for x, y in zip(_params(a.model), _params(b.model)))
    c = train(cfg.replace(seed=1), None)
    assert not all(np.array_equal(x, y) for x, y in zip(_params(a.model), _params(c.model)))


def test_resume_continues_from_the_newest_checkpoint(tmp_path: Path) -> None:
    from agentsim_env.train.runner import latest_checkpoint, train

    cfg = load_config("navigation", {**TINY, "timesteps": 1024})
    train(cfg, tmp_path)
    assert latest_checkpoint(tmp_path).name == "step_1024.zip"
    with pytest.raises(ValueError, match=r"differs .* in \['seed'\]"):
        train(cfg.replace(seed=3, timesteps=2048), tmp_path, resume=True)
    res = train(cfg.replace(timesteps=2048), tmp_path, resume=True)
    assert res.timesteps == 2048
    curve = res.curve
    assert [r["timesteps"] for r in curve] == sorted({r["timesteps"] for r in curve})  # no row twice
    assert curve[-1]["timesteps"] == 2048 and curve[-1]["wall_s"] >= curve[0]["wall_s"]
    with pytest.raises(ValueError, match="no checkpoint"):
        train(cfg, tmp_path / "empty", resume=True)


# --------------------------------------------------------------------------------------- learned policies
@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from agentsim_env.train.runner import train

    out = tmp_path_factory.mktemp("model")
    train(load_config("navigation", {**TINY, "env": {"n_agents": 3}, "ppo": {"batch_size": 128}}), out)
    return out


def test_learned_policy_acts_in_dict_and_flat_envs(model_dir: Path) -> None:
    import agentsim_env
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.policies.rollout import run_episode

    for fmt in ("dict", "flat"):
        env = agentsim_env.make("navigation", n_agents=3, obs_format=fmt, action_format=fmt, max_steps=30)
        policy = make_policy("navigation", env, str(model_dir))
        ep = run_episode(env, policy, 0)
        assert ep.steps > 0 and set(ep.returns) == set(env.possible_agents)
    # the Dict observation and its flat twin give the same actions
    d = agentsim_env.make("navigation", n_agents=3)
    f = agentsim_env.make("navigation", n_agents=3, obs_format="flat", action_format="flat")
    od, _ = d.reset(seed=4)
    of, _ = f.reset(seed=4)
    ad = make_policy("navigation", d, str(model_dir / "model.zip")).act(od)
    af = make_policy("navigation", f, str(model_dir)).act(of)
    for a in d.possible_agents:
        np.testing.assert_array_equal(ad[a]["motion"], af[a])


def test_learned_policy_errors(model_dir: Path, tmp_path: Path) -> None:
    import agentsim_env
    from agentsim_env.policies.learned import load_policy

    with pytest.raises(ValueError, match="observations .* build the env with the config"):
        load_policy(model_dir, agentsim_env.make("navigation", n_agents=3, sensing={"n_azimuth": 8}))
    with pytest.raises(ValueError, match="trained on scenario 'navigation', not 'relay'"):
        load_policy(model_dir, agentsim_env.make("relay"))
    with pytest.raises(ValueError, match="has no model.zip"):
        load_policy(tmp_path, agentsim_env.make("navigation"))
    (tmp_path / "x.zip").write_bytes(b"")
    with pytest.raises(ValueError, match="no config.json"):
        load_policy(tmp_path / "x.zip", agentsim_env.make("navigation"))


def test_agentsim_run_takes_a_trained_model(model_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.cli import main

    rc = main(
        [
            "run",
            "navigation",
            "--policy",
            str(model_dir),
            "--episodes",
            "2",
            "--quiet",
            "--out",
            str(tmp_path),
        ]
    )
    assert rc == 0
    out = capsys.readouterr().out
    assert "policy=" in out and "arrived per agent" in out
    assert list(tmp_path.glob(f"navigation_{model_dir.name}_seed0*.png"))
    assert main(["run", "relay", "--policy", str(model_dir), "--quiet", "--out", ""]) == 2
    assert "was trained on 'navigation', not 'relay'" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ command
def test_agentsim_train_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.cli import main
    from agentsim_env.recorder.read import open_store

    out, db = tmp_path / "run", tmp_path / "eval.db"
    args = [
        "train",
        "navigation",
        "--timesteps",
        "1024",
        "--worlds",
        "2",
        "--out",
        str(out),
        "--quiet",
        "--set",
        "eval.seeds=2",
        "checkpoint_every=512",
        "env.n_agents=2",
        "ppo.batch_size=128",
    ]
    assert main(args + ["--record", str(db)]) == 0
    text = capsys.readouterr().out
    assert "| run | learned | 2 |" in text and "| go_to_goal | baseline | 2 |" in text, text
    for name in ("model.zip", "eval.csv", "eval.md", "curve.png", "curve.csv", "checkpoints/step_512.zip"):
        assert (out / name).exists(), name
    assert any((out / "tb").rglob("events.out.tfevents.*"))
    with open_store(db) as st:
        assert len(st.runs()) == 3  # the model and the two navigation baselines
    assert main(args) == 2  # the folder holds a run already
    assert "already holds a run" in capsys.readouterr().err
    assert (
        main(
            [
                "train",
                "navigation",
                "--out",
                str(out),
                "--eval-only",
                "--quiet",
                "--set",
                "eval.seeds=1",
                "env.n_agents=2",
                "eval.baselines=go_to_goal",
            ]
        )
        == 0
    )
    assert "| go_to_goal | baseline | 1 |" in capsys.readouterr().out
    assert main(["train", "navigation", "--set", "ppo.gamma=2", "--out", str(tmp_path / "x")]) == 2
    assert "ppo.gamma" in capsys.readouterr().err and not (tmp_path / "x").exists()
    assert main(["train", "navigation", "--record", str(tmp_path / "no" / "db"), "--out", str(tmp_path / "y")]) == 2
    assert not (tmp_path / "y").exists()


def test_python_m_train_without_rich_shows_progress(tmp_path: Path) -> None:
    # SB3's own progress bar needs `rich`, which is not a dependency: the command must not ask for it
    code = """
import runpy, sys
sys.modules["rich"] = None
sys.argv = ["train", "navigation", "--timesteps", "256", "--worlds", "1", "--out", "run", "--no-eval",
            "--set", "ppo.n_steps=64", "ppo.batch_size=64"]
runpy.run_module("agentsim_env.train", run_name="__main__", alter_sys=True)
"""
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "navigation: 100%" in res.stderr and "256/256" in res.stderr and "return" in res.stderr, res.stderr
    assert (tmp_path / "run" / "model.zip").is_file() and (tmp_path / "run" / "curve.png").is_file()


@pytest.mark.slow
def test_ppo_learns_navigation(tmp_path: Path) -> None:
    from agentsim_env.train.evaluate import evaluate_policies
    from agentsim_env.train.runner import train

    # a small budget with PPOConfig's defaults (the shipped config is tuned for 10M agent-steps). torch's CPU
    # kernels round differently on different CPUs (AVX2 vs AVX-512), so the run is exact on one machine only: at
    # 150,000 agent-steps one machine's policy arrived 0.0 per agent and another's passed; at 250,000 the first
    # arrives 0.35 per agent (350,000: 0.35 too)
    cfg = load_config(
        {
            "scenario": "navigation",
            "timesteps": 250_000,
            "worlds": 16,
            "eval": {"seeds": 10, "baselines": "random"},
        }
    )
    res = train(cfg, tmp_path)
    learned, random_ = evaluate_policies(cfg, res.model)
    assert learned["mean_return"] > random_["mean_return"] + 10.0, (learned, random_)
    assert learned["arrived_per_agent"] >= random_["arrived_per_agent"] + 0.1, (learned, random_)


def test_train_config_defaults_are_valid() -> None:
    assert TrainConfig().scenario == "navigation"
