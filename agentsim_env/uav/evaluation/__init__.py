"""Batch evaluation of the UAV sensor-release case study (``agentsim evaluate``).

``runner`` flies every (zone file, strategy, seed) and evaluates the landed network, with the policies named
by the ``strategies`` registry; ``scoring`` holds the composite score and the ranking, ``report`` writes
``sensors.csv``, ``runs.csv`` and the Markdown ranking ``summary.md``, ``plots`` draws the PNG figures.
"""

from agentsim_env.uav.evaluation.report import write_outputs
from agentsim_env.uav.evaluation.runner import TELEPORT, GridResult, RunResult, run_grid, run_one
from agentsim_env.uav.evaluation.scoring import composite_score

__all__ = ["TELEPORT", "GridResult", "RunResult", "composite_score", "run_grid", "run_one", "write_outputs"]
