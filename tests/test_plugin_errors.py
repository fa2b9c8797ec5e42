"""core.plugins: an installed plug-in that cannot be used harms only its own name. Each broken plug-in of the
table (a module that fails to import, one that raises on import, a module that is not installed, a missing
attribute, an object of the wrong kind) is installed (a distribution's metadata on sys.path) beside the working
``examples/plugin`` package, with one broken entry in each of the three groups; listing, looking up the other
names, looking up the broken one, the baselines of a scenario and the training evaluation's list are checked."""

from __future__ import annotations

import sys
import textwrap
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

import agentsim_env
from agentsim_env.core import plugins
from agentsim_env.core.plugins import POLICIES, SCENARIOS, STRATEGIES, PluginLoadError, PluginLoadWarning

ROOT = Path(__file__).resolve().parents[1]
BROKEN = {
    "agentsim_env.scenarios": "broken_sc",
    "agentsim_env.policies": "broken_pol",
    "agentsim_env.strategies": "broken_ring",
}
REGISTRIES = {r.group: r for r in (SCENARIOS, POLICIES, STRATEGIES)}
BUILTIN_SCENARIOS = ["navigation", "relay", "rendezvous", "uav_release"]


@dataclass(frozen=True)
class Breakage:
    """One way a plug-in is broken: the reference its entry points give, and the error that loading it raises."""

    ref: str
    cause: type[BaseException]
    says: str  # a piece of the original error's message


#: The modules the references point into (written on sys.path).
MODULES = {
    "plugmod_missing_dep": "import plugmod_missing_dependency\n",
    "plugmod_raises": "raise RuntimeError('plugmod_raises fails on import')\n",
    "plugmod_fine": "def helper():\n    '''A function.'''\n\n\nNUMBER = 3\n",
}
BREAKAGES = {
    "import error": Breakage("plugmod_missing_dep:Thing", ModuleNotFoundError, "plugmod_missing_dependency"),
    "exception on import": Breakage("plugmod_raises:Thing", RuntimeError, "plugmod_raises fails on import"),
    "module not installed": Breakage("plugmod_uninstalled.sub:Thing", ValueError, "no module named"),
    "missing attribute": Breakage("plugmod_fine:Thing", ValueError, "has no attribute 'Thing'"),
    "wrong type": Breakage("plugmod_fine:NUMBER", ValueError, "is an int, expected"),
}


def _refresh() -> None:
    for registry in REGISTRIES.values():
        registry.refresh()


@pytest.fixture(params=list(BREAKAGES), ids=list(BREAKAGES))
def broken(request: pytest.FixtureRequest, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Breakage]:
    """A distribution with the working beacon plug-in and one broken entry per group, installed on sys.path."""
    breakage = BREAKAGES[request.param]
    for module, text in MODULES.items():
        (tmp_path / f"{module}.py").write_text(text)
    info = tmp_path / "plugmod_dist-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: plugmod-dist\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        textwrap.dedent(
            f"""
            [agentsim_env.scenarios]
            beacon = agentsim_beacon.scenario:Beacon
            broken_sc = {breakage.ref}
            [agentsim_env.policies]
            to_beacon = agentsim_beacon.policy:ToBeaconPolicy
            broken_pol = {breakage.ref}
            [agentsim_env.strategies]
            beacon_ring = agentsim_beacon.strategy:BeaconRing
            broken_ring = {breakage.ref}
            """
        )
    )
    monkeypatch.syspath_prepend(str(ROOT / "examples" / "plugin"))
    monkeypatch.syspath_prepend(str(tmp_path))
    warned = set(plugins._WARNED)
    plugins._WARNED.clear()
    _refresh()
    try:
        yield breakage
    finally:
        monkeypatch.undo()
        _refresh()
        plugins._WARNED.clear()
        plugins._WARNED.update(warned)
        for name in [m for m in sys.modules if m.startswith(("plugmod_", "agentsim_beacon"))]:
            del sys.modules[name]


