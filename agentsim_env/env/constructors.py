"""PettingZoo's constructor names for a scenario: ``parallel_env``, ``env`` (AEC) and ``raw_env``.

``agentsim_env.parallel_env(name, **config)`` and ``agentsim_env.env(name, **config)`` take the scenario's name;
the modules ``agentsim_env.scenarios.<name>_v<version>`` (named like ``pettingzoo.mpe.simple_v3`` and like the
env's ``metadata["name"]``) bind it, so PettingZoo tutorials and tests that take such a module run unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from agentsim_env.env.parallel_env import AgentSimParallelEnv, build_parallel_env, to_aec


def aec_env(name: str, **config: Any) -> Any:
    """The AEC env of scenario ``name``: its ParallelEnv through PettingZoo's ``parallel_to_aec``.

    Args:
        name: A registered scenario.
        **config: As for ``agentsim_env.make`` (``ended_agents`` must stay ``"leave"``: an AEC agent that ended
            takes one ``None`` action and leaves).

    Returns:
        The AEC env (a PettingZoo ``AECEnv``, with PettingZoo's order checks).

    Raises:
        ValueError: Unknown scenario or config key, a bad value, or ``ended_agents="stay"``.
    """
    return to_aec(build_parallel_env(name, **config))


def scenario_constructors(name: str) -> tuple[Callable[..., Any], Callable[..., Any], Callable[..., Any]]:
    """``(env, parallel_env, raw_env)`` of scenario ``name``, each taking the config as keywords.

    Args:
        name: A registered scenario.

    Returns:
        ``env(**config)``: the AEC env (:func:`aec_env`); ``parallel_env(**config)``: the ParallelEnv
        (``agentsim_env.make``); ``raw_env(**config)``: the AEC env without PettingZoo's order checks.
    """

    def env(**config: Any) -> Any:
        return aec_env(name, **config)

    def parallel_env(**config: Any) -> AgentSimParallelEnv:
        return build_parallel_env(name, **config)

    def raw_env(**config: Any) -> Any:
        return to_aec(build_parallel_env(name, **config), raw=True)

    env.__doc__ = f"The AEC env of ``{name}`` (``agentsim_env.env({name!r}, **config)``)."
    parallel_env.__doc__ = f"The ParallelEnv of ``{name}`` (``agentsim_env.make({name!r}, **config)``)."
    raw_env.__doc__ = f"The AEC env of ``{name}`` without PettingZoo's order checks."
    return env, parallel_env, raw_env
