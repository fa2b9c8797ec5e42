"""``agentsim train --eval-baselines none|default|all``: how many baselines the final evaluation plays, and
the output says what the evaluation costs (episodes, an estimate, the time taken)."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from agentsim_env.cli import main  # noqa: E402
from agentsim_env.train.config import load_config  # noqa: E402
from agentsim_env.train.evaluate import baselines_of  # noqa: E402

ENV = {"n_agents": 3, "max_steps": 30}


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An untrained PPO saved as ``agentsim train`` saves one."""
    import torch
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("run") / "nav"
    folder.mkdir()
    vec = AgentSimVecEnv("navigation", 1, seed=0, **ENV)
    PPO("MlpPolicy", vec, n_steps=16, batch_size=16, seed=0, device="cpu").save(folder / "model.zip")
    vec.close()
    (folder / "config.json").write_text(json.dumps({"scenario": "navigation", "env": ENV}))
    return folder


def test_default_is_the_scenarios_default_baseline() -> None:
    pick = {b: baselines_of(load_config("navigation", {"eval": {"baselines": b}})) for b in ("none", "default", "all")}
    assert pick == {"none": [], "default": ["go_to_goal"], "all": ["go_to_goal", "random"]}


@pytest.mark.parametrize(("profile", "policies"), [("none", ["nav"]), ("default", ["nav", "go_to_goal"])])
def test_eval_baselines_flag_and_the_cost_line(
    model_dir: Path, capsys: pytest.CaptureFixture[str], profile: str, policies: list[str]
) -> None:
    argv = [
        "train",
        "navigation",
        "--out",
        str(model_dir),
        "--eval-only",
        "--quiet",
        "--eval-baselines",
        profile,
        "--set",
        "eval.seeds=2",
        *[f"env.{k}={v}" for k, v in ENV.items()],
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    with open(model_dir / "eval.csv", encoding="utf-8") as f:
        assert [r["policy"] for r in csv.DictReader(f)] == policies
    n = len(policies) - 1
    head = f"evaluating the model and {n} baseline{'' if n == 1 else 's'} (--eval-baselines {profile}) x 2 seeds"
    assert head + f" = {2 * len(policies)} episodes" in out, out
    assert re.search(r"~\d+(\.\d)? s in all at the first episode's pace", out), out
    assert re.search(rf"evaluation: {2 * len(policies)} episodes in \d+\.\d s", out), out


def test_a_bad_profile_is_one_error(model_dir: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["train", "navigation", "--out", str(model_dir), "--eval-only", "--eval-baselines", "some"])
    assert info.value.code == 2
    assert "--eval-baselines: invalid choice: 'some'" in capsys.readouterr().err
