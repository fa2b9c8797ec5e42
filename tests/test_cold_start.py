"""Cold start: the one-line compile notice (``agentsim_env._compile_notice``) and the cold-start benchmark.

The subprocess cases give each process its own numba cache directory (``NUMBA_CACHE_DIR`` in a temporary
folder), so "must compile" and "loads from the cache" do not depend on the state of the repository's cache.
The kernel they compile is one small scalar function, ``_landing_time_nb`` of ``agentsim_env.motion.integrate``,
under two signatures (float64, float32): two compilations, which must give one line.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from agentsim_env import _compile_notice
from agentsim_env._compile_notice import NOTICE, QUIET_ENV
from tests.bench_tables import markdown_tables

ROOT = Path(__file__).resolve().parents[1]

TWO_COMPILES = """
import os, sys
if os.environ.get("IMPORT_NUMBA_FIRST"):
    import numba
import numpy as np
from agentsim_env.motion.integrate import _landing_time_nb as f
f(1.0, 2.0, 9.8, 3.0)
f(np.float32(1.0), np.float32(2.0), np.float32(9.8), np.float32(3.0))
print("signatures", len(f.signatures))
"""

FIRST_STEP = """
import agentsim_env
env = agentsim_env.make("navigation", n_agents=2)
env.reset(seed=0)
env.step({a: env.action_space(a).sample() for a in env.agents})
print("stepped")
"""


def _run(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    base = {k: v for k, v in os.environ.items() if k != QUIET_ENV}
    base["PYTHONPATH"] = str(ROOT) + (os.pathsep + base["PYTHONPATH"] if base.get("PYTHONPATH") else "")
    base.setdefault("NUMBA_NUM_THREADS", "1")
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=base | env, capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-3000:]
    return res


def _notices(res: subprocess.CompletedProcess[str]) -> int:
    return res.stderr.count("compiling simulation kernels")


# ------------------------------------------------------------------------------------ subprocesses
@pytest.mark.parametrize("numba_first", [False, True], ids=["package-first", "numba-first"])
def test_compiling_prints_one_line_and_the_cached_start_none(tmp_path: Path, numba_first: bool) -> None:
    extra = {"IMPORT_NUMBA_FIRST": "1"} if numba_first else {}
    res = _run(TWO_COMPILES, NUMBA_CACHE_DIR=str(tmp_path), **extra)
    assert "signatures 2" in res.stdout
    assert _notices(res) == 1 and res.stderr.count(NOTICE) == 1
    assert list(tmp_path.rglob("*.nbi")), "nothing was cached"
    again = _run(TWO_COMPILES, NUMBA_CACHE_DIR=str(tmp_path), **extra)  # both signatures load from the cache
    assert "signatures 2" in again.stdout and _notices(again) == 0


def test_quiet_variable_silences_the_notice(tmp_path: Path) -> None:
    res = _run(TWO_COMPILES, NUMBA_CACHE_DIR=str(tmp_path), **{QUIET_ENV: "1"})
    assert "signatures 2" in res.stdout and _notices(res) == 0
    assert list(tmp_path.rglob("*.nbi")), "the kernels compiled all the same"


def test_second_process_on_the_warm_cache_prints_nothing() -> None:
    # the repository's own cache (filled by ``agentsim warmup``); the first run recompiles whatever a source
    # edit since then made stale, the second must then load everything
    _run(FIRST_STEP)
    res = _run(FIRST_STEP)
    assert "stepped" in res.stdout and _notices(res) == 0, res.stderr[-2000:]


def test_cli_notice_stands_for_the_library_notice(tmp_path: Path) -> None:
    # ``agentsim run`` / ``warmup`` announce a cold cache themselves; the compilation that follows adds no line
    code = "from agentsim_env.cli import announce_compile\nassert announce_compile()\n" + TWO_COMPILES
    res = _run(code, NUMBA_CACHE_DIR=str(tmp_path))
    assert _notices(res) == 1 and NOTICE not in res.stderr
    quiet = _run(code, NUMBA_CACHE_DIR=str(tmp_path / "other"), **{QUIET_ENV: "1"})
    assert _notices(quiet) == 0


def test_importing_the_package_does_not_import_numba() -> None:
    res = _run("import sys, agentsim_env\nprint('numba' in sys.modules)")
    assert res.stdout.strip() == "False"


# -------------------------------------------------------------------------------------- in process
def test_notify_prints_once_and_only_for_package_functions(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(_compile_notice._state, "shown", False)
    monkeypatch.delenv(QUIET_ENV, raising=False)

    def outside() -> None: ...

    def inside() -> None: ...

    inside.__module__ = "agentsim_env.core.spatial"
    assert not _compile_notice.notify(outside) and not _compile_notice.notify(None)
    assert not _compile_notice.shown()
    assert _compile_notice.notify(inside) and not _compile_notice.notify(inside)
    assert capsys.readouterr().err == NOTICE + "\n"
    assert _compile_notice.is_package_function(inside) and not _compile_notice.is_package_function(outside)
    fake = type("F", (), {"__module__": "agentsim_envx.kernels"})()
    assert not _compile_notice.is_package_function(fake)


@pytest.mark.parametrize(("value", "quiet"), [("1", True), ("yes", True), ("0", False), ("", False)])
def test_quiet_values(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], value: str, quiet: bool
) -> None:
    monkeypatch.setitem(_compile_notice._state, "shown", False)
    monkeypatch.setenv(QUIET_ENV, value)
    assert _compile_notice.quiet() is quiet

    def inside() -> None: ...

    inside.__module__ = "agentsim_env"
    assert _compile_notice.notify(inside) is not quiet
    assert (capsys.readouterr().err == "") is quiet and _compile_notice.shown()


def test_mark_shown_keeps_the_listener_silent(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(_compile_notice._state, "shown", False)
    _compile_notice.mark_shown()

    def inside() -> None: ...

    inside.__module__ = "agentsim_env.payloads.kernels"
    assert not _compile_notice.notify(inside) and capsys.readouterr().err == ""


# ----------------------------------------------------------------------------------------- benchmark
_tables = markdown_tables


def _number(cell: str) -> bool:
    try:
        float(cell.replace(",", ""))
    except ValueError:
        return False
    return True


@pytest.mark.slow
def test_coldstart_benchmark_quick_run_prints_its_table() -> None:
    cmd = [sys.executable, str(ROOT / "benchmarks" / "bench_coldstart.py"), "--quick", "--runs", "2"]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode in (0, 1), res.stderr[-3000:]  # 1: a case missed the target (no timing checks here)
    assert res.stdout.startswith("machine: ") and "\ndate: " in res.stdout
    ((head, rows),) = _tables(res.stdout)
    assert head == [
        "case",
        "warm start s",
        "warm CPU s",
        "warm process s",
        "warm runs compiling",
        "empty-cache start s",
        "target",
        "result",
    ]
    assert [r[0] for r in rows] == [
        "navigation",
        "relay",
        "uav_release quickstart (first step)",
        "agentsim warmup (empty cache)",
    ]
    for row in rows[:-1]:
        assert all(_number(c) for c in row[1:4] + row[5:6]), row
        compiled, runs = row[4].split("/")
        assert int(runs) == 2 and 0 <= int(compiled) <= 2, row
        assert row[6] == "<= 3 s" and row[7] in ("PASS", "FAIL"), row
    assert _number(rows[-1][5]) and float(rows[-1][5]) > 0
