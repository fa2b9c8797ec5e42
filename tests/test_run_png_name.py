"""The name of ``agentsim run``'s trajectory PNG: ``SCENARIO_POLICY_seedSEED[_HASH].png``, HASH from ``--set`` only."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agentsim_env.cli import main


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An untrained PPO saved as ``agentsim train`` saves one, its env config differing from the defaults."""
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("trained") / "mymodel"
    folder.mkdir()
    env = {"n_agents": 3}
    vec = AgentSimVecEnv("navigation", 1, seed=0, **env)
    PPO("MlpPolicy", vec, n_steps=16, batch_size=16, seed=0, device="cpu").save(folder / "model.zip")
    vec.close()
    (folder / "config.json").write_text(json.dumps({"scenario": "navigation", "env": env}))
    return folder


def _pngs(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("*.png"))


def test_a_trained_model_without_set_has_no_hash(model_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "a"
    assert (
        main(
            [
                "run",
                "navigation",
                "--policy",
                str(model_dir),
                "--episodes",
                "1",
                "--quiet",
                "--out",
                str(out),
                "--set",
                "max_steps=20",
            ]
        )
        == 0
    )
    with_set = _pngs(out)
    assert len(with_set) == 1 and with_set[0].startswith("navigation_mymodel_seed0_"), with_set
    out = tmp_path / "b"
    assert main(["run", "navigation", "--policy", str(model_dir), "--episodes", "1", "--quiet", "--out", str(out)]) == 0
    assert _pngs(out) == ["navigation_mymodel_seed0.png"]
