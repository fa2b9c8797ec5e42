"""The env front ends (ParallelEnv, AEC, batched, single-agent) and the RL stacks' adapters.

The package is also callable: ``agentsim_env.env(name, **config)`` is the AEC env of a scenario, PettingZoo's
name beside ``agentsim_env.parallel_env``. The name belongs to both, and a function of that name would be replaced
by this package as soon as one of its modules is imported, so the package's module object itself is callable.
"""

from __future__ import annotations

import sys
import types
from typing import Any


class _CallablePackage(types.ModuleType):
    """This package's module type: calling it builds an AEC env."""

    def __call__(self, name: str, **config: Any) -> Any:
        """The AEC env of scenario ``name`` (``agentsim_env.env.constructors.aec_env``)."""
        from agentsim_env.env.constructors import aec_env

        return aec_env(name, **config)


sys.modules[__name__].__class__ = _CallablePackage
