"""Where the evaluation finds its release strategies: a registry of ``"module:attribute"`` references.

The evaluation package does not import the policies package. It needs four callables, a policy factory
(``make_policy(scenario, env, name) -> Policy``), the list of strategy names of a scenario
(``baseline_names(scenario) -> list[str]``), the current name of a possibly deprecated strategy name
(``baseline_name(scenario, name) -> str``) and the reader of a trained model's config
(``model_env_config(path) -> (scenario, env_config)``); all are named here as ``"module:attribute"`` strings
and loaded with importlib on first use.

A strategy token that is a path (it contains a path separator or names an existing folder) is a trained model
folder (``model.zip`` and ``config.json``, as ``agentsim train`` writes them): ``is_model_token`` tells them
apart, ``model_label`` names it (the folder name) and ``model_env`` reads its scenario and env config.

This module imports no other module of the evaluation package.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = [
    "CURRENT_NAME",
    "MODEL_ENV",
    "NAMES",
    "POLICY_FACTORY",
    "NameLister",
    "PolicyFactory",
    "current_name",
    "is_model_token",
    "load",
    "model_env",
    "model_label",
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
#: Default reference of ``baseline_name(scenario, name)``: a deprecated name's current name (warns).
CURRENT_NAME = "agentsim_env.policies.registry:baseline_name"
#: Default reference of the trained-model config reader, ``model_env_config(path) -> (scenario, env)``.
MODEL_ENV = "agentsim_env.policies.learned:model_env_config"


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


def current_name(scenario: str, name: str) -> str:
    """The current name of strategy ``name`` of ``scenario``.

    Args:
        scenario: Scenario name.
        name: A strategy name, possibly a deprecated former one (mapped with a ``DeprecationWarning``).

    Returns:
        The current name; a name that is not a strategy of ``scenario`` comes back unchanged.
    """
    resolver: Callable[[str, str], str] = load(CURRENT_NAME)
    return resolver(scenario, name)


def is_model_token(token: str) -> bool:
    """Whether a strategy token is a trained model folder's path (not a registered strategy name).

    Args:
        token: The ``--strategies`` token.

    Returns:
        True when it contains a path separator or names an existing folder.
    """
    text = str(token)
    return "/" in text or os.sep in text or Path(text).is_dir()


def model_label(token: str) -> str:
    """The name of a trained model in tables: its folder's name."""
    return Path(str(token).rstrip("/" + os.sep)).name or str(token)


def model_env(token: str, scenario: str) -> dict[str, Any]:
    """Check a trained model folder and return the env config it was trained with.

    Args:
        token: The model folder.
        scenario: The scenario it must have been trained on.

    Returns:
        The scenario config keys of its ``config.json`` ``env``.

    Raises:
        ValueError: The path does not exist or is a file, the folder lacks ``model.zip`` or ``config.json``,
            its config cannot be read, or it was trained on another scenario.
    """
    folder = Path(str(token))
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "does not exist"
        raise ValueError(
            f"strategy {token!r} {what}; a trained model is a folder holding model.zip and "
            "config.json (as 'agentsim train --out DIR' writes them), and a strategy name is "
            "one of 'agentsim evaluate --help'"
        )
    missing = [f for f in ("model.zip", "config.json") if not (folder / f).is_file()]
    if missing:
        raise ValueError(
            f"trained model folder {token!r} lacks {' and '.join(missing)} (a trained model folder "
            "holds model.zip and config.json, as 'agentsim train --out DIR' writes them)"
        )
    reader: Callable[[str], tuple[str, dict[str, Any]]] = load(MODEL_ENV)
    trained_on, env = reader(str(folder))
    if trained_on != scenario:
        raise ValueError(f"trained model {token!r} was trained on scenario {trained_on!r}, not {scenario!r}")
    return dict(env)
