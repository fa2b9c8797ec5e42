"""Cold start: ``import agentsim_env`` + ``make`` + ``reset`` + first ``step`` in a new Python process.

Every figure comes from separate Python processes (the same interpreter, the repository on ``PYTHONPATH``,
``NUMBA_NUM_THREADS`` and friends inherited as 1), each with its own numba cache directory
(``NUMBA_CACHE_DIR``), so the repository's own cache is neither used nor touched:

- ``agentsim warmup``: ``python -m agentsim_env.cli warmup --quiet`` on an empty cache directory, the step
  ``make install`` runs after installing (wall seconds of the whole process);
- **warm start** (the target): a process started after that warm-up, on the cache it filled: the wall time
  from before ``import agentsim_env`` to the end of the first ``step``, measured inside the process; the
  median over the runs, which go round the cases in turn. Also shown: the process's CPU time at that point
  (interpreter start included) and the wall time of the whole process (start to exit);
- **empty-cache start**: the same on a fresh, empty cache directory each run, what a user who skipped the
  warm-up sees once (the kernels compile);
- **warm runs compiling**: how many warm runs compiled a package kernel (the compile notice's flag,
  ``agentsim_env._compile_notice.shown()``): 0 means the warm-up covers the case (a source file edited during
  the run makes one run recompile what it changed).

Cases: ``navigation`` and ``relay`` with their defaults and random actions, and the README's quickstart up to its
first step (``uav_release`` with the default zones and ``render_mode="rgb_array"``, the ``B5_cvt`` strategy);
the full run adds the whole README quickstart (a full mission, ``render()``, ``evaluate_deployment``) as an
information row without a target.

Target: warm start <= 3 s per case.

Run: ``.venv/bin/python benchmarks/bench_coldstart.py [--quick] [--runs N] [--cold-runs M]``
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import textwrap  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import common  # noqa: E402  (pins thread pools, which the child processes inherit)

ROOT = Path(__file__).resolve().parents[1]
TARGET_S = 3.0
MARK = "COLDSTART "
TIMEOUT_S = 600

_RANDOM_STEP = """
import agentsim_env
env = agentsim_env.make({name!r})
obs, infos = env.reset(seed=0)
for a in env.agents:
    env.action_space(a).seed(0)
env.step({{a: env.action_space(a).sample() for a in env.agents}})
"""

_QUICKSTART_FIRST_STEP = """
import agentsim_env
from agentsim_env.policies.registry import make_policy

env = agentsim_env.make("uav_release", render_mode="rgb_array")
obs, infos = env.reset(seed=0)
policy = make_policy("uav_release", env, "B5_cvt")
policy.reset(seed=0)
obs, rewards, terminations, truncations, infos = env.step(policy.act({a: obs[a] for a in env.agents}))
"""

_QUICKSTART_WHOLE = """
import agentsim_env
from agentsim_env.policies.registry import make_policy

env = agentsim_env.make("uav_release", render_mode="rgb_array")
obs, infos = env.reset(seed=0)
policy = make_policy("uav_release", env, "B5_cvt")
policy.reset(seed=0)
while env.agents:
    obs, rewards, terminations, truncations, infos = env.step(policy.act({a: obs[a] for a in env.agents}))
frame = env.render()

from agentsim_env.uav.wsn import evaluate_deployment
zones = env.scenario.zones
metrics = evaluate_deployment(env.world.payloads.objects.landed_xy(), None, zones.centres(), zones.radii(),
                              [z.radial_profile() for z in zones.zones])