def _check_error(err: PluginLoadError, group: str, breakage: Breakage) -> None:
    """``err`` names the plug-in, its reference, its group and the original error, with a hint, from it."""
    message = str(err)
    for part in (repr(BROKEN[group]), repr(breakage.ref), repr(group), "plugmod-dist", breakage.says):
        assert part in message, (part, message)
    assert "reinstall or uninstall the package that provides it" in message
    assert isinstance(err, ValueError) and isinstance(err.__cause__, breakage.cause) and err.error is err.__cause__


def _plugin_warnings(caught: list[warnings.WarningMessage]) -> list[str]:
    return [str(w.message) for w in caught if issubclass(w.category, PluginLoadWarning)]


# ------------------------------------------------------------------------------------------ listing
def test_names_load_nothing_and_list_the_broken_plugin(broken: Breakage) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for group, registry in REGISTRIES.items():
            assert BROKEN[group] in registry.names() and registry.is_plugin(BROKEN[group])
        assert "broken_sc" in agentsim_env.list_scenarios() and "beacon" in agentsim_env.list_scenarios()
    assert not caught
    assert not [m for m in sys.modules if m.startswith(("plugmod_", "agentsim_beacon"))]


def test_usable_names_leave_the_broken_plugin_out_with_one_warning(broken: Breakage) -> None:
    from agentsim_env.scenarios.registry import usable_scenarios

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(2):
            for group, registry in REGISTRIES.items():
                names = registry.usable_names()
                assert BROKEN[group] not in names and set(names) == set(registry.names()) - {BROKEN[group]}
            assert usable_scenarios() == ["beacon", *BUILTIN_SCENARIOS]
    assert all(c.category is PluginLoadWarning for c in caught), [str(c.message) for c in caught]
    messages = _plugin_warnings(caught)
    assert len(messages) == 3, messages  # one per plug-in and process, however often it is listed
    for group in REGISTRIES:
        (message,) = [m for m in messages if repr(group) in m]
        assert repr(BROKEN[group]) in message and repr(broken.ref) in message and broken.says in message
        assert "left out" in message and "reinstall or uninstall" in message


# ------------------------------------------------------------------------------------------ lookup
def test_other_names_load_whatever_plugin_is_broken(broken: Breakage) -> None:
    from agentsim_env.policies.registry import make_policy
    from agentsim_env.policies.release import strategy_class
    from agentsim_env.scenarios.registry import scenario_class

    with pytest.raises(PluginLoadError):  # the broken ones fail first, then the others still load
        POLICIES.get("broken_pol")
    with pytest.raises(PluginLoadError):
        SCENARIOS.get("broken_sc")
    for name in BUILTIN_SCENARIOS + ["beacon"]:
        assert scenario_class(name).name == name
    assert strategy_class("B5_cvt").name == "B5_cvt" and strategy_class("beacon_ring").name == "beacon_ring"
    env = agentsim_env.make("beacon", n_agents=3, max_steps=5)
    with pytest.warns(PluginLoadWarning, match="'broken_pol'"):  # make_policy lists the plug-in policies
        assert type(make_policy("beacon", env, "to_beacon")).__name__ == "ToBeaconPolicy"
    nav = agentsim_env.make("navigation", n_agents=2, max_steps=5)
    assert type(make_policy("navigation", nav, "go_to_goal")).__name__ == "GoToGoalPolicy"
    assert nav.rollout("random", 5, seed=0).steps == 5


