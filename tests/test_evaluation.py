"""Batch evaluation of the UAV release strategies: `agentsim evaluate` end to end, runner and report."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest

from agentsim_env.cli import main
from agentsim_env.uav.cli import parse_seeds
from agentsim_env.uav.evaluation import report, runner
from agentsim_env.uav.evaluation.mission import MissionLog
from agentsim_env.uav.evaluation.report import (
    SENSOR_COLUMNS,
    composite_score,
    format_mean_std,
    mean_std,
    rank_strategies,
    ranking_table,
)
from agentsim_env.uav.evaluation.runner import TELEPORT, resolve_zones, run_one, teleport_reference

# A small mission: the tiny zone file (one zone, 20 sensors) with exactly the payload it needs.
TINY = ["--set", "n_uavs=2", "payload=10", "max_steps=2500"]
TINY_OVERRIDES = {"n_uavs": 2, "payload": 10, "max_steps": 2500}
PAIR = ["B1LD_sunflower", "B2_rings"]
RUN_KEYS = (
    "zones",
    "strategy",
    "seed",
    "score",
    "completed",
    "mission_time_s",
    "energy_j",
    "energy_fraction",
    "path_length_m",
    "sensors_released",
    "sensors_landed",
    "delivered_fraction",
    "messages_sent",
    "messages_dropped",
    "near_misses",
    "collisions",
    "coverage_weighted",
    "lcc_fraction",
    "fnd",
    "w1_mean",
    "containment",
    "landing_error_mean",
    "coverage_weighted_vs_oracle",
    "fnd_vs_oracle",
)


def _read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with path.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, str]:
    """One in-process `agentsim evaluate` on the tiny zone file, 2 strategies x 2 seeds."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("evaluation") / "ev"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(
            [
                "evaluate",
                "--zones",
                "tiny",
                "--strategies",
                *PAIR,
                "--seeds",
                "2",
                *TINY,
                "--out",
                str(out),
                "--quiet",
            ]
        )
    return out, rc, buf.getvalue()


def test_cli_writes_every_file(evaluated: tuple[Path, int, str]) -> None:
    out, rc, stdout = evaluated
    assert rc == 0
    for name in ("sensors.csv", "runs.csv", "summary.md", "landing_tiny_seed0.png", "metrics_tiny.png"):
        assert (out / name).is_file(), name
    assert not list(out.glob(".*partial*"))
    assert "| Rank | Strategy | Score" in stdout and "written:" in stdout and str(out / "runs.csv") in stdout


def test_runs_csv_has_one_row_per_run_with_every_metric(evaluated: tuple[Path, int, str]) -> None:
    out, _, _ = evaluated
    cols, rows = _read_csv(out / "runs.csv")
    assert cols[:4] == ["zones", "strategy", "seed", "score"]
    assert set(RUN_KEYS) <= set(cols)
    assert sorted((r["strategy"], r["seed"]) for r in rows) == sorted(
        (s, str(k)) for s in [*PAIR, TELEPORT] for k in (0, 1)
    )
    for r in rows:
        assert r["zones"] == "tiny"
        assert math.isfinite(float(r["score"]))
        assert float(r["score"]) == pytest.approx(composite_score(r), abs=1e-8)
        if r["strategy"] != TELEPORT:
            assert float(r["energy_j"]) > 0 and float(r["path_length_m"]) > 0 and float(r["mission_time_s"]) > 0
            assert float(r["sensors_released"]) >= 1 and float(r["messages_sent"]) > 0
            assert float(r["completed"]) == 1.0 and float(r["collisions"]) == 0.0
    ref = [r for r in rows if r["strategy"] == TELEPORT]
    assert all(float(r["landing_error_mean"]) == 0.0 and float(r["energy_j"]) == 0.0 for r in ref)
    assert all(float(r["fnd_vs_oracle"]) == 1.0 for r in ref)


