"""Curriculum training (``agentsim_env.train.curriculum``): the config's checks, the promotion rule, the state file
and resume (an interrupted run resumed ends where the uninterrupted one does, weights included), the command;
slow: a tiny run of ``agentsim train --config`` that promotes."""

from __future__ import annotations

import copy
import json
import os
from pathlib import Path
from typing import Any

import pytest
import yaml

pytest.importorskip("stable_baselines3")

from agentsim_env.train.curriculum import (  # noqa: E402
    STATE_FILE,
    fresh_state,
    load_curriculum,
    record_evaluation,
    run_curriculum,
)

#: Two tiny relay stages (a pair, then two pairs): 32 and 64 agent-steps per rollout.
TINY: dict[str, Any] = {
    "scenario": "relay",
    "timesteps": 384,
    "worlds": 2,
    "env": {"obstacle_density": 0.0, "max_steps": 30},
    "ppo": {"n_steps": 8, "batch_size": 32, "n_epochs": 1},
    "eval": {"seeds": 1, "baselines": "none"},
    "curriculum": {
        "eval_every": 64,
        "eval_seeds": 1,
        "stages": [
            {"name": "pair", "threshold": 0.5, "env": {"n_groups": 1, "group_size": 2}},
            {"name": "pairs", "threshold": None, "env": {"n_groups": 2, "group_size": 2}},
        ],
    },
}


def _tiny(**curriculum: Any) -> dict[str, Any]:
    data = copy.deepcopy(TINY)
    data["curriculum"].update(curriculum)
    return data


def _set(path: str, value: Any) -> Any:
    def change(d: dict[str, Any]) -> None:
        *keys, last = path.split(".")
        for k in keys:
            d = d[int(k)] if isinstance(d, list) else d[k]
        if isinstance(d, list):
            d[int(last)] = value
        else:
            d[last] = value

    return change


def _pop(path: str) -> Any:
    def change(d: dict[str, Any]) -> None:
        *keys, last = path.split(".")
        for k in keys:
            d = d[k]
        del d[last]

    return change


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        (_set("curriculum.foo", 1), r"unknown key curriculum.foo; allowed: \['stages'"),
        (_set("curriculum.stages.0.budgets", 1), r"unknown key curriculum.stages\[0\].budgets"),
        (_set("curriculum.stages", []), "curriculum.stages must be a non-empty list"),
        (_pop("curriculum.stages"), "curriculum.stages must be a non-empty list"),
        (_set("curriculum.stages.1", 3), r"curriculum.stages\[1\] must be a mapping"),
        (_set("curriculum", [1]), "curriculum must be a mapping"),
        (_set("curriculum.stages.0.threshold", 1.5), r"curriculum.stages\[0\].threshold must be <= 1.0, got 1.5"),
        (_set("curriculum.stages.1.threshold", -0.1), r"curriculum.stages\[1\].threshold must be >= 0.0, got -0.1"),
        (_set("curriculum.stages.0.budget", -5), r"curriculum.stages\[0\].budget must be >= 0, got -5"),
        (_set("timesteps", -1), "timesteps must be >= "),
        (_set("curriculum.eval_every", 0), "curriculum.eval_every must be >= 1, got 0"),
        (_set("curriculum.metric", "return"), "curriculum.metric must be one of \\['groups_reached'"),
        (_set("curriculum.on_stage_budget", "skip"), r"on_stage_budget must be one of \['advance', 'stop'\]"),
        (_set("curriculum.stages.1.name", "pair"), "names must differ"),
        (_set("curriculum.stages.1.name", "a/b"), r"curriculum.stages\[1\].name .*pattern"),
        (_set("curriculum.stages.1.env", {"n_groupz": 2}), r"stages\[1\] \(pairs\): env: unknown .*n_groupz"),
        (
            _set("curriculum.stages.1.env", {"comms": {"inbox_size": 2}}),
            r"stages\[1\] \(pairs\) changes the shapes the network sees: observation inbox is \(2, 15\) there and "
            r"\(8, 15\) in stage 0",
        ),
        (_set("ppo.lr_schedule", "linear"), "lr_schedule must be 'constant'"),
    ],
)
def test_bad_curricula_are_named(change: Any, needle: str) -> None:
    data = copy.deepcopy(TINY)
    change(data)
    with pytest.raises(ValueError, match=needle):
        load_curriculum(data)


