"""Scenario registry: scenarios are found by name (``agentsim_env.core.plugins.SCENARIOS``) and tests iterate
over it.

The built-in scenarios, those added with ``agentsim_env.register_scenario`` and those of installed plug-ins
(entry points of the group ``agentsim_env.scenarios``) are listed alike; modules are imported on first use so
``import agentsim_env`` stays cheap. ``docs/extending.md`` shows how to add one. An installed plug-in that
cannot be loaded is still listed by ``list_scenarios`` (which loads nothing) but left out of
``usable_scenarios``; building it raises its ``PluginLoadError``.
"""

from __future__ import annotations

import warnings
from typing import Any

from agentsim_env.core.plugins import SCENARIOS, check_name
from agentsim_env.core.validation import build_config
from agentsim_env.scenarios.base import Scenario


def register(name: str, module: str) -> None:
    """Register a scenario module that defines ``SCENARIO`` (deprecated: use ``register_scenario``).

    Kept for one release: ``register(name, "pkg.module")`` is ``register_scenario(name, "pkg.module:SCENARIO",
    replace=True)``.

    Raises:
        ValueError: A bad name or module path.
    """
    warnings.warn(
        "agentsim_env.scenarios.registry.register(name, 'module') is deprecated and will be removed in the next "
        "release; use agentsim_env.register_scenario(name, 'module:Class') or an entry point "
        "(docs/extending.md)",
        DeprecationWarning,
        stacklevel=2,
    )
    SCENARIOS.register(check_name("scenario", name), f"{module}:SCENARIO", replace=True)


def list_scenarios() -> list[str]:
    """Names of every scenario (built-in, registered and installed plug-ins), sorted; nothing is imported."""
    return SCENARIOS.names()


def usable_scenarios() -> list[str]:
    """``list_scenarios()`` less the installed plug-ins that cannot be used (their module fails to import, or
    ``scenario_class`` refuses the class), each left out with one ``PluginLoadWarning`` per process.

    For the callers that go on to load every scenario; every plug-in scenario is imported here.
    """
    return SCENARIOS.usable_names(scenario_class)


def scenario_class(name: str) -> type[Scenario]:
    """The Scenario class registered under ``name``.

    Raises:
        ValueError: An unknown name (the message lists the known ones), a reference that does not load, an
            object that is no ``Scenario`` subclass, or a class whose ``name`` differs from ``name``.
    """
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; registered scenarios: {list_scenarios()}")
    cls = SCENARIOS.get(name)
    if not (isinstance(cls, type) and issubclass(cls, Scenario)):
        raise ValueError(f"scenario {name!r} ({SCENARIOS.origin(name)}) is not a Scenario subclass: {cls!r}")
    if getattr(cls, "name", None) != name:
        raise ValueError(
            f"scenario {name!r} ({SCENARIOS.origin(name)}) is the class {cls.__qualname__} whose name is "
            f"{getattr(cls, 'name', None)!r}; register it under its own name"
        )
    return cls


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
