"""The release strategy registry and the ``ReleaseStrategy`` contract: names, options, registration, the doc."""

from __future__ import annotations

import re
import sys
import types
import warnings
from dataclasses import FrozenInstanceError, dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

import agentsim_env
from agentsim_env.policies.registry import baseline_names, make_policy, resolve_policy
from agentsim_env.policies.release import (
    Bound,
    Choice,
    Pattern,
    PlanContext,
    ReleasePolicy,
    ReleaseStrategy,
    make_plan,
    make_strategy,
    register,
    strategy_class,
    strategy_names,
    unregister,
)
from agentsim_env.policies.release.baselines import B5Cvt, B6DropClusters, B8Teleport
from agentsim_env.uav.evaluation import runner
from agentsim_env.uav.wsn.profiles import RadialProfile

SHIPPED = [
    "B0_uniform",
    "B1_inverse_cdf",
    "B1LD_sunflower",
    "B2_rings",
    "B3_spiral",
    "B4_boustrophedon",
    "B5_cvt",
    "B6_drop_clusters",
    "B7_ergodic",
    "B8_teleport",
]
TINY = {"zones": "tiny", "n_uavs": 2, "payload": 12, "wind": {"mean_speed": 0.0}}
DOC = Path(__file__).resolve().parents[1] / "docs" / "release_strategies.md"


# ------------------------------------------------------------------------------------- names
def test_names_are_the_shipped_strategies_and_b5_is_the_default_baseline() -> None:
    assert strategy_names() == SHIPPED
    assert [strategy_class(n).name for n in SHIPPED] == SHIPPED
    assert baseline_names("uav_release")[0] == "B5_cvt"
    assert sorted(baseline_names("uav_release")) == sorted(SHIPPED)


def test_unknown_name_lists_the_known_names() -> None:
    with pytest.raises(ValueError, match="strategy must be one of") as err:
        strategy_class("B9_magic")
    assert all(n in str(err.value) for n in SHIPPED) and "B9_magic" in str(err.value)
    with pytest.raises(ValueError, match="B0_uniform"):
        make_strategy("B9_magic")


# ------------------------------------------------------------------------------------- options
@pytest.mark.parametrize(
    ("name", "options", "needle"),
    [
        ("B2_rings", {"n_rings": 0}, "n_rings must be >= 1, got 0"),
        (
            "B2_rings",
            {"ring_radii": "spiral"},
            "ring_radii must be one of ('cdf', 'isotropic'), got 'spiral'",
        ),
        ("B4_boustrophedon", {"lane_spacing": -2.0}, "lane_spacing must be > 0.0, got -2.0"),
        ("B6_drop_clusters", {"n_drops": 0}, "n_drops must be >= 1"),
        ("B7_ergodic", {"modes": 1}, "modes must be >= 2"),
        ("B8_teleport", {"base": "B3_spiral"}, "base must be one of ('B1LD_sunflower', 'B5_cvt')"),
        ("B5_cvt", {"fall_dt": 0.0}, "fall_dt must be > 0.0"),
        ("B1_inverse_cdf", {"mode": "teleport"}, "mode must be one of (None, 'hover', 'waypoints')"),
    ],
)
def test_a_bad_option_value_raises_naming_the_option_the_value_and_the_allowed_ones(
    name: str, options: dict[str, Any], needle: str
) -> None:
    with pytest.raises(ValueError, match=re.escape(f"{name} option {needle}")):
        make_strategy(name, **options)


@pytest.mark.parametrize(
    ("name", "options", "needle"),
    [
        ("B2_rings", {"n_rings": "3"}, "n_rings must be an integer, got '3'"),
        ("B2_rings", {"n_rings": 2.5}, "n_rings must be an integer"),
        ("B5_cvt", {"lloyd_iters": True}, "lloyd_iters must be an integer"),
        ("B0_uniform", {"two_opt": 1}, "two_opt must be True or False"),
        ("B7_ergodic", {"spacing": "wide"}, "spacing must be a finite number"),
    ],
)
def test_option_types_are_checked(name: str, options: dict[str, Any], needle: str) -> None:
    with pytest.raises(ValueError, match=re.escape(needle)):
        make_strategy(name, **options)


