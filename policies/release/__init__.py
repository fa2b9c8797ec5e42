"""Scripted sensor-release baselines B0-B8: planners (``targets``, ``planning``), the env policy and its
multi-UAV coordination protocol."""

from policies.release.coordination import MissionView, Piece, TargetBook, split_work
from policies.release.planning import ReleasePlan, split_sectors
from policies.release.policy import DEFAULT_RELEASE_SPEED, ReleasePolicy
from policies.release.targets import STRATEGIES, make_plan

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
