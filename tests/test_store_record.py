"""``--record`` end to end: ``agentsim run``, ``agentsim evaluate`` (its CSVs read back from the store) and
training record into a store; a bad ``--record`` path fails before any rollout, and a recording that fails
mid-mission fails the run rather than leaving CSVs built from a partial store.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import pytest

import agentsim_env
from agentsim_env.recorder import StoreError, connect, record
from agentsim_env.recorder.read import open_store
from tests.test_store_robust import _full

# ------------------------------------------------------------------------------------------ --record
TINY_OVERRIDES = {"n_uavs": 2, "payload": 10, "max_steps": 2500}
TINY_EVAL = [
    "--zones",
    "tiny",
    "--strategies",
    "B2_rings",
    "--seeds",
    "2",
    "--set",
    "n_uavs=2",
    "payload=10",
    "max_steps=2500",
    "--no-plots",
    "--quiet",
]


def test_cli_run_records_every_episode_in_one_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    db = tmp_path / "run.db"
    argv = [
        "run",
        "navigation",
        "--episodes",
        "3",
        "--seed",
        "5",
        "--set",
        "n_agents=3",
        "max_steps=15",
        "--out",
        "",
        "--quiet",
        "--record",
        str(db),
    ]
    assert main(argv) == 0
    assert f"recorded to {db} (run 1)" in capsys.readouterr().out
    assert main(argv) == 0  # a second rollout: a second run of the same store
    con = connect(db)
    try:
        runs = con.execute("SELECT run, scenario, status, n_agents, label FROM runs").fetchall()
        label = "agentsim run navigation --policy go_to_goal --seed 5 --episodes 3 --set n_agents=3 max_steps=15"
        assert runs == [(1, "navigation", "complete", 3, label), (2, "navigation", "complete", 3, label)]
        assert con.execute("SELECT episode, seed FROM episodes WHERE run = 1").fetchall() == [
            (0, "5"),
            (1, "6"),
            (2, "7"),
        ]
        assert con.execute("SELECT MAX(step) FROM steps WHERE run = 1 GROUP BY episode").fetchall() == [(15,)] * 3
    finally:
        con.close()


def test_cli_evaluate_writes_the_csvs_from_the_store(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """With --record every mission is a run of the store, and sensors.csv / runs.csv read back from it are the
    files written without it, byte for byte."""
    from agentsim_env.cli import main

    db = tmp_path / "eval.db"
    assert main(["evaluate", *TINY_EVAL, "--out", str(tmp_path / "plain")]) == 0
    assert main(["evaluate", *TINY_EVAL, "--out", str(tmp_path / "rec"), "--record", str(db)]) == 0
    assert f"{db} (2 missions recorded, runs 1-2)" in capsys.readouterr().out
    for name in ("sensors.csv", "runs.csv"):
        assert (tmp_path / "rec" / name).read_bytes() == (tmp_path / "plain" / name).read_bytes(), name
    con = connect(db)
    try:
        runs = con.execute("SELECT run, scenario, status, label FROM runs").fetchall()
        assert runs == [
            (1, "uav_release", "complete", "zones=tiny strategy=B2_rings seed=0"),
            (2, "uav_release", "complete", "zones=tiny strategy=B2_rings seed=1"),
        ]
        # every flown sensor of sensors.csv is a row of the store's sensors table
        (n_sensors,) = con.execute("SELECT COUNT(*) FROM sensors").fetchone()
    finally:
        con.close()
    lines = (tmp_path / "rec" / "sensors.csv").read_text(encoding="utf-8").splitlines()[1:]
    assert n_sensors == sum(",B2_rings," in line for line in lines) > 0


def _recording(db: Path) -> Any:
    """``run_grid``'s ``record_env`` for the store ``db`` (what ``agentsim evaluate --record`` passes)."""
    return lambda env, label: record(env, db, label=label)


def _write(grid: Any, db: Path, out: Path) -> None:
    from agentsim_env.uav.evaluation.report import write_outputs

    with open_store(db) as store:
        write_outputs(grid, out, plots=False, store=store.con)