def test_options_are_typed_frozen_fields_and_unknown_ones_are_refused() -> None:
    s = make_strategy("B5_cvt", lloyd_iters=np.int64(5), min_leg=3)
    assert isinstance(s, B5Cvt) and s.lloyd_iters == 5 and type(s.lloyd_iters) is int
    assert s.min_leg == 3.0 and type(s.min_leg) is float
    with pytest.raises(FrozenInstanceError):
        s.lloyd_iters = 6  # type: ignore[misc]
    with pytest.raises(ValueError, match=r"options for B0_uniform must be among .*'two_opt'.*\['n_rings'\]"):
        make_strategy("B0_uniform", n_rings=3)
    assert B5Cvt.option_rule("lloyd_iters") == Bound(0) and B5Cvt.option_rule("fall_dt") == Bound(0.0, lo_open=True)
    assert "grid" in B5Cvt.options() and "grid" not in strategy_class("B0_uniform").options()


def test_per_strategy_behaviour_comes_from_the_class() -> None:
    assert make_strategy("B6_drop_clusters").hovers and make_strategy("B8_teleport").hovers
    assert not make_strategy("B2_rings").hovers and make_strategy("B2_rings", mode="hover").hovers
    assert B6DropClusters.release_speed == 0.0 and B8Teleport.plan_mode == "teleport"
    alts = B8Teleport().layer_altitudes(np.array([15.0, 30.0]), 3, 2.0, (5.0, 40.0))
    np.testing.assert_array_equal(alts, [[5.0, 5.0], [7.0, 7.0], [9.0, 9.0]])
    alts = B5Cvt().layer_altitudes(np.array([15.0, 39.0]), 2, 2.0, (5.0, 40.0))
    np.testing.assert_array_equal(alts, [[15.0, 39.0], [17.0, 40.0]])


# ------------------------------------------------------------------------------------- the old name
def test_b8_oracle_is_a_deprecated_alias_of_b8_teleport() -> None:
    with pytest.warns(DeprecationWarning, match="'B8_oracle' is deprecated.*'B8_teleport'"):
        assert strategy_class("B8_oracle") is B8Teleport
    assert "B8_oracle" not in strategy_names() and "B8_oracle" not in baseline_names("uav_release")
    profile = RadialProfile("gauss", 50.0, sigma=20.0)
    with pytest.warns(DeprecationWarning):
        plan = make_plan("B8_oracle", (0.0, 0.0), profile, 30, 20.0, 5.0, np.random.default_rng(0))
    assert plan.strategy == "B8_teleport" and plan.mode == "teleport"
    env = agentsim_env.make("uav_release", **TINY)
    with pytest.warns(DeprecationWarning):
        pol = make_policy("uav_release", env, "B8_oracle")
    assert isinstance(pol, ReleasePolicy) and pol.strategy == "B8_teleport"
    with pytest.warns(DeprecationWarning):
        assert resolve_policy("uav_release", "B8_oracle", {}) == ("B8_oracle", {})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the current name never warns
        assert make_policy("uav_release", env, "B8_teleport").strategy == "B8_teleport"  # type: ignore[attr-defined]


# ------------------------------------------------------------------------------------- registration
@dataclass(frozen=True, kw_only=True)
class CentreCross(ReleaseStrategy):
    """Test strategy: the wedge's sensors on a line through the centre along its mid-angle, flown outward."""

    name: ClassVar[str] = "T1_centre_line"
    description: ClassVar[str] = "a line of sensors along the wedge's mid-angle"
    release_speed: ClassVar[float] = 3.0
    bounds: ClassVar = {"reach": Bound(0.0, 1.0, lo_open=True), "order": Choice(("out", "in"))}

    reach: float = 0.8
    order: str = "out"

    def pattern(self, ctx: PlanContext) -> Pattern:
        from agentsim_env.policies.release.planning import sector_quota

        n = sector_quota(ctx.n_sensors, ctx.sector)
        theta0, width = ctx.wedge
        r = self.reach * ctx.radius * (np.arange(n) + 1.0) / max(n, 1)
        if self.order == "in":
            r = r[::-1]
        a = theta0 + 0.5 * width
        return Pattern(np.stack([r * np.cos(a), r * np.sin(a)], axis=1).reshape(-1, 2), info={"n": n})


