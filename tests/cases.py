"""The one (scenario, config) source that every conformance test iterates over."""

from __future__ import annotations

from typing import Any

from agentsim_env import list_scenarios
from agentsim_env.scenarios.registry import scenario_class

FORMATS: tuple[dict[str, str], ...] = (
    {"obs_format": "dict", "action_format": "dict"},
    {"obs_format": "flat", "action_format": "flat"},
)


def conformance_cases() -> list[tuple[str, dict[str, Any]]]:
    """Every registered scenario x its test configs x both observation/action formats."""
    cases = []
    for name in list_scenarios():
        for cfg in scenario_class(name).test_configs:
            for fmt in FORMATS:
                cases.append((name, {**cfg, **fmt}))
    return cases


def case_id(case: tuple[str, dict[str, Any]]) -> str:
    """Readable pytest id of a case."""
    name, cfg = case
    return name + "-" + "-".join(f"{k}={v}" for k, v in sorted(cfg.items()))
