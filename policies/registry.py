"""Scripted baselines per scenario, found by name so the CLI and tests need no scenario-specific code."""

from __future__ import annotations

import importlib
from typing import Any

from agentsim_env.policies.base import Policy
from agentsim_env.policies.release.targets import STRATEGIES

# scenario -> {policy name: "module:Class" or ("module:Class", kwargs for for_env)}; the first entry is the
# scenario's default baseline.
BASELINES: dict[str, dict[str, str | tuple[str, dict[str, Any]]]] = {
    "navigation": {
        "go_to_goal": "agentsim_env.policies.navigation:GoToGoalPolicy",
        "random": "agentsim_env.policies.random:RandomPolicy",
    },
    "relay": {
        "flood": "agentsim_env.policies.relay:FloodPolicy",
        "silent": "agentsim_env.policies.relay:SilentPolicy",
    },
    "rendezvous": {
        "meet": "agentsim_env.policies.rendezvous:MeetPolicy",
        "random": "agentsim_env.policies.random:RandomPolicy",
    },
}
# B5 (density-weighted CVT) first: the scenario's default baseline
BASELINES["uav_release"] = {
    name: ("agentsim_env.policies.release.policy:ReleasePolicy", {"strategy": name})
    for name in ["B5_cvt"] + [s for s in STRATEGIES if s != "B5_cvt"]
}


def baseline_names(scenario: str) -> list[str]:
    """Baselines available for ``scenario`` (default first)."""
    if scenario not in BASELINES:
        raise ValueError(f"no scripted baselines for scenario {scenario!r}; known: {sorted(BASELINES)}")
    return list(BASELINES[scenario])


def make_policy(scenario: str, env: Any, name: str | None = None) -> Policy:
    """Build baseline ``name`` (default: the scenario's first) configured for ``env``.

    ``name`` may also be a trained model (a folder with ``model.zip`` and ``config.json``, or a ``.zip``; see
    ``agentsim_env.policies.learned``), which then acts like the scripted baselines.
    """
    from agentsim_env.policies.learned import is_model_path, load_policy

    if name is not None and is_model_path(name):
        return load_policy(name, env)
    names = baseline_names(scenario)
    name = name or names[0]
    if name not in BASELINES[scenario]:
        raise ValueError(f"policy must be one of {names} for {scenario!r}, got {name!r}")
    entry = BASELINES[scenario][name]
    path, kwargs = (entry, {}) if isinstance(entry, str) else entry
    module, cls = path.split(":")
    return getattr(importlib.import_module(module), cls).for_env(env, **kwargs)  # type: ignore[no-any-return]


def resolve_policy(scenario: str, policy: str | None, config: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The policy a command runs and the scenario config it runs with (``--policy`` of ``run`` and ``view``).

    Args:
        scenario: The scenario.
        policy: A baseline name, a trained model (folder or ``.zip``), or None for the scenario's first baseline.
        config: The config from ``--set``.

    Returns:
        The policy name and the config: a trained model's env config with ``config`` over it, or ``config``.

    Raises:
        ValueError: An unknown baseline, or a model trained on another scenario.
    """
    from agentsim_env.policies.learned import is_model_path, model_env_config

    names = baseline_names(scenario)
    name = policy or names[0]
    if is_model_path(name):  # a trained model: its scenario config, then --set over it
        trained_on, env_config = model_env_config(name)
        if trained_on != scenario:
            raise ValueError(f"--policy {name!r} was trained on {trained_on!r}, not {scenario!r}")
        return name, {**env_config, **config}
    if name not in names:
        raise ValueError(
            f"--policy must be one of {names} for {scenario!r} or a trained model "
            f"(a folder with model.zip, or a .zip), got {name!r}"
        )
    return name, config