def test_the_broken_name_raises_an_error_naming_the_plugin(broken: Breakage) -> None:
    from agentsim_env.policies.registry import baseline_names, make_policy, policy_class, resolve_policy
    from agentsim_env.policies.release import strategy_class
    from agentsim_env.scenarios.registry import scenario_class

    with pytest.warns(PluginLoadWarning):
        baseline_names("uav_release")  # lists the policy and strategy plug-ins: warned now, and never again
    warnings.simplefilter("error", PluginLoadWarning)  # pytest restores the filters after the test
    for group, registry in REGISTRIES.items():
        for _ in range(2):  # kept: the second lookup raises the same error, from the same original
            with pytest.raises(PluginLoadError, match="cannot be loaded") as err:
                registry.get(BROKEN[group])
            _check_error(err.value, group, broken)
    with pytest.raises(PluginLoadError) as err:
        scenario_class("broken_sc")
    _check_error(err.value, "agentsim_env.scenarios", broken)
    with pytest.raises(PluginLoadError) as err:
        agentsim_env.make("broken_sc")
    _check_error(err.value, "agentsim_env.scenarios", broken)
    with pytest.raises(PluginLoadError) as err:
        strategy_class("broken_ring")
    _check_error(err.value, "agentsim_env.strategies", broken)
    nav = agentsim_env.make("navigation", n_agents=2, max_steps=5)
    for call in (
        lambda: make_policy("navigation", nav, "broken_pol"),
        lambda: policy_class("navigation", "broken_pol"),
        lambda: resolve_policy("navigation", "broken_pol", {}),
    ):
        with pytest.raises(PluginLoadError) as err:
            call()
        _check_error(err.value, "agentsim_env.policies", broken)
    with pytest.raises(PluginLoadError) as err:
        make_policy("uav_release", None, "broken_ring")
    _check_error(err.value, "agentsim_env.strategies", broken)
    with pytest.raises(ValueError, match=r"unknown policy 'nope'; known: \[.*'broken_pol'"):
        POLICIES.get("nope")  # an unknown name is still a plain ValueError


# ------------------------------------------------------------------------------------------ the policies package
def test_baselines_of_every_scenario_leave_the_broken_plugins_out(broken: Breakage) -> None:
    from agentsim_env.policies.registry import BASELINES, baseline_names

    with pytest.warns(PluginLoadWarning) as caught:
        assert baseline_names("beacon") == ["to_beacon"]
        for scenario in BUILTIN_SCENARIOS:
            names = baseline_names(scenario)
            assert names[: len(BASELINES[scenario])] == list(BASELINES[scenario])
            assert "broken_pol" not in names and "broken_ring" not in names
        assert baseline_names("uav_release")[-1] == "beacon_ring" and len(BASELINES["uav_release"]) == 11
    assert sorted(m.split()[0] for m in _plugin_warnings(caught)) == ["policy", "strategy"]
    with pytest.raises(ValueError, match=r"no scripted baselines for scenario 'nowhere'; known: \['beacon', "):
        baseline_names("nowhere")


def test_training_evaluation_lists_the_baselines_without_the_broken_plugins(broken: Breakage) -> None:
    pytest.importorskip("yaml")
    from agentsim_env.train.config import load_config
    from agentsim_env.train.evaluate import baselines_of

    with pytest.warns(PluginLoadWarning, match="'broken_pol'"):
        assert baselines_of(load_config("navigation", {"eval": {"baselines": "all"}})) == ["go_to_goal", "random"]
    with pytest.warns(PluginLoadWarning, match="'broken_ring'"):
        uav = baselines_of(load_config("uav_release", {"eval": {"baselines": "all"}}))
    assert uav[0] == "B5_cvt" and uav[-1] == "beacon_ring" and "broken_ring" not in uav
    with pytest.raises(PluginLoadError) as err:
        baselines_of(load_config("navigation", {"eval": {"baselines": "go_to_goal,broken_pol"}}))
    _check_error(err.value, "agentsim_env.policies", broken)


