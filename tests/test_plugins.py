"""core.plugins: registries by object, by "module:attr" reference and by entry points; the scenario and policy
registries read through them; the top-level exports."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

import agentsim_env
from agentsim_env.core import plugins
from agentsim_env.core.plugins import POLICIES, SCENARIOS, STRATEGIES, Registry


@pytest.fixture(autouse=True)
def clean_registries() -> Iterator[None]:
    """Every test leaves the global registries as it found them."""
    saved = [(r, dict(r._registered), dict(r._loaded)) for r in (SCENARIOS, POLICIES, STRATEGIES)]
    served = dict(plugins._POLICY_SCENARIOS)
    yield
    for reg, registered, loaded in saved:
        reg._registered, reg._loaded = registered, loaded
        reg.refresh()
    plugins._POLICY_SCENARIOS.clear()
    plugins._POLICY_SCENARIOS.update(served)


@pytest.fixture
def module_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder on sys.path with ``plugmod_things.py`` (a class, a function, an int) and a broken module."""
    (tmp_path / "plugmod_things.py").write_text(
        textwrap.dedent(
            '''
            class Thing:
                """A class."""

                class Inner:
                    """A nested class."""


            def helper():
                """A function."""


            NUMBER = 3
            '''
        )
    )
    (tmp_path / "plugmod_broken.py").write_text("import plugmod_missing_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for name in ("plugmod_things", "plugmod_broken"):
        sys.modules.pop(name, None)


def _fake_distribution(folder: Path, name: str, entry_points: str) -> None:
    """A distribution's metadata (what pip installs) with ``entry_points.txt``: importlib.metadata finds it."""
    info = folder / f"{name}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))


def _is_class(obj: object) -> bool:
    return isinstance(obj, type)


# ------------------------------------------------------------------------------------------ Registry
def test_register_by_object_and_by_reference_loaded_on_first_get(module_dir: Path) -> None:
    reg = Registry("widget", "agentsim_env.test_widgets", {"base": "plugmod_things:Thing"}, _is_class, "a class")
    reg.register("obj", dict)
    reg.register("nested", "plugmod_things:Thing.Inner")
    assert reg.names() == ["base", "nested", "obj"] and "nested" in reg and "other" not in reg
    assert "plugmod_things" not in sys.modules  # references load on first get, not on registration
    assert reg.get("obj") is dict
    inner = reg.get("nested")
    assert inner.__qualname__ == "Thing.Inner" and reg.get("nested") is inner
    assert reg.get("base").__name__ == "Thing"
    assert [reg.origin(n) for n in ("base", "obj")] == ["built-in", "registered"]
    assert dict(reg.items()) == {"base": reg.get("base"), "nested": inner, "obj": dict}


def test_bad_references_name_the_reference_and_what_was_expected(module_dir: Path) -> None:
    reg = Registry("widget", "agentsim_env.test_widgets", None, _is_class, "a class")
    for ref in ("plugmod_things.Thing", "plugmod_things:", ":Thing", "plug mod:Thing", "a:b:c"):
        with pytest.raises(ValueError, match="must be 'package.module:attribute'") as err:
            reg.register("x", ref)
        assert repr(ref) in str(err.value)
    reg.register("missing_module", "plugmod_nowhere.sub:Thing")
    reg.register("missing_attr", "plugmod_things:Nothing")
    reg.register("function", "plugmod_things:helper")
    reg.register("number", "plugmod_things:NUMBER")
    with pytest.raises(ValueError, match=r"'plugmod_nowhere.sub:Thing': no module named 'plugmod_nowhere'"):
        reg.get("missing_module")
    with pytest.raises(ValueError, match=r"'plugmod_things:Nothing': 'plugmod_things' has no attribute 'Nothing'"):
        reg.get("missing_attr")
    with pytest.raises(ValueError, match=r"'plugmod_things:helper' is a function, expected a class"):
        reg.get("function")
    with pytest.raises(ValueError, match=r"'plugmod_things:NUMBER' is an int, expected a class"):
        reg.get("number")
    with pytest.raises(ValueError, match=r"widget 'obj' must be a class or a 'module:attribute' reference"):
        reg.register("obj", 3)
    # a module that fails on an import of its own is not a bad reference: its error surfaces as it is
    reg.register("broken", "plugmod_broken:Thing")
    with pytest.raises(ModuleNotFoundError, match="plugmod_missing_dependency"):
        reg.get("broken")


def test_names_are_checked_and_taken_names_refused_unless_replace() -> None:
    reg = Registry("widget", "agentsim_env.test_widgets", {"base": int}, _is_class, "a class")
    for bad in ("", "has space", "-lead", "x" * 65, "semi;colon", 7, None):
        with pytest.raises(ValueError, match="widget name must be 1 to 64 characters"):
            reg.register(bad, float)  # type: ignore[arg-type]
    for good in ("B5_cvt", "my-scenario", "v1.2", "9lives"):
        reg.register(good, float)
    with pytest.raises(ValueError, match=r"widget name 'base' is already taken \(built-in\).*replace=True"):
        reg.register("base", float)
    with pytest.raises(ValueError, match=r"'B5_cvt' is already taken \(registered\)"):
        reg.register("B5_cvt", str)
    reg.register("base", float, replace=True)
    assert reg.get("base") is float and reg.origin("base") == "registered"
    reg.unregister("base")
    assert reg.get("base") is int  # the built-in shows again
    with pytest.raises(ValueError, match="was not registered"):
        reg.unregister("base")
    with pytest.raises(ValueError, match=r"unknown widget 'nope'; known: \['9lives', 'B5_cvt', 'base'"):
        reg.get("nope")


def test_entry_points_of_installed_distributions(
    tmp_path: Path, module_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    group = "agentsim_env.test_widgets"
    reg = Registry("widget", group, {"base": int}, _is_class, "a class")
    assert reg.names() == ["base"]  # entry points read now, before the distribution exists
    dists = tmp_path / "site"
    dists.mkdir()
    _fake_distribution(
        dists,
        "widget_plugin",
        f"""
        [{group}]
        thing = plugmod_things:Thing
        base = plugmod_things:Thing
        bad name = plugmod_things:Thing
        [another.group]
        elsewhere = plugmod_things:Thing
        """,
    )
    monkeypatch.syspath_prepend(str(dists))
    assert reg.names() == ["base"]  # read once ...
    with pytest.warns(RuntimeWarning) as caught:
        reg.refresh()  # ... until refreshed
        assert reg.names() == ["base", "thing"]
    messages = " | ".join(str(w.message) for w in caught)
    assert "'base'" in messages and "taken by a built-in" in messages and "'bad name'" in messages
    assert reg.get("thing").__name__ == "Thing" and reg.get("base") is int
    assert reg.origin("thing") == "entry point 'plugmod_things:Thing' of widget_plugin"
    with pytest.raises(ValueError, match=r"'thing' is already taken \(entry point 'plugmod_things:Thing' of "):
        reg.register("thing", float)
    reg.register("thing", float, replace=True)  # a registration wins over the entry point
    assert reg.get("thing") is float


# ------------------------------------------------------------------------------------------ the three
def test_the_three_registries_and_their_groups() -> None:
    assert (SCENARIOS.group, POLICIES.group, STRATEGIES.group) == (
        "agentsim_env.scenarios",
        "agentsim_env.policies",
        "agentsim_env.strategies",
    )
    assert SCENARIOS.builtin_names() == ["navigation", "relay", "rendezvous", "uav_release"]
    with pytest.raises(ValueError, match="must be a Scenario subclass"):
        agentsim_env.register_scenario("not_a_scenario", dict)
    with pytest.raises(ValueError, match=r"must be a policy class \(for_env, reset, act\)"):
        agentsim_env.register_policy("not_a_policy", dict, scenario="rendezvous")
    assert "B5_cvt" in STRATEGIES.builtin_names() and len(STRATEGIES.builtin_names()) == 10
    with pytest.raises(ValueError, match="must be a ReleaseStrategy subclass"):
        agentsim_env.register_strategy("not_a_strategy", 3)
    with pytest.raises(ValueError, match="already taken"):
        agentsim_env.register_strategy("B5_cvt", "plugmod_nowhere:cvt")
    agentsim_env.register_strategy("spread", "plugmod_nowhere:spread")
    assert "spread" in STRATEGIES.names() and STRATEGIES.origin("spread") == "registered"


def test_registered_scenario_is_made_listed_and_checked() -> None:
    from agentsim_env.scenarios.registry import scenario_class
    from agentsim_env.scenarios.rendezvous import Rendezvous

    class Meet(Rendezvous):
        name = "meet_again"

    agentsim_env.register_scenario("meet_again", Meet)
    assert "meet_again" in agentsim_env.list_scenarios()
    env = agentsim_env.make("meet_again", n_agents=3, max_steps=5)
    assert type(env.scenario) is Meet and len(env.possible_agents) == 3
    agentsim_env.register_scenario("other_name", Meet)
    with pytest.raises(ValueError, match=r"'other_name' \(registered\) is the class .*Meet whose name is 'meet_ag"):
        scenario_class("other_name")
    with pytest.raises(ValueError, match="unknown scenario 'nowhere'; registered scenarios: "):
        agentsim_env.make("nowhere")


def test_the_old_register_still_works_with_a_deprecation_warning() -> None:
    from agentsim_env.scenarios.registry import register, scenario_class
    from agentsim_env.scenarios.rendezvous import Rendezvous

    with pytest.warns(DeprecationWarning, match="use agentsim_env.register_scenario"):
        register("rendezvous", "agentsim_env.scenarios.rendezvous")
    assert scenario_class("rendezvous") is Rendezvous and SCENARIOS.origin("rendezvous") == "registered"


def test_registered_policy_serves_its_scenarios() -> None:
    from agentsim_env.policies.registry import baseline_names, make_policy, policy_class, resolve_policy
    from agentsim_env.policies.rendezvous import MeetPolicy

    class Eager(MeetPolicy):
        """MeetPolicy without slowing down."""

        @classmethod
        def for_env(cls, env: object, **options: object) -> MeetPolicy:
            pol = super().for_env(env)
            pol.slow_radius = 1e-3
            return pol

    class Tagged(MeetPolicy):
        scenarios = ("rendezvous", "navigation")

    agentsim_env.register_policy("eager", Eager, scenario="rendezvous")
    agentsim_env.register_policy("tagged", Tagged)
    assert baseline_names("rendezvous") == [
        "meet",
        "random",
        "eager",
        "tagged",
    ]  # built-ins first, default kept
    assert baseline_names("navigation")[-1] == "tagged" and "eager" not in baseline_names("navigation")
    assert plugins.policy_scenarios("tagged") == ("rendezvous", "navigation")
    assert policy_class("rendezvous", "eager") is Eager
    env = agentsim_env.make("rendezvous", n_agents=3, max_steps=5)
    pol = make_policy("rendezvous", env, "eager")
    assert isinstance(pol, Eager) and pol.slow_radius == 1e-3
    assert resolve_policy("rendezvous", "eager", {}) == ("eager", {})
    assert env.rollout(pol, 5, seed=0).steps == 5
    with pytest.raises(ValueError, match=r"policy must be one of \['meet', 'random', 'eager', 'tagged'\]"):
        make_policy("rendezvous", env, "nope")
    with pytest.raises(ValueError, match="scenario name must be"):
        agentsim_env.register_policy("bad_scenario", Eager, scenario="has space")


def test_policy_without_scenario_or_with_a_builtin_name_is_refused() -> None:
    from agentsim_env.policies.registry import baseline_names
    from agentsim_env.policies.rendezvous import MeetPolicy

    agentsim_env.register_policy("meet", MeetPolicy, scenario="rendezvous")
    with pytest.raises(ValueError, match=r"'meet' \(registered\) repeats the name of a built-in baseline"):
        baseline_names("rendezvous")
    POLICIES.unregister("meet")
    agentsim_env.register_policy("untagged", MeetPolicy)
    with pytest.raises(ValueError, match=r"'untagged' \(registered\) names no scenario: give register_policy"):
        baseline_names("navigation")


# ------------------------------------------------------------------------------------------ top level
def test_top_level_exports() -> None:
    from agentsim_env.env.parallel_env import AgentSimParallelEnv
    from agentsim_env.env.vector import BatchedEnv
    from agentsim_env.scenarios.base import Scenario
    from agentsim_env.sim import World

    assert agentsim_env.BatchedEnv is BatchedEnv and agentsim_env.Scenario is Scenario
    assert agentsim_env.World is World
    assert agentsim_env.register_scenario is plugins.register_scenario
    assert agentsim_env.register_policy is plugins.register_policy
    assert agentsim_env.register_strategy is plugins.register_strategy
    assert set(agentsim_env.__all__) >= {"make", "parallel_env", "env", "list_scenarios", "__version__"}
    assert all(hasattr(agentsim_env, n) for n in agentsim_env.__all__)
    assert {"BatchedEnv", "Scenario", "World"} <= set(dir(agentsim_env))
    assert agentsim_env.make.__annotations__["return"] == "AgentSimParallelEnv"
    assert isinstance(agentsim_env.make("rendezvous", n_agents=2), AgentSimParallelEnv)
    with pytest.raises(AttributeError, match="has no attribute 'Nothing'"):
        agentsim_env.Nothing  # noqa: B018


def test_importing_the_package_loads_no_scenario_env_or_simulator() -> None:
    code = (
        "import sys, agentsim_env\n"
        "print(sorted(m for m in sys.modules if m.startswith('agentsim_env')))\n"
        "agentsim_env.World\n"
        "print('agentsim_env.sim.world' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    loaded, world = out.splitlines()
    heavy = ("agentsim_env.scenarios", "agentsim_env.sim", "agentsim_env.policies", "agentsim_env.env.")
    modules = eval(loaded)  # noqa: S307 (our own output)
    assert "agentsim_env.core.plugins" in modules
    assert not [m for m in modules if m.startswith(heavy)], modules
    assert world == "True"


def test_training_evaluation_compares_against_plugin_policies_too() -> None:
    pytest.importorskip("yaml")
    from agentsim_env.policies.navigation import GoToGoalPolicy
    from agentsim_env.train.config import load_config
    from agentsim_env.train.evaluate import baselines_of

    agentsim_env.register_policy("go_again", GoToGoalPolicy, scenario="navigation")
    assert baselines_of(load_config("navigation", {"eval": {"baselines": "all"}})) == [
        "go_to_goal",
        "random",
        "go_again",
    ]
    assert baselines_of(load_config("navigation", {"eval": {"baselines": "go_again"}})) == ["go_again"]
    with pytest.raises(ValueError, match=r"or from \['go_to_goal', 'random', 'go_again'\]"):
        baselines_of(load_config("navigation", {"eval": {"baselines": "nope"}}))