def test_stages_merge_onto_the_base_and_the_shipped_pair_are_twins() -> None:
    cur = load_curriculum(TINY)
    assert [c.env["n_groups"] for c in cur.stages] == [1, 2]
    assert all(c.env["max_steps"] == 30 and c.env["obstacle_density"] == 0.0 for c in cur.stages)
    comm, cut = load_curriculum("relay_curriculum"), load_curriculum("relay_curriculum_nocomm")
    assert comm.spec == cut.spec and comm.base.ppo == cut.base.ppo and comm.base.timesteps == cut.base.timesteps
    assert comm.stages[0].env["n_groups"] == 1 and comm.stages[0].env["group_size"] == 2
    assert comm.stages[0].env["obstacle_density"] == 0.0
    assert set(comm.stages[-1].env) == {"reward"}  # the last stage is relay's default config
    for a, b in zip(comm.stages, cut.stages):
        assert b.env == {**a.env, "comms": {"loss": 1.0, "overlay_range": 1e-3}}
        assert b.eval_env()["comms"] == {"loss": 1.0, "overlay_range": 1e-3}


# ------------------------------------------------------------------------------------------- promotion rule
def _stepped(cur: Any, values: list[float], every: int = 100) -> tuple[dict[str, Any], list[str]]:
    state, events = fresh_state(cur), []
    for v in values:
        if state["finished"]:
            break
        state["timesteps"] += every
        events.append(record_evaluation(cur, state, v))
    return state, events


def test_promotion_rule() -> None:
    three = copy.deepcopy(TINY["curriculum"]["stages"])
    three.insert(1, {"name": "mid", "threshold": 0.7, "budget": 300, "env": {"n_groups": 1, "group_size": 3}})
    cur = load_curriculum({**_tiny(stages=three), "timesteps": 1000})
    state, events = _stepped(cur, [0.2, 0.5, 0.6, 0.69, 0.9])
    assert events == ["stay", "promoted", "stay", "stay", "promoted"]
    assert state["stage"] == 2 and state["finished"] is None
    assert [(p["from"], p["to"], p["timesteps"], p["how"]) for p in state["promotions"]] == [
        (0, 1, 200, "promoted"),
        (1, 2, 500, "promoted"),
    ]
    # the last stage has no threshold: it trains to the total budget
    state, events = _stepped(cur, [1.0, 0.0, 0.0, 1.0] + [1.0] * 8)
    assert events == ["promoted", "stay", "stay", "promoted"] + ["stay"] * 5 + ["budget"]
    assert state["finished"] == "budget" and state["timesteps"] == 1000
    # a stage out of its budget stops the run, or advances with on_stage_budget: advance
    state, events = _stepped(cur, [0.9, 0.1, 0.1, 0.1, 0.1])
    assert events == ["promoted", "stay", "stay", "stalled"] and state["finished"] == "stalled"
    adv = load_curriculum({**_tiny(stages=three, on_stage_budget="advance"), "timesteps": 1000})
    state, events = _stepped(adv, [0.9, 0.1, 0.1, 0.1, 0.1])
    assert events == ["promoted", "stay", "stay", "advanced", "stay"] and state["stage"] == 2
    assert state["promotions"][-1]["how"] == "advanced"
    # the last stage's threshold met completes the run
    last = copy.deepcopy(TINY["curriculum"]["stages"])
    last[1]["threshold"] = 0.3
    state, events = _stepped(load_curriculum(_tiny(stages=last)), [0.6, 0.2, 0.3, 0.9])
    assert events == ["promoted", "stay", "completed"] and state["finished"] == "completed"


