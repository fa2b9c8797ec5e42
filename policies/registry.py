"""Scripted baselines per scenario, found by name so the CLI and tests need no scenario-specific code.

A scenario's policies are its built-in baselines (``BASELINES``, the default first) followed by the policies of
``agentsim_env.core.plugins.POLICIES`` that serve it (added with ``agentsim_env.register_policy(name, cls,
scenario=...)`` or by an installed plug-in's entry point in the group ``agentsim_env.policies``, whose class
names its scenarios in a class attribute ``scenarios = ("my_scenario",)``), sorted by name. A policy is built
with its class's ``for_env(env, **options)`` (the ``Policy`` protocol). ``docs/extending.md`` has an example.

An installed plug-in policy (or release strategy) that cannot be used (it does not load, names no scenario, or
repeats the name of a built-in baseline of a scenario it serves) is left out of every list with one
``PluginLoadWarning``; asking for it by name raises its ``PluginLoadError``.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, Mapping
from typing import Any

from agentsim_env.core.plugins import POLICIES, STRATEGIES, policy_scenarios
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
        usable = set(STRATEGIES.usable_names(strategy_class))  # a strategy plug-in that fails is left out
        names = [n for n in strategy_names() if n in usable]
        head = [self.DEFAULT] if self.DEFAULT in names else []
        return iter(head + [n for n in names if n != self.DEFAULT])

    def __len__(self) -> int:
        return sum(1 for _ in self)


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


def _check_plugin_policy(name: str) -> None:
    """Refuse installed policy ``name`` when it names no scenario or repeats a built-in baseline of one it serves
    (``POLICIES.usable_names`` then leaves it out, whatever scenario is listed)."""
    for scenario in policy_scenarios(name):
        if name in BASELINES.get(scenario, {}):
            raise ValueError(f"it repeats the name of a built-in baseline of {scenario!r}")


def _usable_policies() -> list[str]:
    """The names of ``POLICIES`` less the installed plug-ins that cannot be used (each warned about once)."""
    return POLICIES.usable_names(_check_plugin_policy)


def check_plugin(scenario: str, name: str) -> None:
    """Raise the ``PluginLoadError`` of ``name`` when it is an installed plug-in policy (or, for ``uav_release``,
    release strategy) that cannot be used; else do nothing (callers then report an unknown name)."""
    error = POLICIES.load_error(name) or (STRATEGIES.load_error(name) if scenario == "uav_release" else None)
    if error is not None:
        raise error from error.error


def plugin_policies(scenario: str) -> list[str]:
    """The names of the policies of ``POLICIES`` (registered or installed) that serve ``scenario``, sorted.

    Raises:
        ValueError: A registered policy that does not load, names no scenario, or repeats the name of a built-in
            baseline of ``scenario`` (an installed plug-in that does is left out, see the module docstring).
    """
    names = [n for n in _usable_policies() if scenario in policy_scenarios(n)]
    for name in names:
        if name in BASELINES.get(scenario, {}):
            raise ValueError(
                f"policy {name!r} ({POLICIES.origin(name)}) repeats the name of a built-in baseline of "
                f"{scenario!r} ({list(BASELINES[scenario])}); register it under another name"
            )
    return names


def scenario_policies(scenario: str) -> list[str]:
    """Every policy of ``scenario``: its built-in baselines (default first), then plug-in policies; may be empty."""
    return list(BASELINES.get(scenario, {})) + plugin_policies(scenario)


def baseline_names(scenario: str) -> list[str]:
    """Baselines available for ``scenario`` (default first), plug-in policies serving it included.

    Raises:
        ValueError: A scenario without any policy (the message lists the scenarios that have some).
    """
    names = scenario_policies(scenario)
    if not names:
        known = sorted({*BASELINES, *(s for n in _usable_policies() for s in policy_scenarios(n))})
        raise ValueError(f"no scripted baselines for scenario {scenario!r}; known: {known}")
    return names


def policy_class(scenario: str, name: str) -> Any:
    """The class of policy ``name`` of ``scenario`` (a built-in baseline or a plug-in), imported.

    Raises:
        PluginLoadError: ``name`` is an installed plug-in that cannot be used.
        ValueError: ``name`` is no policy of ``scenario`` (the message lists them).
    """
    builtin = BASELINES.get(scenario, {})
    if name in builtin:
        entry = builtin[name]
        module, cls = (entry if isinstance(entry, str) else entry[0]).split(":")
        return getattr(importlib.import_module(module), cls)
    if name not in plugin_policies(scenario):
        check_plugin(scenario, name)
        raise ValueError(f"policy must be one of {baseline_names(scenario)} for {scenario!r}, got {name!r}")
    return POLICIES.get(name)


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
    if name not in names and name not in BASELINES.get(scenario, {}):  # the latter: a deprecated former name
        check_plugin(scenario, name)
        raise ValueError(f"policy must be one of {names} for {scenario!r}, got {name!r}")
    entry = BASELINES.get(scenario, {}).get(name)
    kwargs = entry[1] if isinstance(entry, tuple) else {}
    return policy_class(scenario, name).for_env(env, **kwargs)  # type: ignore[no-any-return]


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
    if name not in names and name not in BASELINES.get(scenario, {}):  # the latter: a deprecated former name
        check_plugin(scenario, name)
        raise ValueError(
            f"--policy must be one of {names} for {scenario!r} or a trained model "
            f"(a folder with model.zip, or a .zip), got {name!r}"
        )
    return name, config
