"""Scripted baselines per scenario, found by name so the CLI and tests need no scenario-specific code."""

from __future__ import annotations

import importlib
from typing import Any

from policies.base import Policy

# scenario -> {policy name: "module:Class"}; the first entry is the scenario's default baseline.
BASELINES: dict[str, dict[str, str]] = {
    "navigation": {"go_to_goal": "policies.navigation:GoToGoalPolicy", "random": "policies.random:RandomPolicy"},
}


def baseline_names(scenario: str) -> list[str]:
    """Baselines available for ``scenario`` (default first)."""
    if scenario not in BASELINES:
        raise ValueError(f"no scripted baselines for scenario {scenario!r}; known: {sorted(BASELINES)}")
    return list(BASELINES[scenario])


def make_policy(scenario: str, env: Any, name: str | None = None) -> Policy:
    """Build baseline ``name`` (default: the scenario's first) configured for ``env``."""
    names = baseline_names(scenario)
    name = name or names[0]
    if name not in BASELINES[scenario]:
        raise ValueError(f"policy must be one of {names} for {scenario!r}, got {name!r}")
    module, cls = BASELINES[scenario][name].split(":")
    return getattr(importlib.import_module(module), cls).for_env(env)  # type: ignore[no-any-return]