class FakeEvaluator:
    """The metric as a function of the agent-steps trained: the run's decisions do not depend on training."""

    def __init__(self, promote_at: int) -> None:
        self.promote_at = promote_at
        self.calls: list[tuple[int, int]] = []

    def __call__(self, cfg: Any, model: Any) -> float:
        self.calls.append((int(model.num_timesteps), int(cfg.env["n_groups"])))
        return 1.0 if model.num_timesteps >= self.promote_at else 0.0


def _weights(path: Path) -> dict[str, Any]:
    from agentsim_env.policies.learned import load_model

    return load_model(path, device="cpu").policy.state_dict()


def _same_weights(a: Path, b: Path) -> bool:
    wa, wb = _weights(a), _weights(b)
    return wa.keys() == wb.keys() and all(bool((wa[k] == wb[k]).all()) for k in wa)


def _bookkeeping(state: dict[str, Any]) -> dict[str, Any]:
    keep = {k: v for k, v in state.items() if k not in ("wall_s", "cpu_s", "evals")}
    keep["evals"] = [{k: v for k, v in e.items() if k not in ("wall_s", "cpu_s")} for e in state["evals"]]
    return keep


def test_run_promotes_on_a_fake_evaluator_and_writes_its_files(tmp_path: Path) -> None:
    cur = load_curriculum(TINY)
    fake = FakeEvaluator(promote_at=128)
    state = run_curriculum(cur, tmp_path, evaluate=fake, say=lambda _l: None)
    # 64 agent-steps a segment; promoted at 128; stage 2 (two pairs, 64 a rollout) to the 384 budget
    assert fake.calls == [(64, 1), (128, 1), (192, 2), (256, 2), (320, 2), (384, 2)]
    assert state["promotions"] == [{"from": 0, "to": 1, "timesteps": 128, "value": 1.0, "how": "promoted"}]
    assert (state["stage"], state["timesteps"], state["segment"], state["finished"]) == (1, 384, 6, "budget")
    assert state["checkpoint"] == "stages/1_pairs/checkpoints/step_384.zip"
    assert json.loads((tmp_path / STATE_FILE).read_text()) == state
    rows = (tmp_path / "curriculum.csv").read_text().splitlines()
    assert rows[0] == "timesteps,stage,stage_name,value,threshold,event,wall_s,cpu_s"
    assert [r.split(",")[:6] for r in rows[1:3]] == [
        ["64", "0", "pair", "0", "0.5", "stay"],
        ["128", "0", "pair", "1", "0.5", "promoted"],
    ]
    assert len(rows) == 7 and (tmp_path / "curriculum.png").stat().st_size > 5000
    for k, name in enumerate(["0_pair", "1_pairs"]):
        folder = tmp_path / "stages" / name
        assert {p.name for p in folder.iterdir()} >= {"model.zip", "config.json", "config.yaml", "curve.csv"}
        meta = json.loads((folder / "config.json").read_text())
        assert meta["env"]["n_groups"] == k + 1
    assert sorted(p.name for p in (tmp_path / "stages" / "0_pair" / "checkpoints").glob("*.zip")) == [
        "step_128.zip",
        "step_64.zip",
    ]
    assert not list(tmp_path.rglob("*.tmp"))
    with pytest.raises(ValueError, match="already holds a curriculum run"):
        run_curriculum(cur, tmp_path, evaluate=fake)


