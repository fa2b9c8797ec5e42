"""Scripted baselines per scenario, found by name so the CLI and tests need no scenario-specific code."""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from typing import Any

from agentsim_env.policies.base import Policy
from agentsim_env.policies.release.registry import strategy_class, strategy_names

#: A baseline: ``"module:Class"`` or ``("module:Class", kwargs for for_env)``.
Entry = str | tuple[str, dict[str, Any]]


class ReleaseBaselines(Mapping[str, Entry]):
    """The ``uav_release`` baselines: every registered release strategy, read from the registry at each call.

    ``B5_cvt`` (density-weighted CVT) comes first: the scenario's default baseline. A deprecated former
    strategy name is found too (``strategy_class`` warns) but not listed.
    """

    DEFAULT = "B5_cvt"
    POLICY = "agentsim_env.policies.release.policy:ReleasePolicy"

    def __getitem__(self, name: str) -> Entry:
        try:
            cls = strategy_class(name)
        except ValueError:
            raise KeyError(name) from None
        return (self.POLICY, {"strategy": cls.name})

    def __iter__(self) -> Iterator[str]:
        names = strategy_names()
        head = [self.DEFAULT] if self.DEFAULT in names else []
        return iter(head + [n for n in names if n != self.DEFAULT])

    def __len__(self) -> int:
        return len(strategy_names())


# scenario -> {policy name: "module:Class" or ("module:Class", kwargs for for_env)}; the first entry is the
# scenario's default baseline.
BASELINES: dict[str, Mapping[str, Entry]] = {
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
BASELINES["uav_release"] = ReleaseBaselines()


def baseline_names(scenario: str) -> list[str]:
    """Baselines available for ``scenario`` (default first)."""
    if scenario not in BASELINES:
        raise ValueError(f"no scripted baselines for scenario {scenario!r}; known: {sorted(BASELINES)}")
    return list(BASELINES[scenario])


def baseline_name(scenario: str, name: str) -> str:
    """The current name of baseline ``name`` of ``scenario``.

    A deprecated former name (``B8_oracle``) maps to its current one with a ``DeprecationWarning``; a current
    name, and a name that is not a baseline of ``scenario``, are returned unchanged (the caller reports those).
    """
    entry = BASELINES.get(scenario, {}).get(name)
    if isinstance(entry, tuple) and isinstance(entry[1].get("strategy"), str):
        return str(entry[1]["strategy"])
    return name


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
    if name not in BASELINES[scenario]:
        raise ValueError(
            f"--policy must be one of {names} for {scenario!r} or a trained model "
            f"(a folder with model.zip, or a .zip), got {name!r}"
        )
    return name, config
