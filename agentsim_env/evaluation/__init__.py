"""Batch evaluation of the UAV sensor-release case study (``agentsim evaluate``).

``runner`` flies every (zone file, strategy, seed) and evaluates the landed network, ``report`` writes
``sensors.csv``, ``runs.csv`` and the Markdown ranking ``summary.md``, ``plots`` draws the PNG figures.
"""

from agentsim_env.evaluation.report import composite_score, write_outputs
from agentsim_env.evaluation.runner import TELEPORT, GridResult, RunResult, run_grid, run_one

__all__ = ["TELEPORT", "GridResult", "RunResult", "composite_score", "run_grid", "run_one", "write_outputs"]
