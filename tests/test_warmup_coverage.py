"""``agentsim warmup`` covers every kernel the shipped commands reach: after it, nothing compiles.

One empty numba cache directory (``NUMBA_CACHE_DIR`` in a temporary folder, as in ``tests/test_cold_start.py``)
is warmed by ``agentsim warmup``; then one process runs, on small sizes, the README's command lines, every
scenario with every scripted baseline, ``evaluate`` with every strategy, short ``train`` runs with their
evaluation against the baselines, a recorded run and its replay, and the README quickstart. A listener on
numba's compile event names every package kernel that compiled, and under which command: the list must be
empty. A run over Ray shards (when Ray is installed) must add no signature to the cache either. (A kernel
compiles once per signature, so a command that hands a kernel other argument types than the warm-up did,
another dtype, layout or read-only flag, shows up here.)
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

# Runs the commands given as a JSON list of argument lists (``agentsim ARGS...``) and Python snippets
# (``["python", CODE]``) in this one process; prints one JSON line: {command: [kernels compiled]}.
DRIVER = r"""
import contextlib, io, json, sys
from numba.core import event
from agentsim_env.cli import main

current = ["import"]
compiled = {}

class Listener(event.Listener):
    def on_start(self, ev):
        func = getattr(ev.data.get("dispatcher"), "py_func", None)
        module = getattr(func, "__module__", "") or ""
        if module.startswith("agentsim_env"):
            compiled.setdefault(current[0], []).append(f"{module}.{func.__name__} {ev.data.get('args')}")

    def on_end(self, ev):
        pass

event.register("numba:compile", Listener())
for command in json.loads(sys.argv[1]):
    current[0] = " ".join(command)[:200]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        if command[0] == "python":
            exec(command[1], {})
            rc = 0
        else:
            rc = main(command)
    if rc != 0:
        raise SystemExit(f"{current[0]!r} exited with {rc}: {out.getvalue()[-2000:]}")
print("COMPILED " + json.dumps(compiled))
"""


def readme_quickstart() -> str:
    """The README's quickstart code, as a newcomer copies it (the first Python block of its Quickstart)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Quickstart") :]
    start = section.index("```python\n") + len("```python\n")
    return section[start : section.index("```", start)]


def _commands(out: Path) -> list[list[str]]:
    from agentsim_env.policies.registry import BASELINES

    o = ["--quiet", "--out", str(out / "runs")]
    tiny_uav = ["zones=tiny", "n_uavs=2"]
    commands = [
        # the README's command lines, at small sizes (a live window replaced by a batch run)
        ["run", "navigation", "--episodes", "2", *o],
        ["run", "navigation", "--episodes", "1", "--set", "comms={}", *o],
        [
            "run",
            "navigation",
            "--set",
            "n_agents=32",
            "physics=pymunk",
            "collisions=false",
            "body.radius=0.8",
            "--policy",
            "go_to_goal",
            "--episodes",
            "1",
            *o,
        ],
        [
            "run",
            "navigation",
            "--policy",
            "random",
            "--set",
            "n_agents=8",
            "collisions=false",
            "body.max_speed=8",
            "--episodes",
            "1",
            *o,
        ],
        ["run", "navigation", "--threads", "2", "--set", "n_agents=64", "--episodes", "1", *o],
        ["run", "relay", "--episodes", "3", *o],
        ["run", "relay", "--set", "gap=12,20", "comms.loss=0.1", "--episodes", "1", *o],
        ["run", "uav_release", "--set", *tiny_uav, "--episodes", "1", *o],
        [
            "evaluate",
            "--zones",
            "tiny",
            "--strategies",
            "all",
            "--seeds",
            "1",
            "--no-plots",
            "--quiet",
            "--out",
            str(out / "evaluation"),
        ],
        ["run", "navigation", "--episodes", "1", "--record", str(out / "run.db"), *o],
        [
            "replay",
            str(out / "run.db"),
            "--episode",
            "0",
            "--every",
            "100",
            "--out",
            str(out / "frames") + "/",
        ],
        ["python", readme_quickstart()],
    ]
    for scenario, baselines in BASELINES.items():  # every scenario x every baseline
        sets = ["--set", *tiny_uav] if scenario == "uav_release" else []
        commands += [["run", scenario, "--policy", b, "--episodes", "1", *sets, *o] for b in baselines]
    for scenario in ("navigation", "relay"):  # training's vector env, then its quick evaluation
        commands.append(
            [
                "train",
                scenario,
                "--timesteps",
                "256",
                "--worlds",
                "2",
                "--quiet",
                "--set",
                "eval.seeds=1",
                "--out",
                str(out / "train" / scenario),
            ]
        )
    commands.append(
        [
            "train",
            "uav_release",
            "--timesteps",
            "256",
            "--worlds",
            "2",
            "--quiet",
            "--no-eval",
            "--set",
            *[f"env.{s}" for s in tiny_uav],
            "--out",
            str(out / "train" / "uav_release"),
        ]
    )
    return commands


