"""Scripted sensor-release strategies B0-B8: the ``ReleaseStrategy`` contract (``strategy``), the shipped
strategies (``baselines``) and their registry (``registry``), the planners (``targets``, ``planning``), the env
policy and its multi-UAV coordination protocol."""

from agentsim_env.policies.release.coordination import MissionView, Piece, TargetBook, split_work
from agentsim_env.policies.release.planning import ReleasePlan, split_sectors
from agentsim_env.policies.release.policy import ReleasePolicy
from agentsim_env.policies.release.registry import (
    make_plan,
    make_strategy,
    register,
    strategy_class,
    strategy_names,
    unregister,
)
from agentsim_env.policies.release.strategy import Bound, Choice, Pattern, PlanContext, ReleaseStrategy

__all__ = [
    "Bound",
    "Choice",
    "MissionView",
    "Pattern",
    "Piece",
    "PlanContext",
    "ReleasePlan",
    "ReleasePolicy",
    "ReleaseStrategy",
    "TargetBook",
    "make_plan",
    "make_strategy",
    "register",
    "split_sectors",
    "split_work",
    "strategy_class",
    "strategy_names",
    "unregister",
]
