"""agentsim-env: a vectorised multi-agent simulator exposed as a PettingZoo ParallelEnv.

Importing the package has no side effects; scenarios load on first use. The one exception: where numba
cannot cache compiled kernels in its default locations (a read-only install without a writable home), the
import points ``NUMBA_CACHE_DIR`` at a private temporary directory first (or, failing that, lets the
kernels compile uncached) and warns (see ``_numba_cache``).

Example:
    >>> import agentsim_env
    >>> env = agentsim_env.make("navigation", n_agents=8)
    >>> obs, infos = env.reset(seed=0)

PettingZoo's constructor names: ``agentsim_env.parallel_env(name, **config)`` (the same as ``make``) and
``agentsim_env.env(name, **config)`` (the AEC env); per scenario, ``agentsim_env.scenarios.<name>_v<version>``
has ``parallel_env``, ``env`` and ``raw_env``. Gymnasium ids: see ``agentsim_env.gymnasium_envs``.

Extending from your own package (``docs/extending.md``): ``register_scenario``, ``register_policy`` and
``register_strategy`` (or entry points in the groups ``agentsim_env.scenarios``, ``agentsim_env.policies`` and
``agentsim_env.strategies``); ``Scenario`` and ``World`` are the classes a scenario is written with. The classes
(``Scenario``, ``World``, ``BatchedEnv``) load on first access.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from agentsim_env import env  # the env package, callable: env(name, **config) is the AEC env
from agentsim_env._compile_notice import install as _install_compile_notice
from agentsim_env._moved import install as _install_moved_paths
from agentsim_env._numba_cache import ensure_numba_cache as _ensure_numba_cache
from agentsim_env.core.plugins import register_policy, register_scenario, register_strategy

if TYPE_CHECKING:
    from agentsim_env.env.parallel_env import AgentSimParallelEnv
    from agentsim_env.env.vector import BatchedEnv
    from agentsim_env.scenarios.base import Scenario
    from agentsim_env.sim import World

_ensure_numba_cache()  # before any kernel module: numba picks a function's cache directory when decorating it
_install_compile_notice()  # one stderr line when a kernel compiles instead of loading from the cache
_install_moved_paths()  # the UAV modules' old paths (agentsim_env._moved): their new modules, with a warning

__version__ = "0.1.0"


def list_scenarios() -> list[str]:
    """Names of every registered scenario."""
    from agentsim_env.scenarios.registry import list_scenarios as _list

    return _list()


def make(name: str, **config: Any) -> AgentSimParallelEnv:
    """Build the ParallelEnv of scenario ``name``.

    Args:
        name: A registered scenario (see ``list_scenarios()``).
        **config: ``render_mode`` (None or "rgb_array"), ``obs_format`` / ``action_format`` ("dict" or "flat"),
            ``check_finite`` (a debug switch: fail fast on a NaN or inf observation, reward or info, naming the
            part and the agent; default from ``AGENTSIM_CHECK_FINITE``), ``num_threads`` (1..256),
            ``ended_agents`` (``"leave"``, the default: an agent that ends leaves ``agents``; ``"stay"``: it stays
            with zero observations and reward 0 until the episode ends), and the scenario's config fields
            (unknown keys raise ``ValueError`` naming them).

    Returns:
        An ``AgentSimParallelEnv``.
    """
    from agentsim_env.env.parallel_env import build_parallel_env

    return build_parallel_env(name, **config)


def parallel_env(name: str, **config: Any) -> AgentSimParallelEnv:
    """Alias of :func:`make` (PettingZoo naming)."""
    return make(name, **config)


# classes exported on first access, so that importing the package loads no scenario, simulator or env module
_LAZY = {
    "BatchedEnv": "agentsim_env.env.vector",
    "Scenario": "agentsim_env.scenarios.base",
    "World": "agentsim_env.sim",
}


def __getattr__(name: str) -> Any:
    """The lazily exported classes (``BatchedEnv``, ``Scenario``, ``World``), imported on first access."""
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value  # later accesses skip this function
        return value
    raise AttributeError(f"module 'agentsim_env' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names, the lazy classes included."""
    return sorted({*globals(), *_LAZY})


__all__ = [
    "BatchedEnv",
    "Scenario",
    "World",
    "__version__",
    "env",
    "list_scenarios",
    "make",
    "parallel_env",
    "register_policy",
    "register_scenario",
    "register_strategy",
]
