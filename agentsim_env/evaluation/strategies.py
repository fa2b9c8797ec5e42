"""Where the evaluation finds its release strategies: a registry of ``"module:attribute"`` references.

The evaluation package does not import the policies package. It needs two callables, a policy factory
(``make_policy(scenario, env, name) -> Policy``) and the list of strategy names of a scenario
(``baseline_names(scenario) -> list[str]``); both are named here as ``"module:attribute"`` strings and loaded
with importlib on first use.

This module imports no other module of the evaluation package.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = [
    "NAMES",
    "POLICY_FACTORY",
    "NameLister",
    "PolicyFactory",
    "load",
    "policy_factory",
    "strategy_names",
]

#: ``make_policy(scenario, env, name)``: the scripted policy ``name`` configured for ``env``.
PolicyFactory = Callable[[str, Any, str | None], Any]
#: ``baseline_names(scenario)``: the strategy names of a scenario.
NameLister = Callable[[str], list[str]]

#: Default reference of the policy factory.
POLICY_FACTORY = "agentsim_env.policies.registry:make_policy"
#: Default reference of the name lister.
NAMES = "agentsim_env.policies.registry:baseline_names"

def load(ref: str) -> Any:
    """Import ``"package.module:attribute"`` and return the attribute.

    Args:
        ref: Module path and attribute name, separated by a colon.

    Returns:
        The attribute.

    Raises:
        ValueError: When ``ref`` has no ``:`` or names a missing module or attribute.
    """
    module, sep, attr = ref.partition(":")
    if not sep or not module or not attr:
        raise ValueError(f"expected 'package.module:attribute', got {ref!r}")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"cannot load {ref!r}: {exc}") from exc


def policy_factory() -> PolicyFactory:
    """The policy factory (loaded now)."""
    factory: PolicyFactory = load(POLICY_FACTORY)
    return factory


def strategy_names(scenario: str) -> list[str]:
    """The strategy names the name lister gives for ``scenario``, in its order.

    Args:
        scenario: Scenario name.

    Returns:
        The names.
    """
    lister: NameLister = load(NAMES)
    return list(lister(scenario))