def test_the_scenarios_command_lists_the_rest(broken: Breakage, capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    with pytest.warns(PluginLoadWarning, match="'broken_sc'"):
        assert main(["scenarios"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == ["beacon", *BUILTIN_SCENARIOS]


# ------------------------------------------------------------------------------------------ loads but refused
@pytest.fixture
def odd_plugins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Plug-ins that load but cannot be used: a policy that names no scenario, one named as a built-in baseline
    of a scenario it serves, a scenario class registered under another name; and one that works."""
    (tmp_path / "plugmod_odd.py").write_text(
        textwrap.dedent(
            """
            from agentsim_env.policies.navigation import GoToGoalPolicy
            from agentsim_env.scenarios.rendezvous import Rendezvous


            class Untagged(GoToGoalPolicy):
                '''Names no scenario.'''


            class Meet(GoToGoalPolicy):
                '''Named 'meet' (rendezvous's built-in baseline) in the entry points.'''

                scenarios = ("navigation", "rendezvous")


            class Works(GoToGoalPolicy):
                '''Serves navigation.'''

                scenarios = ("navigation",)


            class Misnamed(Rendezvous):
                '''Registered as odd_sc, named rendezvous.'''
            """
        )
    )
    info = tmp_path / "plugmod_odd-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: plugmod-odd\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[agentsim_env.policies]\nuntagged = plugmod_odd:Untagged\nmeet = plugmod_odd:Meet\n"
        "works = plugmod_odd:Works\n[agentsim_env.scenarios]\nodd_sc = plugmod_odd:Misnamed\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    warned = set(plugins._WARNED)
    plugins._WARNED.clear()
    _refresh()
    try:
        yield
    finally:
        monkeypatch.undo()
        _refresh()
        plugins._WARNED.clear()
        plugins._WARNED.update(warned)
        sys.modules.pop("plugmod_odd", None)


def test_plugins_that_load_but_cannot_be_used_are_left_out(odd_plugins: None) -> None:
    from agentsim_env.policies.registry import baseline_names, make_policy
    from agentsim_env.policies.rendezvous import MeetPolicy
    from agentsim_env.scenarios.registry import scenario_class, usable_scenarios

    with pytest.warns(PluginLoadWarning) as caught:
        assert baseline_names("navigation") == ["go_to_goal", "random", "works"]
        assert baseline_names("rendezvous") == ["meet", "random"]  # the built-in keeps its name
        assert usable_scenarios() == BUILTIN_SCENARIOS
    messages = _plugin_warnings(caught)
    assert len(messages) == 3 and all("loads but cannot be used" in m for m in messages), messages
    env = agentsim_env.make("rendezvous", n_agents=2, max_steps=5)
    assert isinstance(make_policy("rendezvous", env, "meet"), MeetPolicy)
    with pytest.raises(PluginLoadError, match=r"'meet' = 'plugmod_odd:Meet'.*built-in baseline of 'rendezvous'"):
        POLICIES.get("meet")
    nav = agentsim_env.make("navigation", n_agents=2, max_steps=5)
    with pytest.raises(PluginLoadError, match=r"'untagged' = 'plugmod_odd:Untagged' .*names no scenario"):
        make_policy("navigation", nav, "untagged")
    with pytest.raises(PluginLoadError, match=r"'odd_sc' .*whose name is 'rendezvous'; register it under its own"):
        scenario_class("odd_sc")


def test_a_registration_may_take_the_name_of_a_broken_plugin(broken: Breakage) -> None:
    from agentsim_env.policies.navigation import GoToGoalPolicy
    from agentsim_env.policies.registry import baseline_names

    with pytest.raises(PluginLoadError):
        POLICIES.get("broken_pol")
    agentsim_env.register_policy("broken_pol", GoToGoalPolicy, scenario="navigation", replace=True)
    try:
        assert POLICIES.get("broken_pol") is GoToGoalPolicy and not POLICIES.is_plugin("broken_pol")
        assert baseline_names("navigation") == ["go_to_goal", "random", "broken_pol"]
    finally:
        POLICIES.unregister("broken_pol")
        plugins._POLICY_SCENARIOS.pop("broken_pol", None)
    with pytest.raises(PluginLoadError):  # the entry point shows again, as broken as it was
        POLICIES.get("broken_pol")