def test_store_rows_refuse_a_store_that_disagrees(tmp_path: Path) -> None:
    from agentsim_env.uav.evaluation.runner import run_grid

    db = tmp_path / "eval.db"
    grid = run_grid(["tiny"], ["B2_rings"], [0], TINY_OVERRIDES, progress=False, record_env=_recording(db))
    (flown,) = [r for r in grid.runs if r.store_run is not None]
    assert flown.store_run == 1
    _write(grid, db, tmp_path / "ok")
    con = sqlite3.connect(db)
    con.execute("UPDATE sensors SET land_x = land_x + 1 WHERE sensor = (SELECT MIN(sensor) FROM sensors)")
    con.commit()
    con.close()
    with pytest.raises(ValueError, match=r"disagree on x_land"):
        _write(grid, db, tmp_path / "bad")
    con = sqlite3.connect(db)
    con.execute("UPDATE runs SET status = 'incomplete'")
    con.commit()
    con.close()
    with pytest.raises(ValueError, match=r"zones=tiny strategy=B2_rings seed=0 is not recorded complete"):
        _write(grid, db, tmp_path / "bad")
    assert not (tmp_path / "bad").exists()  # checked before anything is written


def test_a_recording_that_fails_mid_mission_fails_the_run(tmp_path: Path) -> None:
    """The recorder detaches and the mission flies on, but its rows in the store are incomplete: the run fails
    (rather than sensors.csv being read from a partial recording)."""
    from agentsim_env.uav.evaluation.runner import resolve_zones, run_one

    db = tmp_path / "full.db"

    def record_env(env: Any, label: str) -> Any:
        recorded = record(env, db, label=label)
        _full(recorded.recorder.con)
        return recorded

    (src,) = resolve_zones(["tiny"])
    with (
        pytest.warns(RuntimeWarning, match="database or disk is full"),
        pytest.raises(ValueError, match=rf"{db}: recording the mission zones=tiny strategy=B2_rings seed=0 failed"),
    ):
        run_one(src, "B2_rings", 0, TINY_OVERRIDES, record_env=record_env)
    con = connect(db)
    try:
        assert con.execute("SELECT status FROM runs").fetchall() == [("incomplete",)]
    finally:
        con.close()


@pytest.mark.parametrize("command", [["run", "navigation"], ["evaluate", "--zones", "tiny"]])
def test_cli_bad_record_path_fails_before_any_rollout(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, command: list[str]
) -> None:
    from agentsim_env.cli import main
    from agentsim_env.uav.evaluation import runner

    def boom(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("a rollout started")

    monkeypatch.setattr(agentsim_env, "make", boom)
    monkeypatch.setattr(runner, "run_grid", boom)
    junk = tmp_path / "junk.db"
    junk.write_text("not a store")
    for path, needle in ((tmp_path / "no" / "r.db", "does not exist"), (junk, "not a database")):
        out = tmp_path / "out"
        assert main([*command, "--out", str(out), "--record", str(path)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("agentsim: error: --record ") and str(path) in err and needle in err, err
        assert not out.exists()


def test_training_records_the_training_env(tmp_path: Path) -> None:
    pytest.importorskip("stable_baselines3")
    from agentsim_env.train.config import load_config
    from agentsim_env.train.runner import train

    db = tmp_path / "train.db"
    cfg = load_config(
        "navigation",
        {
            "timesteps": 256,
            "worlds": 2,
            "seed": 3,
            "env": {"n_agents": 2, "max_steps": 40},
            "ppo": {"n_steps": 64, "batch_size": 64, "n_epochs": 1},
        },
    )
    train(cfg, None, record=db)
    con = connect(db)
    try:
        assert con.execute("SELECT status, n_worlds, n_agents, label FROM runs").fetchall() == [
            ("complete", 2, 2, "agentsim train navigation worlds=2 seed=3")
        ]
        # 256 agent-steps / (2 worlds x 2 agents) = 64 steps: the worlds ran through their 40-step episodes and
        # were reset automatically, each reset a new recorded episode
        assert con.execute("SELECT world, COUNT(*) FROM episodes GROUP BY world").fetchall() == [
            (0, 2),
            (1, 2),
        ]
        (last,) = con.execute("SELECT last_step FROM runs").fetchone()
        assert last == 64 - 40  # the step count of the episode running when training ended
        rows = con.execute("SELECT episode, MAX(step) FROM steps WHERE world = 0 GROUP BY episode").fetchall()
        assert rows == [(0, 40), (1, 24)]
    finally:
        con.close()
    with pytest.raises(StoreError, match="does not exist"):
        train(cfg, None, record=tmp_path / "no" / "t.db")