"""

_FOOTER = """
__t1 = __time.perf_counter()
import json as __json
from agentsim_env import _compile_notice as __notice
print({mark!r} + __json.dumps({{"s": __t1 - __t0, "cpu": __time.process_time(), "compiled": __notice.shown()}}))
"""


@dataclass(frozen=True)
class ColdCase:
    """One start-up script: its table label, its code, and whether the 3 s target applies to it."""

    label: str
    code: str
    targeted: bool = True

    def script(self) -> str:
        """The code wrapped with the timer and the line that reports to the parent."""
        head = "import time as __time\n__t0 = __time.perf_counter()\n"
        return head + textwrap.dedent(self.code) + _FOOTER.format(mark=MARK)


CASES = [
    ColdCase("navigation", _RANDOM_STEP.format(name="navigation")),
    ColdCase("relay", _RANDOM_STEP.format(name="relay")),
    ColdCase("uav_release quickstart (first step)", _QUICKSTART_FIRST_STEP),
]
WHOLE_QUICKSTART = ColdCase("README quickstart (whole script)", _QUICKSTART_WHOLE, targeted=False)


@dataclass(frozen=True)
class Run:
    """What one child process reported."""

    s: float  # wall seconds from before the import to the end of the case's code
    cpu: float  # the process's CPU seconds at that point
    process_s: float  # wall seconds of the whole process, measured by the parent
    compiled: bool  # a package kernel compiled in the process


def _child_env(cache_dir: str) -> dict[str, str]:
    env = dict(os.environ)
    env["NUMBA_CACHE_DIR"] = cache_dir
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.pop("AGENTSIM_QUIET_COMPILE", None)
    return env


def run_case(case: ColdCase, cache_dir: str) -> Run:
    """Run ``case`` in a new process on the numba cache ``cache_dir``."""
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, "-c", case.script()],
        cwd=ROOT,
        env=_child_env(cache_dir),
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )
    process_s = time.perf_counter() - t0
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith(MARK)]
    if res.returncode != 0 or not lines:
        raise RuntimeError(f"{case.label}: exit {res.returncode}\n{res.stderr[-3000:]}")
    data = json.loads(lines[-1][len(MARK) :])
    return Run(float(data["s"]), float(data["cpu"]), process_s, bool(data["compiled"]))


def run_warmup(cache_dir: str) -> float:
    """Wall seconds of ``agentsim warmup --quiet`` filling ``cache_dir``."""
    t0 = time.perf_counter()
    res = subprocess.run(
        [sys.executable, "-m", "agentsim_env.cli", "warmup", "--quiet"],
        cwd=ROOT,
        env=_child_env(cache_dir),
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
    )
    if res.returncode != 0:
        raise RuntimeError(f"agentsim warmup: exit {res.returncode}\n{res.stderr[-3000:]}")
    return time.perf_counter() - t0


def coldstart_rows(
    quick: bool, runs: int | None = None, cold_runs: int | None = None, whole_quickstart: bool | None = None
) -> list[dict[str, Any]]:
    """Measure every case (see the module docstring) and return one dict per case.

    Args:
        quick: Fewer runs: 3 warm runs and 1 empty-cache run per case, one warm-up, no whole-quickstart row
            (full: 7, 3, 2, with it).
        runs: Warm runs per case (overrides the mode's).
        cold_runs: Empty-cache runs per case (overrides the mode's).
        whole_quickstart: Add the whole README quickstart row (default: in full mode only).

    Returns:
        Dicts with the keys ``case`` (label), ``warm_s`` (median wall seconds, import to end of the first step,
        on the warmed cache), ``warm_cpu_s`` (median CPU seconds of the process at that point),
        ``warm_process_s`` (median wall seconds of the whole process), ``warm_runs``, ``warm_runs_compiled``
        (how many warm runs compiled a package kernel; 0 when the warm-up covers the case), ``cold_s`` (median of the
        same on an empty cache),
        ``cold_runs``, ``warmup_s`` (median wall seconds of ``agentsim warmup`` on an empty cache, the same in
        every row), ``target_s`` (3.0, or None for the information row) and ``passed`` (``warm_s <= target_s``,
        or None without a target).
    """
    n_warm = runs or (3 if quick else 7)
    n_cold = cold_runs or (1 if quick else 3)
    n_warmup = 1 if quick else 2
    whole = not quick if whole_quickstart is None else whole_quickstart
    cases = [*CASES, WHOLE_QUICKSTART] if whole else CASES
    with tempfile.TemporaryDirectory(prefix="bench_coldstart_") as tmp:
        warmups = []
        for i in range(n_warmup):
            cache = os.path.join(tmp, f"warm{i}")
            warmups.append(run_warmup(cache))
        warm_cache = os.path.join(tmp, f"warm{n_warmup - 1}")
        warm: dict[str, list[Run]] = {c.label: [] for c in cases}
        for _ in range(n_warm):  # round-robin, so a load change hits every case alike
            for c in cases:
                warm[c.label].append(run_case(c, warm_cache))
        cold: dict[str, list[Run]] = {c.label: [] for c in cases}
        for i in range(n_cold):
            for j, c in enumerate(cases):
                cold[c.label].append(run_case(c, os.path.join(tmp, f"cold{i}_{j}")))
    warmup_s = statistics.median(warmups)
    rows = []
    for c in cases:
        w, k = warm[c.label], cold[c.label]
        warm_s = statistics.median(r.s for r in w)
        target = TARGET_S if c.targeted else None
        rows.append(
            {
                "case": c.label,
                "warm_s": warm_s,
                "warm_cpu_s": statistics.median(r.cpu for r in w),
                "warm_process_s": statistics.median(r.process_s for r in w),
                "warm_runs": len(w),
                "warm_runs_compiled": sum(r.compiled for r in w),
                "cold_s": statistics.median(r.s for r in k),
                "cold_runs": len(k),
                "warmup_s": warmup_s,
                "target_s": target,
                "passed": None if target is None else warm_s <= target,
            }
        )
    return rows


def table(rows: list[dict[str, Any]]) -> str:
    """The markdown table of ``coldstart_rows``'s rows, with the warm-up as its last row."""
    headers = [
        "case",
        "warm start s",
        "warm CPU s",
        "warm process s",
        "warm runs compiling",
        "empty-cache start s",
        "target",
        "result",
    ]
    body = []
    for r in rows:
        body.append(
            [
                r["case"],
                common.fmt_num(r["warm_s"]),
                common.fmt_num(r["warm_cpu_s"]),
                common.fmt_num(r["warm_process_s"]),
                f"{r['warm_runs_compiled']}/{r['warm_runs']}",
                common.fmt_num(r["cold_s"]),
                "-" if r["target_s"] is None else f"<= {r['target_s']:g} s",
                "-" if r["passed"] is None else ("PASS" if r["passed"] else "FAIL"),
            ]
        )
    if rows:
        body.append(
            [
                "agentsim warmup (empty cache)",
                "-",
                "-",
                "-",
                "-",
                common.fmt_num(rows[0]["warmup_s"]),
                "-",
                "-",
            ]
        )
    return common.markdown_table(headers, body)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Measure, print the machine line and the table, and return the rows."""
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 warm runs and 1 empty-cache run per case, 1 warm-up")
    ap.add_argument("--runs", type=int, default=None, help="warm runs per case (default 7, quick 3)")
    ap.add_argument("--cold-runs", type=int, default=None, help="empty-cache runs per case (default 3, quick 1)")
    args = ap.parse_args(argv)
    if (args.runs is not None and args.runs < 1) or (args.cold_runs is not None and args.cold_runs < 1):
        ap.error("--runs and --cold-runs must be at least 1")
    print(f"machine: {common.machine_description()}")
    print(f"date: {time.strftime('%Y-%m-%d')}")
    rows = coldstart_rows(args.quick, args.runs, args.cold_runs)
    print(
        f"mode: {'quick' if args.quick else 'full'}; {rows[0]['warm_runs']} warm runs and {rows[0]['cold_runs']} "
        "empty-cache run(s) per case, each a new process with its own NUMBA_CACHE_DIR; medians, wall time"
    )
    print()
    print(table(rows))
    print()
    print(
        "warm start: wall seconds from before `import agentsim_env` to the end of the first step, in a process "
        "started after `agentsim warmup` filled its cache; warm CPU s: the process's CPU time at that point "
        "(interpreter start included); warm process s: the whole process, start to exit; warm runs compiling: "
        "warm runs that compiled a package kernel (0: the warm-up covers the case); empty-cache start: the "
        "same without the warm-up (kernels compile)."
    )
    return {"rows": rows}


if __name__ == "__main__":
    out = main()
    sys.exit(0 if all(r["passed"] is not False for r in out["rows"]) else 1)
