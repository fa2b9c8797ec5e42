"""The learning benchmark: every scenario, PPO (SB3, parameter sharing) and BenchMARL MAPPO / IPPO / MASAC, several
training seeds, evaluated on held-out seeds beside every scripted baseline.

The same code as ``agentsim benchmark-rl`` (``agentsim_env.train.learnbench``); configs in
``train/configs/bench/``; files under ``--out``: ``runs.csv``, ``curves.csv``, ``baselines.csv``, a PNG per
scenario and ``summary.md``. The full table takes hours and is run on demand; ``--quick`` checks the pipeline in
about 3 minutes (tiny budgets: not a result).

Run: ``.venv/bin/python benchmarks/bench_learning.py [--quick] [--out DIR] [--benchmarl-python PATH]``
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402, F401  (pins thread pools before numpy / numba / torch load)

from agentsim_env.train.learnbench_cli import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
