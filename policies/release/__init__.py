"""Scripted sensor-release baselines B0-B8: planners (``targets``, ``planning``), the env policy and its
multi-UAV coordination protocol."""

from agentsim_env.policies.release.coordination import MissionView, Piece, TargetBook, split_work
from agentsim_env.policies.release.planning import ReleasePlan, split_sectors
from agentsim_env.policies.release.policy import DEFAULT_RELEASE_SPEED, ReleasePolicy
from agentsim_env.policies.release.targets import STRATEGIES, make_plan

__all__ = [
    "DEFAULT_RELEASE_SPEED",
    "STRATEGIES",
    "MissionView",
    "Piece",
    "ReleasePlan",
    "ReleasePolicy",
    "TargetBook",
    "make_plan",
    "split_sectors",
    "split_work",
]
