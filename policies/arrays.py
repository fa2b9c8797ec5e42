"""Policies acting on rows of arrays (``ArrayPolicy``, ``agentsim_env.env.rollout``), built from picklable inputs.

:func:`build_policy` turns a scenario name, its config and a policy (a registered baseline name, a trained
model folder, a dict ``Policy`` object) into an ``ArrayPolicy``, without an env when none is at hand, as a shard
process builds its own copy:

| policy                                  | acts on rows                                              |
|-----------------------------------------|-----------------------------------------------------------|
| navigation ``go_to_goal``               | natively (``act_rows``)                                   |
| relay ``flood``, ``silent``             | natively; per-agent memory indexed by slot                |
| rendezvous ``meet``                     | natively                                                  |
| ``random`` (navigation, rendezvous)     | natively; draws keyed by (seed, step, slot)               |
| a trained model                         | natively (one forward pass; torch runs one thread)        |
| uav_release strategies                  | through dicts (they plan over the whole fleet and read the env they drive: an env is required) |
| a plug-in policy (``register_policy``)  | natively with ``act_rows``, else through dicts (``DictRows``) |
| any other ``Policy`` object             | through dicts (``DictRows``, the slow path)               |
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from agentsim_env.env.rollout import ArrayPolicy, DictRows
from agentsim_env.policies.learned import is_model_path, load_policy
from agentsim_env.policies.registry import baseline_names, check_plugin, make_policy, policy_class
from agentsim_env.scenarios.registry import make_scenario


class PolicyEnv:
    """What a policy reads of an env, without a world: the scenario, its agents and the dict formats.

    Args:
        scenario: The scenario name.
        config: Its config keys.
    """

    obs_format = "dict"
    action_format = "dict"

    def __init__(self, scenario: str, config: Mapping[str, Any]) -> None:
        self.scenario = make_scenario(scenario, **dict(config))
        self.possible_agents = self.scenario.agent_names()


def _rows(policy: Any, env: Any) -> ArrayPolicy:
    """``policy`` itself when it acts on rows, else wrapped in ``DictRows``."""
    if isinstance(policy, ArrayPolicy):
        return policy
    return DictRows(policy, list(env.possible_agents), env.scenario.act_parts())


def _allowed(scenario: str) -> str:
    return (
        f"one of {baseline_names(scenario)} for {scenario!r}, a trained model (a folder with model.zip, or "
        "a .zip), a Policy or an ArrayPolicy"
    )


def build_policy(
    scenario: str, config: Mapping[str, Any], policy: Any, *, env: Any = None, deterministic: bool = True
) -> ArrayPolicy:
    """An ``ArrayPolicy`` for ``scenario`` (module docstring).

    Args:
        scenario: The scenario name.
        config: Its config keys (ignored when ``env`` is given).
        policy: A baseline name registered for ``scenario`` (None: its default), a trained model folder or
            ``.zip`` (loaded with torch set to one thread), a dict ``Policy`` or an ``ArrayPolicy``.
        env: The env the policy will drive, when there is one (required by the ``uav_release`` strategies).
        deterministic: A trained model acts on the mode of its action distribution.

    Returns:
        The policy.

    Raises:
        ValueError: An unknown name (the message lists the registered ones), a model trained on another
            scenario or layout, a ``uav_release`` strategy without ``env``, or an object that is no policy.
    """
    if isinstance(policy, ArrayPolicy):
        return policy
    if policy is not None and not isinstance(policy, (str, Path)):
        if callable(getattr(policy, "act", None)) and callable(getattr(policy, "reset", None)):
            target = env if env is not None else PolicyEnv(scenario, config)
            return _rows(policy, target)
        raise ValueError(f"policy must be {_allowed(scenario)}; got a {type(policy).__name__}")
    names = baseline_names(scenario)
    name = names[0] if policy is None else str(policy)
    if is_model_path(name):
        import torch

        torch.set_num_threads(1)  # a shard is one process per core: its forward passes stay on that core
        target = env if env is not None else PolicyEnv(scenario, config)
        return load_policy(name, target, deterministic=deterministic)
    if name not in names:
        check_plugin(scenario, name)  # a plug-in that cannot be used: its own error
        raise ValueError(f"policy must be {_allowed(scenario)}; got {name!r}")
    if env is None:
        if not hasattr(policy_class(scenario, name), "act_rows"):
            raise ValueError(f"policy {name!r} of {scenario!r} reads the env it drives: pass env= to build it")
        env = PolicyEnv(scenario, config)
    return _rows(make_policy(scenario, env, name), env)