def _env(cache: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "AGENTSIM_QUIET_COMPILE"}
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env |= {
        "NUMBA_CACHE_DIR": str(cache),
        "NUMBA_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "1",
        "SDL_VIDEODRIVER": "dummy",
        "MPLBACKEND": "Agg",
    }
    return env


@pytest.mark.slow
def test_after_warmup_no_shipped_command_compiles_a_kernel(tmp_path: Path) -> None:
    env = _env(tmp_path / "numba-cache")
    warm = subprocess.run(
        [sys.executable, "-m", "agentsim_env.cli", "warmup", "--quiet"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert warm.returncode == 0, warm.stderr[-3000:]
    res = subprocess.run(
        [sys.executable, "-c", DRIVER, json.dumps(_commands(tmp_path))],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    line = next(x for x in res.stdout.splitlines() if x.startswith("COMPILED "))
    compiled = json.loads(line[len("COMPILED ") :])
    assert compiled == {}, "compiled after 'agentsim warmup':\n" + json.dumps(compiled, indent=1)[:6000]
    assert "compiling simulation kernels" not in res.stderr
    if importlib.util.find_spec("ray") is None:
        return
    # shards on Ray compile in the worker processes, out of the listener's sight: a kernel compiled there adds a
    # signature to the cache's index files
    before = _cache_index(tmp_path / "numba-cache")
    ray = subprocess.run(
        [
            sys.executable,
            "-m",
            "agentsim_env.cli",
            "run",
            "relay",
            "--shards",
            "2",
            "--episodes",
            "1",
            "--quiet",
            "--out",
            str(tmp_path / "ray"),
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert ray.returncode == 0, ray.stderr[-3000:]
    after = _cache_index(tmp_path / "numba-cache")
    assert after == before, f"compiled by the Ray shards: {sorted(k for k in after if after[k] != before.get(k))}"


def _cache_index(cache: Path) -> dict[str, bytes]:
    """Every index file of a numba cache directory (one per kernel, listing its compiled signatures)."""
    return {str(p.relative_to(cache)): p.read_bytes() for p in cache.rglob("*.nbi")}


# ------------------------------------------------------------------------------------------------ fast
def test_the_inboxpush_kernel_has_one_signature_whatever_producers_hand_it() -> None:
    # strided broadcasts (several messages of one kind or hop count), their one-message cuts (contiguous),
    # read-only arrays (as Ray hands shards) and other integer dtypes all reach the kernel in one form: a run
    # can never compile a version the warm-up did not
    from agentsim_env.comms.inbox import Inbox
    from agentsim_env.comms.inbox_kernels import push_kernel

    inbox = Inbox(4, 2, 2)
    ids = np.arange(3, dtype=np.int64)
    frozen = ids.copy()
    frozen.flags.writeable = False
    forms = [
        (
            ids,
            np.ones(3, dtype=np.int8),
            ids,
            np.broadcast_to(np.zeros(1, dtype=np.int16), (3,)),
            ids,
            np.zeros((3, 2), dtype=np.float32),
            ids[:0],
        ),
        (
            ids[:1],
            np.broadcast_to(np.ones(1, dtype=np.int8), (1,)),
            ids[:1],
            np.zeros(1, dtype=np.int32),
            ids[:1],
            np.zeros((1, 2), dtype=np.float32),
            ids[:0],
        ),
        (
            frozen,
            np.ones(3, dtype=np.int8),
            frozen,
            frozen,
            frozen,
            np.zeros((3, 2), dtype=np.float64),
            frozen[:0],
        ),
    ]
    for a in forms:
        for b in forms:
            inbox.push_batches([a, b])
        inbox.push_batches([a])
    assert len(push_kernel.signatures) == 1, push_kernel.signatures
    assert inbox.received.tolist() == [
        21,
        14,
        14,
        0,
    ]  # 21 batches reach slot 0, the 14 of three messages 1 and 2
