"""The performance targets in one table: every row with its target, its result and whether it is met.

Rows (all ``navigation``; "full stack" is the comms config of ``bench_comms``: 32-ray 3D scan, bus, overlay with
hop limit 2, groups of 8, heartbeats, every agent sending one message per step):

- 1x64 array / dict API and 512x4 array API, agent-steps per CPU second (VMAS on CPU measured alongside);
- full stack 1x1,000 and 1x10,000, dict and array API, env-steps per CPU second;
- comms cost: the full-stack step over the same step without comms (array API);
- dict API cost above the array API at 1x1,000, microseconds per agent-step (``1/dict - 1/array``);
- 1x100,000 array API without comms, env-steps per CPU second on one core;
- 2 threads vs 1 at 1x100,000 (``num_threads=2``), wall-time ratio; needs 2 free cores;
- cold start: a second process's import + make + reset + first step (``bench_coldstart``).

Two more tables: per-core agent-steps/s with the 32-ray scan on, next to the published CPU anchor (a C++
batched engine, ~2M steps/s per core without sensing), and the scaling curve 1k -> 10k -> 100k agents (CPU
microseconds per agent-step, which should stay flat). ``--plot PATH`` draws the curve.

CPU time (``time.process_time``) for one-thread rows, wall time for the threads row; interleaved rounds,
medians (``common``).

Run: ``python benchmarks/bench_perf.py [--quick] [--plot scaling.png] [--no-coldstart]``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402, I001  (first: pins the thread pools)

import bench_comms  # noqa: E402
import bench_step  # noqa: E402
from common import fmt_num, machine_description, markdown_table, measure_interleaved  # noqa: E402

from agentsim_env.core.threads import available_cores  # noqa: E402

CPP_ANCHOR = 2_000_000  # agent-steps/s per core of a C++ batched engine without sensing (published figure)
T = TypeVar("T")


@dataclass
class Row:
    """One line of the targets table.

    Attributes:
        case: What is measured.
        value: The measured figure.
        unit: Its unit.
        target: The figure to reach.
        higher: Whether higher is better (else lower).
        note: A baseline or remark measured in the same run.
    """

    case: str
    value: float | None
    unit: str
    target: float | None
    higher: bool = True
    note: str = ""

    def cells(self) -> list[str]:
        """The table cells: case, result, target, met."""
        op = ">=" if self.higher else "<="
        if self.target is None:
            return [
                self.case,
                "n/a" if self.value is None else f"{fmt_num(self.value)} {self.unit}",
                "-",
                "-",
                self.note,
            ]
        if self.value is None:
            return [self.case, "n/a", f"{op} {fmt_num(self.target)} {self.unit}", "n/a", self.note]
        met = self.value >= self.target if self.higher else self.value <= self.target
        return [
            self.case,
            f"{fmt_num(self.value)} {self.unit}",
            f"{op} {fmt_num(self.target)} {self.unit}",
            "PASS" if met else "short",
            self.note,
        ]


THREAD_COUNTS = [1, 2, 4, 8, 16]
"""The thread scaling curve's counts (those above the machine's cores are left out)."""


def _vmas(b: int, n: int) -> common.Case | None:
    try:
        return bench_step.vmas_case(b, n, 0)
    except ImportError:
        return None


def small_worlds(rounds: int, block_s: float) -> tuple[list[Row], dict[str, float]]:
    """1x64 array / dict, 512x4 array, 1x1,000 array / dict (the dict API cost); VMAS alongside."""
    rows: list[Row] = []
    rates: dict[str, float] = {}
    for b, n in ((1, 64), (512, 4), (1, 1000)):
        cases: dict[str, common.Case] = {"array": bench_step.array_case(b, n, 0)}
        if b == 1:
            cases["dict"] = bench_step.dict_case(b, n, 0)
        if n != 1000:
            v = _vmas(b, n)
            if v is not None:
                cases["vmas"] = v
        st = measure_interleaved(cases, rounds=rounds, block_s=block_s, max_block_steps=bench_step.MAX_BLOCK_STEPS)
        for k, s in st.items():
            rates[f"{k} {b}x{n}"] = s.agent_steps_per_s
    vm = {k: rates.get(f"vmas {k}") for k in ("1x64", "512x4")}
    note = {k: (f"VMAS CPU {fmt_num(v)} ag-st/s" if v else "VMAS not installed") for k, v in vm.items()}
    rows.append(Row("navigation 1x64, array API", rates["array 1x64"], "ag-st/s", 1_000_000, note=note["1x64"]))
    rows.append(Row("navigation 1x64, dict API", rates["dict 1x64"], "ag-st/s", 700_000, note=note["1x64"]))
    rows.append(
        Row(
            "navigation 512x4, array API (1 core)",
            rates["array 512x4"],
            "ag-st/s",
            4_000_000,
            note=note["512x4"],
        )
    )
    cost = (1.0 / rates["dict 1x1000"] - 1.0 / rates["array 1x1000"]) * 1e6
    rows.append(
        Row(
            "dict API cost above the array API, 1x1,000",
            cost,
            "us/agent-step",
            0.4,
            higher=False,
            note=f"dict {fmt_num(rates['dict 1x1000'])}, array {fmt_num(rates['array 1x1000'])} ag-st/s",
        )
    )
    return rows, rates


def full_stack(sizes: list[int], rounds: int, block_s: float) -> list[Row]:
    """Full stack dict / array env-steps/s and the comms cost, per size."""
    rows: list[Row] = []
    targets = {1000: (1000, 2000), 10_000: (100, 200)}
    for n in sizes:
        cases = {
            "dict": bench_comms.dict_case(n, True),
            "array": bench_comms.array_case(n, True),
            "bare": bench_comms.array_case(n, False),
        }
        st = measure_interleaved(cases, rounds=rounds, block_s=block_s)
        e = {k: 1.0 / s.step_s for k, s in st.items()}
        td, ta = targets.get(n, (None, None))
        rows.append(Row(f"full stack 1x{n:,}, dict API", e["dict"], "env-steps/s", td))
        rows.append(Row(f"full stack 1x{n:,}, array API", e["array"], "env-steps/s", ta))
        rows.append(
            Row(
                f"comms cost 1x{n:,} (full step / step without comms)",
                e["bare"] / e["array"],
                "x",
                {1000: 1.5, 10_000: 2.5}.get(n),
                higher=False,
                note=f"without comms {fmt_num(e['bare'])} env-steps/s",
            )
        )
    return rows


def _array(n: int, threads: int = 1, **config: object) -> common.Case:
    return bench_step.array_case(1, n, 0, num_threads=threads, **config)


def big_world(n: int, rounds: int) -> list[Row]:
    """1xN array API without comms on one core, and 2 threads vs 1 (wall time)."""
    cases = {"1": _array(n, 1), "2": _array(n, 2)}
    st = measure_interleaved(cases, rounds=rounds, block_s=0.3, warmup=2)
    tgt = 1.7 if n >= 100_000 else None
    rows = [Row(f"1x{n:,} array API, no comms, 1 core", 1.0 / st["1"].step_s, "env-steps/s", 25 if tgt else None)]
    cores = available_cores()
    if cores < 2:
        rows.append(Row(f"1x{n:,}: 2 threads vs 1 (wall)", None, "x", tgt, note=f"only {cores} core available"))
    else:
        ratio = st["1"].wall_step_s / st["2"].wall_step_s
        rows.append(
            Row(
                f"1x{n:,}: 2 threads vs 1 (wall)",
                ratio,
                "x",
                tgt,
                note=f"{st['1'].wall_step_s * 1e3:.1f} vs {st['2'].wall_step_s * 1e3:.1f} ms/step wall",
            )
        )
    return rows


def full_stack_threads(sizes: list[int], rounds: int) -> list[Row]:
    """Full stack (comms on) through the array API, 2 threads vs 1 in wall time, interleaved, per size."""
    rows: list[Row] = []
    cores = available_cores()
    for n in sizes:
        label = f"full stack 1x{n:,}: 2 threads vs 1 (wall)"
        if cores < 2:
            rows.append(Row(label, None, "x", 1.7, note=f"only {cores} core available"))
            continue
        cases = {"1": bench_comms.array_case(n, True, 1), "2": bench_comms.array_case(n, True, 2)}
        st = measure_interleaved(cases, rounds=rounds, block_s=0.3 if n < 100_000 else 0.6, warmup=2)
        w1, w2 = st["1"].wall_step_s, st["2"].wall_step_s
        rows.append(Row(label, w1 / w2, "x", 1.7, note=f"{w1 * 1e3:.1f} vs {w2 * 1e3:.1f} ms/step wall"))
        if n == 10_000:
            rows.append(Row(f"full stack 1x{n:,}, array API, 2 threads (wall)", 1.0 / w2, "env-steps/s", 130))
    return rows


def thread_curve(n: int, counts: list[int], rounds: int) -> dict[int, float]:
    """Wall ms per step of the full stack at 1xN for each thread count (interleaved), up to the cores there are."""
    counts = [k for k in counts if k <= available_cores()]
    cases = {str(k): bench_comms.array_case(n, True, k) for k in counts}
    st = measure_interleaved(cases, rounds=rounds, block_s=0.5, warmup=2)
    return {k: st[str(k)].wall_step_s * 1e3 for k in counts}


def plot_threads(curve: dict[int, float], n: int, path: str) -> None:
    """Speed-up over one thread against threads, with the ideal line."""
    ks = sorted(curve)
    fig, ax = _figure(5.0)
    ax.plot(ks, [curve[ks[0]] / curve[k] for k in ks], marker="o", label="measured")
    ax.plot(ks, ks, ls="--", color="grey", label="ideal")
    ax.set_xlabel("threads (num_threads)")
    ax.set_ylabel("speed-up over 1 thread (wall)")
    ax.set_xticks(ks)
    ax.set_title(f"navigation full stack, 1x{n:,}, array API ({available_cores()} cores)")
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, path)


def cold_start(quick: bool) -> list[Row]:
    """Second-process start per case, from ``bench_coldstart``."""
    import bench_coldstart

    rows = []
    # fewer runs than bench_coldstart's own table (which make bench prints too): the medians barely move
    for r in bench_coldstart.coldstart_rows(quick, runs=3 if quick else 5, cold_runs=1, whole_quickstart=False):
        rows.append(
            Row(
                f"cold start: {r['case']} (warm cache)",
                r["warm_s"],
                "s",
                3.0,
                higher=False,
                note=f"empty cache {r['cold_s']:.1f} s" if r.get("cold_s") else "",
            )
        )
    return rows


def scaling(sizes: list[int], rounds: int) -> dict[str, dict[int, float]]:
    """CPU microseconds per agent-step, array API, without comms and with the full stack, per size."""
    curve: dict[str, dict[int, float]] = {"no comms": {}, "full stack": {}}
    for n in sizes:
        cases: dict[str, common.Case] = {
            "no comms": bench_comms.array_case(n, False),
            "full stack": bench_comms.array_case(n, True),
        }
        st = measure_interleaved(cases, rounds=rounds, block_s=0.2, warmup=1)
        for k, s in st.items():
            curve[k][n] = s.step_s / n * 1e6
    return curve


def _figure(width: float) -> tuple[Any, Any]:
    """A figure and its axes, 3.5 inches high, on the Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=(width, 3.5))