def test_sensors_csv_schema_and_one_row_per_released_sensor(evaluated: tuple[Path, int, str]) -> None:
    out, _, _ = evaluated
    cols, sensors = _read_csv(out / "sensors.csv")
    assert tuple(cols) == SENSOR_COLUMNS
    _, runs = _read_csv(out / "runs.csv")
    for r in runs:
        mine = [s for s in sensors if s["strategy"] == r["strategy"] and s["seed"] == r["seed"]]
        assert len(mine) == int(float(r["sensors_released"])), (r["strategy"], r["seed"])
        assert len({s["sensor_id"] for s in mine}) == len(mine)
        landed = [s for s in mine if s["x_land"] != "nan"]
        assert len(landed) == int(float(r["sensors_landed"]))
        if r["strategy"] != TELEPORT:
            assert all(float(s["z_rel"]) > 0 and float(s["t_land"]) > float(s["t_release"]) for s in landed)
            assert {s["uav_id"] for s in mine} <= {"0", "1"}


def test_summary_ranks_every_strategy(evaluated: tuple[Path, int, str]) -> None:
    out, _, _ = evaluated
    text = (out / "summary.md").read_text(encoding="utf-8")
    table = [line for line in text.splitlines() if line.startswith("| ") and "`" in line]
    names = [line.split("|")[2].strip().strip("`") for line in table]
    assert sorted(names) == sorted([*PAIR, TELEPORT])
    assert [line.split("|")[1].strip() for line in table] == ["1", "2", "3"]
    scores = [float(line.split("|")[3].split("±")[0]) for line in table]
    assert scores == sorted(scores, reverse=True)
    assert "runs.csv" in text and "sensors.csv" in text


