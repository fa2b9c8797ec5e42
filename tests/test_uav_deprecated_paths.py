"""The old import paths of the UAV modules (before they moved into ``agentsim_env.uav``) still work for one
release: each warns with a DeprecationWarning naming the new path and re-exports the same objects."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from .test_layers import DEPRECATED


def _public(module: object) -> list[str]:
    """The public names of a module: its ``__all__``, or every name without a leading underscore."""
    names = getattr(module, "__all__", None)
    return list(names) if names is not None else [n for n in vars(module) if not n.startswith("_")]


@pytest.mark.parametrize("old", sorted(DEPRECATED))
def test_old_path_warns_and_reexports_the_same_objects(old: str) -> None:
    new = importlib.import_module(DEPRECATED[old])
    sys.modules.pop(old, None)  # a fresh import, so that it warns again
    with pytest.warns(DeprecationWarning) as caught:
        shim = importlib.import_module(old)
    assert shim is new, f"{old} is not the module {DEPRECATED[old]} itself"
    messages = [str(w.message) for w in caught if issubclass(w.category, DeprecationWarning)]
    assert any(m.startswith(f"{old} is deprecated: import {DEPRECATED[old]} instead") for m in messages), messages
    names = _public(new)
    assert names, f"{DEPRECATED[old]} has no public names"
    for name in names:
        assert getattr(shim, name) is getattr(new, name), f"{old}.{name} is not {DEPRECATED[old]}.{name}"


def test_the_new_paths_do_not_warn() -> None:
    # in a fresh interpreter: re-importing the new modules here would make second copies of their classes
    code = "import importlib\n" + "".join(f"importlib.import_module({n!r})\n" for n in sorted(set(DEPRECATED.values())))
    res = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr


def test_the_registry_names_the_new_module() -> None:
    from agentsim_env.scenarios.registry import scenario_class
    from agentsim_env.uav.scenario import UavReleaseScenario

    assert scenario_class("uav_release") is UavReleaseScenario
