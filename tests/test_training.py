"""End-to-end training: PPO with parameter sharing over the batched env learns navigation (slow)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")


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


@pytest.mark.slow
def test_ppo_learns_navigation(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv
    from agentsim_env.train.ppo import evaluate, train

    model = train("navigation", timesteps=60_000, worlds=16, seed=0, out=tmp_path)
    assert (tmp_path / "model.zip").exists() and (tmp_path / "config.json").exists()
    trained = evaluate(model, "navigation", list(range(100, 110)))
    untrained = evaluate(PPO("MlpPolicy", AgentSimVecEnv("navigation", 1), seed=0, device="cpu"), "navigation",
                         list(range(100, 110)))  # fmt: skip
    assert trained["mean_return"] > untrained["mean_return"] + 10.0, (trained, untrained)


def test_training_entry_point_without_rich_shows_progress(tmp_path: Path) -> None:
    # SB3's own progress bar needs `rich`, which is not a dependency: the command line must not ask for it
    code = """
import runpy, sys
sys.modules["rich"] = None
sys.argv = ["ppo", "navigation", "--timesteps", "64", "--worlds", "1", "--eval-seeds", "1", "--out", "run"]
runpy.run_module("agentsim_env.train.ppo", run_name="__main__", alter_sys=True)
"""
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "navigation: 100%" in res.stderr and "64/64" in res.stderr, res.stderr
    assert "| mean_return |" in res.stdout
    assert (tmp_path / "run" / "model.zip").is_file()
