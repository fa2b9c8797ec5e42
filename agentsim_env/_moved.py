"""The old import paths of the UAV case study's modules, which moved into ``agentsim_env.uav``.

For one release an old path still imports: ``MovedFinder`` (installed first on ``sys.meta_path`` when the package
is imported) resolves it to the module's new home and warns with a ``DeprecationWarning`` naming the new path.
The old name is then the new module itself (the same classes and functions, not copies), so nothing is defined
twice. No file stands at an old path, and this module imports nothing of the package: an old path never makes a
generic package (``scenarios``, ``render``) depend on ``uav``.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from types import ModuleType
from typing import Any

_UAV_MODULES = {
    "uav_release": "scenario",
    "uav_config": "config",
    "uav_zones": "zones",
    "uav_energy": "energy",
    "uav_autopilot": "autopilot",
    "uav_tracking": "tracking",
    "uav_outcome": "outcome",
    "uav_capacity": "capacity",
    "landed_grid": "landed_grid",
}
_WSN = ("connectivity", "coverage", "evaluate", "fidelity", "lifetime", "profiles", "radio")
_EVALUATION = ("mission", "plots", "report", "runner", "scoring", "strategies")

#: Old module path -> new module path.
MOVED: dict[str, str] = {
    **{f"agentsim_env.scenarios.{old}": f"agentsim_env.uav.{new}" for old, new in _UAV_MODULES.items()},
    "agentsim_env.wsn": "agentsim_env.uav.wsn",
    **{f"agentsim_env.wsn.{m}": f"agentsim_env.uav.wsn.{m}" for m in _WSN},
    "agentsim_env.evaluation": "agentsim_env.uav.evaluation",
    **{f"agentsim_env.evaluation.{m}": f"agentsim_env.uav.evaluation.{m}" for m in _EVALUATION},
    "agentsim_env.render.web.designer": "agentsim_env.uav.designer",
}


class _MovedLoader(importlib.abc.Loader):
    """Loads an old path as its new module (imported by its new name), after a ``DeprecationWarning``."""

    def __init__(self, old: str, new: str) -> None:
        self.old, self.new = old, new

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        """The new module itself (the import system then also files it under the old name)."""
        warnings.warn(
            f"{self.old} is deprecated: import {self.new} instead (this path is removed in the next release)",
            DeprecationWarning,
            stacklevel=2,
        )
        return importlib.import_module(self.new)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the new module ran when it was imported."""


class MovedFinder(importlib.abc.MetaPathFinder):
    """Finds the old paths of ``MOVED`` (and nothing else)."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        """A spec loading the new module for an old path; None for every other name."""
        new = MOVED.get(fullname)
        if new is None:
            return None
        return importlib.util.spec_from_loader(fullname, _MovedLoader(fullname, new))


def install() -> None:
    """Put ``MovedFinder`` first on ``sys.meta_path`` (once)."""
    if not any(isinstance(f, MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, MovedFinder())