def _save(fig: Any, path: str) -> None:
    """Write ``fig`` as a PNG at ``path`` (folders made) and close it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_scaling(curve: dict[str, dict[int, float]], path: str) -> None:
    """Draw microseconds per agent-step against agents (log x)."""
    fig, ax = _figure(5.5)
    for k, pts in curve.items():
        ns = sorted(pts)
        ax.plot(ns, [pts[n] for n in ns], marker="o", label=k)
    ax.set_xscale("log")
    ax.set_xlabel("agents in one world")
    ax.set_ylabel("CPU us per agent-step")
    ax.set_ylim(bottom=0)
    ax.set_title("navigation, array API, 1 thread")
    ax.grid(alpha=0.3)
    ax.legend()
    _save(fig, path)


def _timed(label: str, fn: Callable[[], T]) -> T:
    print(f"  measuring {label}", file=sys.stderr, flush=True)
    return fn()


def main(argv: list[str] | None = None) -> int:
    """Print the targets table, the per-core table and the scaling curve."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes, few rounds (smoke test; targets not comparable)")
    p.add_argument("--plot", default=None, help="write the scaling curve to this PNG")
    p.add_argument("--no-coldstart", action="store_true", help="skip the cold-start rows")
    p.add_argument(
        "--threads-only",
        action="store_true",
        help="only the full stack's thread rows and the thread scaling curve",
    )
    p.add_argument("--thread-plot", default=None, help="write the thread scaling curve to this PNG")
    args = p.parse_args(argv)
    q = args.quick
    rounds, block = (2, 0.02) if q else (11, 0.15)
    big = 5_000 if q else 100_000
    comm_sizes = [200, 500] if q else [1000, 10_000]
    if args.threads_only:
        return threads_report(q, args.thread_plot)
    print(f"machine: {machine_description()}")
    print(f"mode: {'quick' if q else 'full'}; CPU time, one thread unless stated; medians of interleaved rounds\n")
    rows: list[Row] = []
    small, rates = _timed("small worlds", lambda: small_worlds(rounds, block))
    rows += small
    rows += _timed("full stack", lambda: full_stack(comm_sizes, max(3, rounds // 2), 0.3 if not q else 0.02))
    rows += _timed(f"1x{big}", lambda: big_world(big, 2 if q else 5))
    rows += _timed("full stack, threads", lambda: full_stack_threads(comm_sizes[1:] + [big], 2 if q else 5))
    if not args.no_coldstart:
        rows += _timed("cold start", lambda: cold_start(q))
    print("## Targets\n")
    print(markdown_table(["case", "result", "target", "met", "measured alongside"], [r.cells() for r in rows]))
    met = sum(1 for r in rows if r.cells()[3] == "PASS")
    print(f"\n{met} of {len(rows)} rows met.\n")

    print("## Per core, 32-ray scan on (navigation, array API, 1 thread)\n")
    per_core = [
        ["512x4", fmt_num(rates["array 512x4"])],
        ["1x1,000", fmt_num(rates["array 1x1000"])],
        ["C++ batched engine (published, no sensing)", fmt_num(CPP_ANCHOR)],
    ]
    print(markdown_table(["case", "agent-steps/s per core"], per_core))

    sizes = [1000, 5000] if q else [1000, 10_000, 100_000]
    curve = _timed("scaling", lambda: scaling(sizes, 2 if q else 3))
    print("\n## Scaling: CPU us per agent-step (array API, 1 thread)\n")
    table = [[f"1x{n:,}"] + [fmt_num(curve[k][n]) for k in curve] for n in sizes]
    print(markdown_table(["agents", *curve], table))
    if args.plot:
        plot_scaling(curve, args.plot)
        print(f"\nscaling plot: {args.plot}")
    _print_thread_curve(q, args.thread_plot)
    return 0


def _print_thread_curve(quick: bool, plot: str | None) -> None:
    n = 5_000 if quick else 100_000
    curve = _timed("thread curve", lambda: thread_curve(n, THREAD_COUNTS, 2 if quick else 4))
    one = curve[min(curve)]
    print(f"\n## Threads: full stack 1x{n:,}, array API, wall ms per step ({available_cores()} cores here)\n")
    print(
        markdown_table(
            ["threads", "ms/step", "speed-up"],
            [[str(k), f"{v:.1f}", f"{one / v:.2f}"] for k, v in sorted(curve.items())],
        )
    )
    if plot:
        plot_threads(curve, n, plot)
        print(f"\nthread plot: {plot}")


def threads_report(quick: bool, plot: str | None) -> int:
    """``--threads-only``: the full stack's 2-vs-1 thread rows and the thread curve."""
    print(f"machine: {machine_description()}\n")
    sizes = [1_000, 5_000] if quick else [10_000, 100_000]
    rows = _timed("full stack, threads", lambda: full_stack_threads(sizes, 2 if quick else 7))
    print(markdown_table(["case", "result", "target", "met", "measured alongside"], [r.cells() for r in rows]))
    _print_thread_curve(quick, plot)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
