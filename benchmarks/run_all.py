"""Run every ``benchmarks/bench_*.py`` that defines ``main()`` and print their tables (``make bench``).

Each benchmark runs in its own Python process, so each pins its thread pools before numpy / numba / torch load
and none inherits another's caches or allocator state. ``--quick`` is passed on to the benchmarks that accept
it (the others run as they are). The exit status is non-zero when any benchmark failed.

Run: ``.venv/bin/python benchmarks/run_all.py [--quick] [--only step lidar ...]``
"""

from __future__ import annotations

import argparse
import ast
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def has_main(path: Path) -> bool:
    """Whether the module defines a top-level function ``main``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return any(isinstance(node, ast.FunctionDef) and node.name == "main" for node in tree.body)


def benchmarks(only: list[str] | None = None) -> list[Path]:
    """The ``bench_*.py`` files with a ``main()``, sorted; ``only`` keeps names like ``step`` or ``bench_step``."""
    found = sorted(p for p in HERE.glob("bench_*.py") if has_main(p))
    if only:
        keep = {o.removeprefix("bench_").removesuffix(".py") for o in only}
        found = [p for p in found if p.stem.removeprefix("bench_") in keep]
    return found


def main(argv: list[str] | None = None) -> int:
    """Run the benchmarks one after the other and return the number that failed."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="pass --quick to the benchmarks that accept it")
    ap.add_argument("--only", nargs="+", default=None, help="benchmark names to run (e.g. step lidar)")
    args = ap.parse_args(argv)
    env = dict(os.environ)
    for var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env.setdefault(var, "1")
    root = str(HERE.parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    failed = 0
    for path in benchmarks(args.only):
        cmd = [sys.executable, str(path)]
        if args.quick and "--quick" in path.read_text(encoding="utf-8"):
            cmd.append("--quick")
        print(f"\n## {path.stem}  ({' '.join(cmd[1:])})\n", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call(cmd, cwd=root, env=env)
        print(f"\n({path.stem}: exit {rc}, {time.perf_counter() - t0:.1f} s)", flush=True)
        failed += rc != 0
    return failed


if __name__ == "__main__":
    sys.exit(main())
