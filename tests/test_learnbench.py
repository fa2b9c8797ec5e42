"""The learning benchmark (``agentsim benchmark-rl``, ``benchmarks/bench_learning.py``): options, writers, --quick."""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import pytest

from agentsim_env.train.learnbench import (
    ALGORITHMS,
    BENCHMARL_ALGORITHMS,
    MISSING_BENCHMARL,
    SUCCESS_METRIC,
    BenchOptions,
    _baselines,
    _run_benchmarl,
    bench_config,
    bench_scenarios,
)
from agentsim_env.train.learnbench_report import (
    RUN_FIELDS,
    BenchResult,
    csv_text,
    mean_std,
    summary_markdown,
    write_all,
)

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ["navigation", "relay", "rendezvous", "uav_release"]


def test_every_shipped_scenario_has_a_bench_config_with_a_success_metric() -> None:
    assert bench_scenarios() == SHIPPED
    for name in SHIPPED:
        cfg = bench_config(name, BenchOptions())
        assert cfg.scenario == name and cfg.timesteps > 0 and cfg.checkpoint_every == 0
        assert name in SUCCESS_METRIC
    quick = bench_config("navigation", BenchOptions(quick=True))
    assert quick.timesteps < 10_000 and quick.eval.seeds == 2 and quick.env["n_agents"] == 2


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"scenarios": ("nowhere",)}, ["scenario must be one of", "navigation", "'nowhere'"]),
        ({"algorithms": ("dqn",)}, ["algorithm must be one of", "mappo", "'dqn'"]),
        ({"seeds": 0}, ["seeds must be an integer >= 1", "0"]),
        ({"budget": 0}, ["budget must be", "> 0"]),
        ({"budget": -5}, ["budget must be", "-5"]),
        ({"eval_seeds": 0}, ["eval_seeds must be an integer >= 1"]),
    ],
)
def test_bad_options_are_named_with_the_allowed_values(kwargs: dict[str, object], words: list[str]) -> None:
    with pytest.raises(ValueError) as err:
        BenchOptions(**kwargs)  # type: ignore[arg-type]
    for w in words:
        assert w in str(err.value)


def test_defaults_select_every_algorithm_and_three_seeds_quick_two() -> None:
    assert BenchOptions().selected_algorithms() == list(ALGORITHMS) and BenchOptions().n_seeds() == 3
    quick = BenchOptions(quick=True)
    assert quick.selected_algorithms() == ["ppo", "mappo"] and quick.n_seeds() == 2
    assert BenchOptions(algorithms=("masac", "ppo")).selected_algorithms() == ["ppo", "masac"]


def test_command_line_refuses_a_bad_option_with_one_line(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "bench_learning.py"), "--seeds", "0", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "error: seeds must be an integer >= 1, got 0" in proc.stderr
    assert not (tmp_path / "runs.csv").exists()


def test_a_plugin_policy_that_does_not_load_leaves_rows_not_a_stopped_benchmark() -> None:
    from agentsim_env.core.plugins import POLICIES, register_policy

    cfg = bench_config("navigation", BenchOptions(quick=True))
    register_policy("lb_broken", "no_such_module_lb:Policy")  # no scenario given: it is read from the class
    try:
        rows = _baselines("navigation", cfg)
    finally:
        POLICIES.unregister("lb_broken")
    assert rows[0]["policy"] == "plug-in policies" and "no_such_module_lb" in rows[0]["status"]
    assert [r["policy"] for r in rows[1:]] == ["go_to_goal", "random"]
    assert all(r["status"].startswith(("failed: ", "scripted")) for r in rows)
    assert {r["success_metric"] for r in rows} == {SUCCESS_METRIC["navigation"]}


def test_missing_benchmarl_environment_gives_rows_without_numbers(tmp_path: Path) -> None:
    opts = BenchOptions(out=tmp_path, benchmarl_python=tmp_path / "no" / "python")
    cfg = bench_config("navigation", opts)
    result = BenchResult()
    _run_benchmarl([("navigation", cfg, "mappo", 0), ("navigation", cfg, "ippo", 1)], opts, result, None)
    assert [r["status"] for r in result.runs] == [MISSING_BENCHMARL] * 2
    assert all(r["eval_return"] == "" and r["cpu_s"] == "" for r in result.runs)
    assert "make test-ecosystem-benchmarl" in MISSING_BENCHMARL and set(BENCHMARL_ALGORITHMS) < set(ALGORITHMS)


def test_csv_text_refuses_an_unknown_column_and_leaves_missing_cells_empty() -> None:
    assert csv_text([{"a": 1}], ["a", "b"]) == "a,b\n1,\n"
    with pytest.raises(ValueError, match="row field 'c' is not a column"):
        csv_text([{"a": 1, "c": 2}], ["a", "b"])


def test_mean_std_skips_empty_and_non_finite_cells() -> None:
    assert mean_std([1.0, 3.0, "", float("nan")]) == "2.000 ± 1.000"
    assert mean_std(["", None]) == "-"


def _row(algorithm: str, seed: int, ret: object, status: str = "ok") -> dict[str, object]:
    row: dict[str, object] = {k: "" for k in RUN_FIELDS}
    row.update(scenario="navigation", algorithm=algorithm, seed=seed, status=status, budget_agent_steps=1000)
    row.update(eval_return=ret, success=0.5 if ret != "" else "", success_metric="arrived_per_agent")
    row.update(cpu_s=2.0 if ret != "" else "")
    return row


