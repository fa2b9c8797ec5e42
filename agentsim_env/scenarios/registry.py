"""Scenario registry: scenarios are registered by name and tests iterate over it."""

from __future__ import annotations

import importlib
from typing import Any

from agentsim_env.core.validation import build_config
from agentsim_env.scenarios.base import Scenario

# name -> module path; modules are imported on first use so `import agentsim_env` stays cheap.
_SCENARIOS: dict[str, str] = {
    "navigation": "agentsim_env.scenarios.navigation",
    "uav_release": "agentsim_env.uav.scenario",
    "relay": "agentsim_env.scenarios.relay",
    "rendezvous": "agentsim_env.scenarios.rendezvous",
}


def register(name: str, module: str) -> None:
    """Register a scenario module (it must define ``Scenario`` subclass ``SCENARIO``)."""
    _SCENARIOS[name] = module


def list_scenarios() -> list[str]:
    """Names of every registered scenario, sorted."""
    return sorted(_SCENARIOS)


def scenario_class(name: str) -> type[Scenario]:
    """The Scenario class registered under ``name``."""
    if name not in _SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; registered scenarios: {list_scenarios()}")
    return importlib.import_module(_SCENARIOS[name]).SCENARIO  # type: ignore[no-any-return]


def make_scenario(name: str, **config: Any) -> Scenario:
    """Build a scenario from its name and config keys (validated; unknown keys raise)."""
    cls = scenario_class(name)
    if "max_cycles" in config:  # PettingZoo's name for the episode length
        config["max_steps"] = config.pop("max_cycles")
    for alias, key in getattr(cls.config_cls, "aliases", {}).items():
        if alias in config:
            if key in config:
                raise ValueError(f"give {key!r} or its alias {alias!r}, not both")
            config[key] = config.pop(alias)
    return cls(build_config(cls.config_cls, config))
