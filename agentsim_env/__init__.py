"""agentsim-env: a vectorised multi-agent simulator exposed as a PettingZoo ParallelEnv.

Importing the package has no side effects; scenarios load on first use.

Example:
    >>> import agentsim_env
    >>> env = agentsim_env.make("navigation", n_agents=8)
    >>> obs, infos = env.reset(seed=0)
"""

from __future__ import annotations

from typing import Any

__version__ = "0.1.0"

ENV_KEYS = ("render_mode", "obs_format", "action_format")


def list_scenarios() -> list[str]:
    """Names of every registered scenario."""
    from agentsim_env.scenarios.registry import list_scenarios as _list

    return _list()


def make(name: str, **config: Any) -> Any:
    """Build the ParallelEnv of scenario ``name``.

    Args:
        name: A registered scenario (see ``list_scenarios()``).
        **config: ``render_mode`` (None or "rgb_array"), ``obs_format`` / ``action_format`` ("dict" or "flat"),
            and the scenario's config fields (unknown keys raise ``ValueError`` naming them).

    Returns:
        An ``AgentSimParallelEnv``.
    """
    from agentsim_env.env.parallel_env import AgentSimParallelEnv
    from agentsim_env.scenarios.registry import make_scenario

    env_kw = {k: config.pop(k) for k in ENV_KEYS if k in config}
    return AgentSimParallelEnv(make_scenario(name, **config), **env_kw)


def parallel_env(name: str, **config: Any) -> Any:
    """Alias of :func:`make` (PettingZoo naming)."""
    return make(name, **config)


__all__ = ["__version__", "list_scenarios", "make", "parallel_env"]