def test_interrupted_run_resumes_exactly(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cur = load_curriculum(TINY)
    whole = run_curriculum(cur, tmp_path / "whole", evaluate=FakeEvaluator(128), say=lambda _l: None)

    # interrupted: the state write of the third segment fails (as a kill there would leave it)
    real_replace, writes = os.replace, []

    def failing_replace(src: Any, dst: Any) -> None:
        if Path(dst).name == STATE_FILE:
            writes.append(dst)
            if len(writes) == 3:
                raise OSError("disk full")
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", failing_replace)
    part = tmp_path / "part"
    with pytest.raises(OSError, match="disk full"):
        run_curriculum(cur, part, evaluate=FakeEvaluator(128), say=lambda _l: None)
    monkeypatch.setattr(os, "replace", real_replace)
    saved = json.loads((part / STATE_FILE).read_text())  # whole: the second segment's state
    assert (saved["stage"], saved["timesteps"], saved["segment"]) == (1, 128, 2)
    assert saved["promotions"][0]["timesteps"] == 128
    assert not list(part.glob(f".{STATE_FILE}.*.tmp"))

    # resumed under another budget is refused unless only timesteps changed; then it ends where `whole` did
    other = load_curriculum({**TINY, "seed": 1})
    with pytest.raises(ValueError, match=r"differs .* in \['seed'\]"):
        run_curriculum(other, part, resume=True, evaluate=FakeEvaluator(128))
    resumed = run_curriculum(cur, part, resume=True, evaluate=FakeEvaluator(128), say=lambda _l: None)
    assert _bookkeeping(resumed) == _bookkeeping(whole)
    assert _same_weights(part / "model.zip", tmp_path / "whole" / "model.zip")
    # a larger budget continues a finished run
    longer = load_curriculum({**TINY, "timesteps": 448})
    more = run_curriculum(longer, part, resume=True, evaluate=FakeEvaluator(128), say=lambda _l: None)
    assert (more["timesteps"], more["finished"], more["segment"]) == (448, "budget", 7)


def test_stop_after_segments_then_resume_matches(tmp_path: Path) -> None:
    cur = load_curriculum(TINY)
    whole = run_curriculum(cur, tmp_path / "whole", evaluate=FakeEvaluator(192), say=lambda _l: None)
    first = run_curriculum(cur, tmp_path / "part", evaluate=FakeEvaluator(192), max_segments=2)
    assert (first["stage"], first["timesteps"], first["finished"]) == (0, 128, None)
    rest = run_curriculum(cur, tmp_path / "part", resume=True, evaluate=FakeEvaluator(192), say=lambda _l: None)
    assert _bookkeeping(rest) == _bookkeeping(whole)
    assert _same_weights(tmp_path / "part" / "model.zip", tmp_path / "whole" / "model.zip")
    assert _same_weights(
        tmp_path / "part" / "stages" / "0_pair" / "model.zip", tmp_path / "whole" / "stages" / "0_pair" / "model.zip"
    )


def test_train_help_names_the_curriculum(capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.cli import main

    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'curriculum:' section" in text and "relay_curriculum" in text


@pytest.mark.slow
def test_agentsim_train_curriculum_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from agentsim_env.cli import main

    data = _tiny(eval_every=1024)
    data.update(timesteps=4096, worlds=4, ppo={"n_steps": 16, "batch_size": 128, "n_epochs": 2})
    data["curriculum"]["stages"][0]["threshold"] = 0.0  # promoted at its first evaluation
    path = tmp_path / "cur.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    out = tmp_path / "run"
    rc = main(["train", "relay", "--config", str(path), "--out", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "stage 1/2 pair: groups_reached" in text and "promoted" in text
    assert "curriculum: stage 2/2 (pairs) reached, budget" in text
    state = json.loads((out / STATE_FILE).read_text())
    assert state["promotions"][0]["timesteps"] == 1024 and state["timesteps"] >= 4096
    assert (out / "curriculum.png").is_file() and (out / "eval.md").is_file()
    assert "run@pair" in (out / "eval.md").read_text() or "run@pairs" in (out / "eval.md").read_text()
    assert main(["train", "relay", "--config", str(path), "--out", str(out), "--quiet"]) == 2
    assert "already holds a curriculum run" in capsys.readouterr().err
    assert main(["train", "relay", "--config", str(path), "--out", str(out), "--quiet", "--eval-only"]) == 0
    assert "curriculum: stage 2/2 (pairs) reached" in capsys.readouterr().out
    more = ["--resume", "--timesteps", str(state["timesteps"] + 1024)]
    assert main(["train", "relay", "--config", str(path), "--out", str(out), "--quiet", *more]) == 0
    again = json.loads((out / STATE_FILE).read_text())
    assert again["timesteps"] >= state["timesteps"] + 1024 and again["segment"] == state["segment"] + 1
