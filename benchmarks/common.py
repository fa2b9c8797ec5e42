"""Timing helpers shared by the benchmarks: one thread, interleaved rounds, medians, a machine line, tables.

Import this module before numpy, numba or torch: it pins every thread pool to one thread (2 threads on a
shared 2-core machine are noisy, and single-thread numbers compare systems on equal terms). Systems are timed
interleaved: each round runs one block of steps of every system in turn, so a load change on the machine
hits all of them alike; the reported number is the median over rounds. Blocks are timed with the process's
CPU time (robust to other processes taking the core) and with wall time (shown alongside).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from importlib import metadata  # noqa: E402

import numpy as np  # noqa: E402


def torch_single_thread() -> None:
    """Import torch (if installed) and pin its intra- and inter-op pools to one thread."""
    try:
        import torch
    except ImportError:
        return
    torch.set_num_threads(1)
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # only settable once, before any parallel work
        pass


def _version(pkg: str) -> str:
    try:
        return metadata.version(pkg)
    except metadata.PackageNotFoundError:
        return "-"


def machine_description() -> str:
    """One line: CPU model and count, OS, Python, the numeric packages' versions, threads and load."""
    model = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    pkgs = ", ".join(f"{p} {_version(p)}" for p in ("numpy", "numba", "torch", "vmas", "mpe2", "pymunk"))
    return (
        f"{model} x {os.cpu_count()} logical CPUs; {platform.system()} {platform.release()}; "
        f"Python {platform.python_version()}; {pkgs}; NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS')}, "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}; load average {load:.2f}"
    )


@dataclass
class Case:
    """One system at one size.

    Attributes:
        step: Advances the system by one step and returns the number of agent-steps it did.
        prepare: Run (untimed) before every block, e.g. to reset an env whose agents are all done.
    """

    step: Callable[[], int]
    prepare: Callable[[], None] | None = None


@dataclass
class Stats:
    """Medians over rounds of one case.

    Attributes:
        step_s: Median CPU seconds per step.
        wall_step_s: Median wall seconds per step.
        agent_steps_per_s: Median agent-steps per CPU second.
        rounds: Number of blocks timed.
        steps_per_block: Steps in each block.
    """

    step_s: float
    wall_step_s: float
    agent_steps_per_s: float
    rounds: int
    steps_per_block: int
    samples: list[float] = field(default_factory=list)


def _block(case: Case, n: int) -> tuple[float, float, int]:
    if case.prepare is not None:
        case.prepare()
    agents = 0
    c0, w0 = time.process_time(), time.perf_counter()
    for _ in range(n):
        agents += case.step()
    return time.process_time() - c0, time.perf_counter() - w0, agents


def measure_interleaved(
    cases: dict[str, Case], rounds: int, block_s: float, warmup: int = 2, max_block_steps: int = 2000
) -> dict[str, Stats]:
    """Time every case in interleaved rounds and return per-case medians.

    Args:
        cases: Name -> case.
        rounds: Timed rounds (each runs one block of every case, in turn).
        block_s: Target length of a block in seconds (a block has at least one step).
        warmup: Untimed steps per case first (numba compilation, caches, allocator).
        max_block_steps: Upper bound on steps per block.

    Returns:
        Name -> statistics.
    """
    steps: dict[str, int] = {}
    for name, case in cases.items():
        _block(case, warmup)
        cpu, wall, _ = _block(case, 1)
        steps[name] = int(min(max_block_steps, max(1, block_s / max(wall, cpu, 1e-7))))
    per_step: dict[str, list[float]] = {k: [] for k in cases}
    per_wall: dict[str, list[float]] = {k: [] for k in cases}
    rate: dict[str, list[float]] = {k: [] for k in cases}
    for _ in range(rounds):
        for name, case in cases.items():
            cpu, wall, agents = _block(case, steps[name])
            cpu = max(cpu, 1e-9)
            per_step[name].append(cpu / steps[name])
            per_wall[name].append(wall / steps[name])
            rate[name].append(agents / cpu)
    return {
        k: Stats(
            float(np.median(per_step[k])),
            float(np.median(per_wall[k])),
            float(np.median(rate[k])),
            rounds,
            steps[k],
            per_step[k],
        )
        for k in cases
    }


def fmt_num(x: float) -> str:
    """A finite number for a table cell: thousands separators, three significant digits below 100."""
    if not math.isfinite(x):
        raise ValueError(f"table cells must be finite numbers, got {x}")
    if abs(x) >= 100:
        return f"{x:,.0f}"
    return f"{x:#.3g}".rstrip(".")


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table (cells are strings, padded to the column width)."""
    width = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(headers)]
    line = "| " + " | ".join(str(h).ljust(w) for h, w in zip(headers, width)) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in width) + "|"
    body = ["| " + " | ".join(str(c).ljust(w) for c, w in zip(r, width)) + " |" for r in rows]
    return "\n".join([line, sep, *body])