def _result() -> BenchResult:
    result = BenchResult()
    result.runs = [_row("ppo", 0, 1.0), _row("ppo", 1, 3.0), _row("mappo", 0, "", MISSING_BENCHMARL)]
    result.curves = [
        {"scenario": "navigation", "algorithm": "ppo", "seed": s, "agent_steps": x, "mean_return": x / 100 + s}
        for s in (0, 1)
        for x in (100, 200, 300)
    ]
    result.baselines["navigation"] = [
        {"policy": "go_to_goal", "episodes": 2, "mean_return": 38.0, "std_return": 1.0, "success": 1.0},
        {"policy": "random", "episodes": 2, "mean_return": -0.5, "std_return": 0.2, "success": 0.0},
        {"policy": "ghost", "episodes": 0, "status": "failed: boom"},  # a baseline that could not be played
    ]
    return result


def test_summary_table_has_one_row_per_algorithm_and_baseline_and_keeps_rows_that_did_not_run() -> None:
    text = summary_markdown(_result(), "agentsim benchmark-rl --quick", quick=True)
    assert "quick profile" in text and "`agentsim benchmark-rl --quick`" in text
    rows = [line for line in text.splitlines() if line.startswith("| navigation")]
    assert len(rows) == 5
    assert rows[0].startswith("| navigation | ppo | 2 | 1,000 | 2.000 ± 1.000 | 0.500 ± 0.000 | 2.000 ± 0.000 | ok |")
    assert rows[1] == f"| navigation | mappo | 1 | 1,000 | - | - | - | {MISSING_BENCHMARL} |"
    assert rows[2] == "| navigation | baseline `go_to_goal` | - | - | 38.000 ± 1.000 | 1.000 | - | scripted |"
    assert rows[4] == "| navigation | baseline `ghost` | - | - | - | - | - | failed: boom |"


def test_write_all_writes_every_file_and_leaves_no_temporary(tmp_path: Path) -> None:
    opts = BenchOptions(scenarios=("navigation",), quick=True)
    configs = {"navigation": bench_config("navigation", opts)}
    paths = write_all(_result(), tmp_path / "out", configs, quick=True, command="cmd")
    names = sorted(p.name for p in paths)
    assert names == ["baselines.csv", "curves.csv", "navigation.png", "runs.csv", "summary.md"]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == names
    with open(tmp_path / "out" / "runs.csv", newline="", encoding="utf-8") as f:
        runs = list(csv.DictReader(f))
    assert [r["status"] for r in runs] == ["ok", "ok", MISSING_BENCHMARL] and list(runs[0]) == list(RUN_FIELDS)
    assert (tmp_path / "out" / "navigation.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_baselines_of_another_mode_are_compared_by_success_not_drawn_on_the_return_axis(tmp_path: Path) -> None:
    # uav_release's strategies play the default mode while the policy learns the autopilot mode: their returns are
    # on another scale, so the plot keeps them off the curves and adds a panel of the success metric
    import matplotlib.image as mpimg

    from agentsim_env.train.learnbench_report import plot_scenario

    r = _result()
    one = plot_scenario("navigation", r.curves, r.baselines["navigation"], tmp_path / "one.png", runs=r.runs)
    two = plot_scenario(
        "navigation", r.curves, r.baselines["navigation"], tmp_path / "two.png", runs=r.runs, baselines_elsewhere=True
    )
    assert mpimg.imread(two).shape[1] > mpimg.imread(one).shape[1]  # the success panel beside the curves
    configs = {"uav_release": bench_config("uav_release", BenchOptions(scenarios=("uav_release",)))}
    assert configs["uav_release"].eval.baseline_env  # the shipped config plays the baselines in their own mode


@pytest.mark.slow
def test_quick_profile_writes_every_file_with_finite_numbers(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    proc = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "bench_learning.py"),
            "--quick",
            "--no-progress",
            "--out",
            str(out),
            "--benchmarl-python",
            str(ROOT / ".venv-eco" / "benchmarl" / "bin" / "python"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("runs.csv", "curves.csv", "baselines.csv", "summary.md"):
        assert (out / name).stat().st_size > 0, name
    with open(out / "runs.csv", newline="", encoding="utf-8") as f:
        runs = list(csv.DictReader(f))
    assert len(runs) == len(SHIPPED) * 2 * 2  # scenarios x (ppo, mappo) x 2 seeds
    for r in runs:
        assert r["status"] in ("ok", MISSING_BENCHMARL), r
        if r["algorithm"] == "ppo":
            assert r["status"] == "ok" and r["eval_return"] != "" and r["success"] != ""
        for key, value in r.items():
            try:
                number = float(value)
            except ValueError:
                continue
            assert math.isfinite(number), (key, r)
    table = (out / "summary.md").read_text(encoding="utf-8")
    for scenario in SHIPPED:
        assert f"| {scenario} | ppo | 2 | 2,000 |" in table
        assert f"| {scenario} | mappo | 2 | 2,000 |" in table
        assert (out / f"{scenario}.png").stat().st_size > 1000
    assert "quick profile" in table and "--quick" in table