@pytest.fixture
def centre_line() -> Any:
    register(CentreCross)
    yield CentreCross
    unregister(CentreCross.name)


def test_a_registered_strategy_is_planned_and_flown_by_name(centre_line: Any) -> None:
    name = centre_line.name
    assert strategy_names()[-1] == name and name in baseline_names("uav_release")
    assert name in runner.available_strategies() and runner.resolve_strategies([name]) == [name]
    assert baseline_names("uav_release")[0] == "B5_cvt"
    with pytest.raises(ValueError, match="T1_centre_line option reach must be <= 1.0, got 2.0"):
        make_strategy(name, reach=2.0)
    profile = RadialProfile("gauss", 50.0, sigma=20.0)
    plan = make_plan(name, (100.0, 100.0), profile, 20, 20.0, 3.0, np.random.default_rng(0), options={"order": "in"})
    assert plan.strategy == name and plan.mode == "waypoints" and plan.n_releases == 20
    assert plan.info == {"n": 20}
    env = agentsim_env.make("uav_release", **TINY)
    pol = make_policy("uav_release", env, name)
    assert isinstance(pol, ReleasePolicy) and pol.strategy == name and pol.release_speed == 3.0
    obs, _ = env.reset(seed=0)
    pol.reset(0)
    for _ in range(4000):
        obs, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
        if pol.mission_complete and env.world.payloads.objects.n_falling == 0:
            break
    objs = env.world.payloads.objects
    zones = env.scenario.zones
    landed, land = objs.get("landed")[: objs.count], objs.get("land_xy")[: objs.count]
    assert pol.mission_complete and landed.sum() == zones.n_sensors
    # the custom pattern was flown: every sensor within reach (0.8 R) of its zone's centre, none on the rim
    zone = objs.get("zone")[: objs.count]
    dist = np.hypot(*(land - zones.centres()[zone]).T)
    assert np.all(dist <= 0.8 * zones.radii()[zone] + 2.0)
    env.close()


def test_registration_refuses_bad_classes_and_taken_names(centre_line: Any) -> None:
    with pytest.raises(ValueError, match="taken"):
        register(centre_line)
    with pytest.raises(ValueError, match="taken"):
        register(B8Teleport)
    with pytest.raises(ValueError, match="concrete ReleaseStrategy subclass"):
        register(ReleaseStrategy)
    with pytest.raises(ValueError, match="concrete ReleaseStrategy subclass"):
        register(dict)  # type: ignore[arg-type]

    @dataclass(frozen=True, kw_only=True)
    class Nameless(CentreCross):
        name: ClassVar[str] = ""

    with pytest.raises(ValueError, match="name must be a non-empty identifier"):
        register(Nameless)
    with pytest.raises(ValueError, match="was not registered with register"):
        unregister("T9_never_registered")


# ------------------------------------------------------------------------------------- the doc
def test_the_docs_example_runs_and_every_shipped_strategy_is_documented(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    text = DOC.read_text(encoding="utf-8")
    for name in SHIPPED:
        assert f"| `{name}` |" in text
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    example = next(b for b in blocks if "class SingleRing" in b)
    module = types.ModuleType("release_strategies_doc")  # run as a module of its own, as a user would
    monkeypatch.setitem(sys.modules, module.__name__, module)
    exec(compile(example, str(DOC), "exec", dont_inherit=True), module.__dict__)  # noqa: S102
    scope = module.__dict__
    assert "X1_single_ring" not in strategy_names()  # the example unregisters its strategy
    with pytest.raises(ValueError, match="X1_single_ring option radius_share must be <= 1.0, got 1.5"):
        scope["SingleRing"](radius_share=1.5)