def test_pngs_are_valid_images(evaluated: tuple[Path, int, str]) -> None:
    out, _, _ = evaluated
    for name in ("landing_tiny_seed0.png", "metrics_tiny.png"):
        img = plt.imread(out / name)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 600
        assert img[..., :3].std() > 0.05  # not blank


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--strategies", "B9_nope"], "B9_nope"),
        (["--strategies", "B2_rings", "--seeds", "x"], "--seeds"),
        (["--zones", "no/such/zones.json"], "no/such/zones.json"),
    ],
)
def test_bad_input_exits_2_naming_the_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], needle: str
) -> None:
    out = tmp_path / "ev"
    rc = main(["evaluate", "--zones", "tiny", *args, "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_bad_strategy_message_lists_the_allowed_names(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", "--strategies", "B9_nope", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "B0_uniform" in err and "B8_teleport" in err and "'all'" in err


def test_bad_zone_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "zones_bad.json"
    bad.write_text(json.dumps({"map_size": [100, 100], "zones": [{"centre": [50, 50], "radius": 80, "n_sensors": 5}]}))
    out = tmp_path / "ev"
    assert main(["evaluate", "--zones", str(bad), "--strategies", "B2_rings", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "radius" in err
    assert not out.exists()


def test_a_failing_run_writes_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(*args: object, **kwargs: object) -> None:
        raise RuntimeError("policy crashed")

    monkeypatch.setattr(runner, "run_one", boom)
    out = tmp_path / "ev"
    with pytest.raises(RuntimeError, match="policy crashed"):
        main(
            [
                "evaluate",
                "--zones",
                "tiny",
                "--strategies",
                "B2_rings",
                "--seeds",
                "1",
                *TINY,
                "--out",
                str(out),
                "--quiet",
            ]
        )
    assert not out.exists()


def test_runs_are_deterministic_and_teleport_is_the_reference() -> None:
    (src,) = resolve_zones(["tiny"])
    ref = teleport_reference(src, TINY_OVERRIDES)
    assert ref.metrics["coverage_weighted_vs_oracle"] == 1.0 and ref.metrics["delivered_fraction"] == 1.0
    assert composite_score(ref.metrics) == pytest.approx(1.0 - ref.metrics["w1_mean"] / 6)
    a = run_one(src, "B2_rings", 3, TINY_OVERRIDES, ref.metrics)
    b = run_one(src, "B2_rings", 3, TINY_OVERRIDES, ref.metrics)
    assert a.metrics.keys() == b.metrics.keys()
    np.testing.assert_array_equal(np.array(list(a.metrics.values())), np.array(list(b.metrics.values())))
    assert a.sensors == b.sensors
    assert a.metrics["coverage_weighted_vs_oracle"] == pytest.approx(
        a.metrics["coverage_weighted"] / ref.metrics["coverage_weighted"]
    )


def test_zone_labels_and_strategy_expansion(tmp_path: Path) -> None:
    srcs = resolve_zones(["tiny", "default"])
    assert [s.label for s in srcs] == ["tiny", "default"] and srcs[1].zones.n_sensors == 150
    assert runner.resolve_strategies(["all"]) == sorted(runner.available_strategies())
    assert runner.resolve_strategies(["all"])[0] == "B0_uniform" and len(runner.available_strategies()) == 10
    # the B8_teleport strategy is flown like the others (the reference row is added anyway), under its own label
    assert runner.resolve_strategies(["B2_rings", TELEPORT, "B2_rings"]) == ["B2_rings", TELEPORT]
    assert runner.strategy_labels(["B2_rings", TELEPORT]) == ["B2_rings", f"{TELEPORT}_flown"]
    with pytest.warns(DeprecationWarning, match="B8_oracle"):
        assert runner.resolve_strategies(["B8_oracle"]) == [TELEPORT]
    with pytest.raises(ValueError, match="at least one"):
        runner.resolve_strategies([])


def _fake_env(pos: np.ndarray) -> SimpleNamespace:
    state = SimpleNamespace(pos=pos, online=np.ones(pos.shape[0], dtype=bool))
    events = SimpleNamespace(went_offline=np.zeros(0, dtype=np.int64), comms=None)
    return SimpleNamespace(
        scenario=SimpleNamespace(n_agents=pos.shape[0]),
        world=SimpleNamespace(state=state, last_events=events, comms=None),
    )


def test_mission_log_path_and_near_misses() -> None:
    # three UAVs take off 3 m apart: adjacent pairs start closer than NEAR_MISS_M and do not count yet
    pos = np.array([[0.0, 0, 5], [3, 0, 5], [6, 0, 5]])
    env = _fake_env(pos)
    log = MissionLog(env)
    moves = [[0, 10, 20], [0, 12, 20], [0, 18, 20], [0, 12, 20], [0, 18, 20]]  # UAV 1 buzzes UAV 2 twice
    for xs in moves:
        env.world.state.pos[:, 0] = xs
        log.update(env)
    assert int(np.count_nonzero(log.near)) == 1 and log.near.tolist() == [False, False, True]
    assert log.path == pytest.approx((0 + 7 + 14) + 2 + 6 + 6 + 6)
    # a pair that closes in while one of them is already down is not a near miss
    env.world.state.online[2] = False
    log.on_prev[2] = False
    env.world.state.pos[:, 0] = [17, 30, 20]
    log.update(env)
    assert int(np.count_nonzero(log.near)) == 1


def testparse_seeds() -> None:
    assert parse_seeds(["3"]) == [0, 1, 2]
    assert parse_seeds(["0,4,9"]) == [0, 4, 9]
    assert parse_seeds(["5", "2"]) == [5, 2]
    assert parse_seeds(["7,"]) == [7]
    for bad in (["0"], ["a"], [","]):
        with pytest.raises(ValueError, match="--seeds"):
            parse_seeds(bad)


# ------------------------------------------------------------------------------------------ report
def _row(strategy: str, seed: int, **kw: float) -> dict:
    base = {
        "zones": "z",
        "strategy": strategy,
        "seed": seed,
        "coverage_weighted_vs_oracle": 1.0,
        "lcc_fraction_vs_oracle": 1.0,
        "fnd_vs_oracle": 1.0,
        "w1_mean": 0.0,
        "containment": 1.0,
        "delivered_fraction": 1.0,
        "energy_fraction": 0.0,
    }
    return {**base, **kw}


def test_composite_score_terms() -> None:
    assert composite_score(_row("a", 0)) == pytest.approx(1.0)
    # ratios are capped at 1, W1 enters as 1 - W1, energy is subtracted, delivery scales the quality
    assert composite_score(_row("a", 0, fnd_vs_oracle=3.0)) == pytest.approx(1.0)
    # coverage weighs 2 of 6, every other quality term 1 of 6
    assert composite_score(_row("a", 0, coverage_weighted_vs_oracle=0.25)) == pytest.approx(0.75)
    assert composite_score(_row("a", 0, w1_mean=0.6)) == pytest.approx(0.9)
    assert composite_score(_row("a", 0, energy_fraction=0.25)) == pytest.approx(0.75)
    assert composite_score(_row("a", 0, delivered_fraction=0.5)) == pytest.approx(0.5)
    assert composite_score(_row("a", 0, containment=math.nan)) == pytest.approx(5 / 6)


def test_mean_std_and_formatting() -> None:
    assert mean_std([0.4, 0.6]) == pytest.approx((0.5, math.sqrt(0.02)))
    assert mean_std([2.0]) == (2.0, 0.0)
    assert all(math.isnan(v) for v in mean_std([math.nan]))
    assert format_mean_std([0.4, 0.6]) == "0.500 ± 0.141"
    assert format_mean_std([1500.0, 2500.0], digits=1, scale=1e-3) == "2.0 ± 0.7"
    assert format_mean_std([1.0, math.nan]) == "1.000 ± 0.000"
    assert format_mean_std([]) == "n/a"


def test_ranking_order_and_table() -> None:
    rows = [
        _row("mid", 0, w1_mean=0.3),
        _row("mid", 1, w1_mean=0.3),
        _row("best", 0),
        _row("best", 1),
        _row("worst", 0, energy_fraction=0.5),
        _row("worst", 1, energy_fraction=0.7),
        _row("aa_tie", 0, w1_mean=0.3),
        _row("aa_tie", 1, w1_mean=0.3),
    ]
    ranked = rank_strategies(rows)
    assert [s.strategy for s in ranked] == ["best", "aa_tie", "mid", "worst"]
    assert ranked[-1].score_mean == pytest.approx(0.4) and ranked[-1].score_std == pytest.approx(math.sqrt(0.02))
    table = ranking_table(ranked).splitlines()
    assert len(table) == 2 + 4
    assert table[2].startswith("| 1 | `best` | 1.000 ± 0.000 |")
    assert "| 4 | `worst` | 0.400 ± 0.141 |" in table[5]
    assert rank_strategies(rows, zones="other") == []


def test_write_csv_formats_values(tmp_path: Path) -> None:
    p = report.write_csv([{"a": 1, "b": 0.1 + 0.2, "c": math.nan}, {"a": 2, "d": "x"}], tmp_path / "t.csv")
    assert p.read_text().splitlines() == ["a,b,c,d", "1,0.3,nan,", "2,,,x"]


@pytest.mark.slow
def test_default_zone_file_every_strategy(tmp_path: Path) -> None:
    out = tmp_path / "ev"
    assert (
        main(
            [
                "evaluate",
                "--zones",
                "default",
                "--strategies",
                "all",
                "--seeds",
                "1",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    _, rows = _read_csv(out / "runs.csv")
    assert {r["strategy"] for r in rows} == {*runner.strategy_labels(runner.available_strategies()), TELEPORT}
    flown = [r for r in rows if r["strategy"] != TELEPORT]
    assert all(float(r["completed"]) == 1.0 and float(r["sensors_landed"]) == 150.0 for r in flown)
    best = max(rows, key=lambda r: float(r["score"]))
    assert best["strategy"] == TELEPORT
    for name in ("landing_default_seed0.png", "metrics_default.png"):
        assert plt.imread(out / name).ndim == 3
