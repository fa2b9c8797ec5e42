"""Smoke tests of the benchmarks: --quick runs at tiny sizes print complete tables (no timing checks)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from agentsim_env.core.threads import available_cores
from tests.bench_tables import markdown_tables

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import common  # noqa: E402
import run_all  # noqa: E402

MAIN_TEXT_COLUMNS = {"size BxN", "target", "array", "dict"}
PASS_VALUES = {"PASS", "FAIL", "skipped", "-"}


_tables = markdown_tables


def _number_or_skipped(cell: str) -> bool:
    if cell.startswith("skipped"):
        return True
    try:
        return math.isfinite(float(cell.replace(",", "")))
    except ValueError:
        return False


@pytest.fixture(scope="module")
def quick_run() -> str:
    # 1x4 follows 1x2, and --max-step-s is tiny: VMAS and mpe2 are skipped at 1x4 (estimate from 1x2), so the
    # run shows measured cells and skipped cells side by side.
    cmd = [
        sys.executable,
        str(ROOT / "benchmarks" / "bench_step.py"),
        "--quick",
        "--sizes",
        "1x2",
        "1x4",
        "2x3",
        "--pymunk-size",
        "1x2",
        "--ratio-sizes",
        "1x2",
        "1x4",
        "--rounds",
        "2",
        "--block-s",
        "0.005",
        "--max-step-s",
        "1e-9",
    ]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    return res.stdout


def test_quick_run_prints_both_tables_with_every_cell_filled(quick_run: str) -> None:
    assert quick_run.startswith("machine: ")
    tables = _tables(quick_run)
    assert len(tables) == 2
    (head, rows), (check_head, checks) = tables
    assert head[0] == "size BxN" and [r[0] for r in rows] == ["1x2", "1x4", "2x3"]
    for row in rows:
        assert len(row) == len(head)
        for name, cell in zip(head, row):
            if name in MAIN_TEXT_COLUMNS:
                assert cell, (row[0], name)
            else:
                assert _number_or_skipped(cell), (row[0], name, cell)
        assert row[-2] in PASS_VALUES and row[-1] in PASS_VALUES
    measured = {r[0]: r for r in rows}
    vmas = head.index("VMAS ag-st/s")
    assert measured["1x4"][vmas].startswith("skipped")  # the tiny --max-step-s at work
    assert _number_or_skipped(measured["1x2"][head.index("array API ag-st/s")])
    assert not measured["1x2"][head.index("array API ag-st/s")].startswith("skipped")
    assert check_head == ["check", "value", "target", "result"] and len(checks) == 2
    for check in checks:
        assert _number_or_skipped(check[1]) and check[3] in PASS_VALUES
        assert not check[1].startswith("skipped")  # both checks had their sizes measured


def test_train_benchmark_quick_run_prints_its_table() -> None:
    pytest.importorskip("stable_baselines3")
    pytest.importorskip("supersuit")
    cmd = [
        sys.executable,
        str(ROOT / "benchmarks" / "bench_train.py"),
        "--quick",
        "--rounds",
        "1",
        "--block-s",
        "0.005",
    ]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.startswith("machine: ") and "\ndate: " in res.stdout
    ((head, rows),) = _tables(res.stdout)
    assert head[0] == "slots (WxN)" and [r[0] for r in rows] == ["16 (4x4)", "64 (16x4)"]
    for row in rows:
        assert len(row) == len(head)
        for name, cell in zip(head[1:], row[1:]):
            if name not in ("target", "result"):
                assert _number_or_skipped(cell) and not cell.startswith("skipped"), (row[0], name, cell)
    assert rows[0][head.index("result")] == "-" and rows[1][head.index("result")] in PASS_VALUES - {"-"}


@pytest.mark.slow
def test_viewer_benchmark_quick_run_prints_its_table() -> None:
    pytest.importorskip("playwright")
    cmd = [sys.executable, str(ROOT / "benchmarks" / "bench_viewer.py"), "--quick"]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.startswith("machine: ") and "\ndate: " in res.stdout
    ((head, rows),) = _tables(res.stdout)
    assert head[:2] == ["agents", "frame KiB"] and [r[0] for r in rows] == ["100"]
    for name, cell in zip(head, rows[0]):
        if name not in ("agents", "target", "result", "slowdown"):
            assert _number_or_skipped(cell) and not cell.startswith("skipped"), (name, cell)
    assert float(rows[0][head.index("page updates/s")]) > 0  # the browser received frames
    assert rows[0][head.index("result")] in PASS_VALUES - {"-"}


def test_markdown_table_and_number_cells() -> None:
    table = common.markdown_table(["a", "bb"], [["1", "22,000"], ["skipped (x)", "3.5"]])
    lines = table.splitlines()
    assert len(lines) == 4 and all(line.startswith("|") and line.endswith("|") for line in lines)
    assert len({len(line) for line in lines}) == 1  # columns padded to one width
    assert common.fmt_num(123456.7) == "123,457" and common.fmt_num(0.01234) == "0.0123"
    with pytest.raises(ValueError, match="finite"):
        common.fmt_num(float("nan"))


def test_measure_interleaved_counts_agent_steps() -> None:
    calls = {"a": 0, "b": 0}

    def step_a() -> int:
        calls["a"] += 1
        return 3

    def step_b() -> int:
        calls["b"] += 1
        return 0

    stats = common.measure_interleaved(
        {"a": common.Case(step_a), "b": common.Case(step_b)}, rounds=3, block_s=0.0, warmup=1
    )
    assert calls == {"a": 1 + 1 + 3, "b": 1 + 1 + 3}  # warm-up, calibration, then one step per round
    assert stats["a"].rounds == 3 and stats["a"].steps_per_block == 1
    assert stats["a"].agent_steps_per_s > 0 and stats["b"].agent_steps_per_s == 0


@pytest.mark.slow
def test_perf_benchmark_quick_run_prints_every_row_with_target_and_result(tmp_path: Path) -> None:
    plot, thread_plot = tmp_path / "scaling.png", tmp_path / "threads.png"
    cmd = [
        sys.executable,
        str(ROOT / "benchmarks" / "bench_perf.py"),
        "--quick",
        "--no-coldstart",
        "--plot",
        str(plot),
        "--thread-plot",
        str(thread_plot),
    ]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert res.stdout.startswith("machine: ")
    (head, rows), (core_head, core_rows), (scale_head, scale_rows), (thr_head, thr_rows) = _tables(res.stdout)
    assert head == ["case", "result", "target", "met", "measured alongside"]
    cases = [r[0] for r in rows]
    for wanted in (
        "1x64, array API",
        "1x64, dict API",
        "512x4",
        "dict API cost",
        "full stack 1x200, dict API",
        "comms cost 1x500",
        "array API, no comms, 1 core",
        "2 threads vs 1",
        "full stack 1x5,000: 2 threads vs 1",
    ):
        assert any(wanted in c for c in cases), wanted
    for row in rows:
        value = row[1].split(" ")[0]
        assert _number_or_skipped(value) or value == "n/a", row
        assert row[3] in {"PASS", "short", "-", "n/a"}, row
        assert (row[2] == "-") == (row[3] == "-"), row  # a row has a target exactly when it has a verdict
    # the rows of the table carry targets in quick mode too
    assert {r[0] for r in rows if r[3] != "-"} >= {
        "navigation 1x64, array API",
        "navigation 512x4, array API (1 core)",
    }
    assert core_head[1] == "agent-steps/s per core" and any("C++" in r[0] for r in core_rows)
    assert scale_head == ["agents", "no comms", "full stack"] and len(scale_rows) == 2
    assert all(_number_or_skipped(c) for r in scale_rows for c in r[1:])
    assert plot.stat().st_size > 1000
    # the thread curve: one thread first (speed-up 1), then as many counts as the machine has cores for
    assert thr_head == ["threads", "ms/step", "speed-up"] and thr_rows[0][0] == "1" and thr_rows[0][2] == "1.00"
    assert [int(r[0]) for r in thr_rows] == [k for k in (1, 2, 4, 8, 16) if k <= available_cores()]
    assert thread_plot.stat().st_size > 1000


def test_run_all_finds_benchmarks_with_main() -> None:
    names = [p.stem for p in run_all.benchmarks()]
    assert "bench_step" in names and "bench_train" in names and "bench_perf" in names
    assert [p.stem for p in run_all.benchmarks(["step"])] == ["bench_step"]
    assert all(run_all.has_main(p) for p in run_all.benchmarks())


# ---- the hot-path kernels written for throughput must give exactly what their plain versions give ----
@given(st.integers(0, 2**32 - 1))
@settings(max_examples=40, deadline=None)
def test_compose_rewards_kernel_equals_numpy_reference(seed: int) -> None:
    from agentsim_env.scenarios.rewards import RewardConfig, compose_rewards
    from tests.reference.rewards import compose_rewards_reference

    rng = np.random.default_rng(seed)
    s, b, g = int(rng.integers(0, 40)), int(rng.integers(1, 4)), int(rng.integers(1, 4))
    cfg = RewardConfig(*(rng.uniform(0, 2, 5) * (rng.random(5) < 0.7)))
    kw = {
        "group": rng.integers(-1, g, s).astype(np.int32),
        "world": rng.integers(0, b, s).astype(np.int32),
        "acting": rng.random(s) < 0.8,
        "n_groups": g,
        "collided": (rng.random(s) < 0.2) * 1.0 if rng.random() < 0.7 else None,
        "energy": rng.random(s),
        "messages_sent": rng.integers(0, 3, s) if rng.random() < 0.5 else None,
    }
    task = rng.normal(size=s)
    np.testing.assert_array_equal(compose_rewards(cfg, task, **kw), compose_rewards_reference(cfg, task, **kw))


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=40, deadline=None)
def test_unchecked_velocity_decoder_equals_validated_one(seed: int) -> None:
    from agentsim_env.motion import MotionState, decode_velocity, set_circular
    from agentsim_env.motion.actions import decode_velocity_unchecked

    rng = np.random.default_rng(seed)
    s = int(rng.integers(1, 20))
    a, b = MotionState.create(s), MotionState.create(s)
    pos = rng.uniform(0, 10, (s, 3))
    for ms in (a, b):  # a running primitive with parameters the decoder must clear
        set_circular(ms, np.arange(s), pos, pos[:, :2] + 1.0, 2.0, 0.5, 3.0)
    acting = rng.random(s) < 0.7
    actions = rng.uniform(-1.5, 1.5, (s, 3))
    vmax = rng.uniform(0, 6, s)
    slots = np.flatnonzero(acting)
    decode_velocity(a, slots, actions[slots], vmax[slots])
    decode_velocity_unchecked(b, acting, actions, vmax)
    for name in ("kind", "params", "t", "n_waypoints", "wp_index", "loop", "done"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_navigation_observe_kernel_equals_numpy_statement() -> None:
    from agentsim_env.env.vector import BatchedEnv

    env = BatchedEnv("navigation", 3, n_agents=5)
    env.reset(seed=1)
    rng = np.random.default_rng(2)
    for _ in range(15):
        env.step(rng.uniform(-1, 1, (3, 5, env.act_dim)))
    sc, world = env.scenario, env.world
    c, stt, scan = sc.config, world.state, world.scan
    s, (lo, hi) = c.side, c.body.altitude
    selfp = np.column_stack(
        [
            stt.pos[:, 0] / s * 2 - 1,
            stt.pos[:, 1] / s * 2 - 1,
            (stt.pos[:, 2] - lo) / (hi - lo) * 2 - 1,
            stt.vel / c.body.max_speed,
            np.cos(stt.heading),
            np.sin(stt.heading),
        ]
    )
    diag = s * np.sqrt(2.0)
    d = world.task.goal - stt.pos
    expected = {
        "self": np.clip(selfp, -1, 1).astype(np.float32),
        "lidar": np.stack([scan.distance, scan.hit_kind / 3.0], axis=-1).astype(np.float32),
        "task": np.clip(np.column_stack([d / diag, np.linalg.norm(d, axis=1) / diag]), -1, 1).astype(np.float32),
    }
    got = sc.observe(world)
    assert list(got) == list(expected)
    for k, v in expected.items():
        assert got[k].dtype == np.float32 and got[k].shape == v.shape
        # cos / sin may differ in the last float64 bit between numpy builds and libm: 1 float32 ulp at most
        np.testing.assert_allclose(got[k], v, rtol=0, atol=1.2e-7 if k == "self" else 0, err_msg=k)


@pytest.mark.slow
def test_soak_tiny_run_prints_its_table_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import soak

    png = tmp_path / "rss.png"
    rc = soak.main(["--steps", "2000", "--missions", "2", "--agents", "20", "--no-progress", "--plot", str(png)])
    out = capsys.readouterr().out
    assert rc in (0, 1)  # growth over so short a run is noise: only the output is checked here
    assert out.startswith("machine: ") and png.stat().st_size > 0
    ((head, rows),) = _tables(out)
    assert head[0] == "phase" and head[-1] == "result" and len(rows) == 2
    for row in rows:
        assert len(row) == len(head) and row[-1] in {"PASS", "FAIL"}
        for cell in row[2:-1]:
            assert math.isfinite(float(cell.replace(",", "").replace("+", ""))), (row[0], cell)
    assert "soak" not in [p.stem for p in run_all.benchmarks()]  # make bench never runs it
