"""Hypothesis fuzz over every registered scenario: random configs inside the documented ranges, random episodes.

For each scenario in ``agentsim_env.list_scenarios()`` a strategy below draws a config inside the ranges that
the config docstrings and validators document (every field of the scenario, sub-config dicts included), with
the range endpoints and other edge values drawn often. The example then builds the env, with
``check_finite=True`` half of the time when ``make`` accepts it. A ``ValueError`` of the config checks at
construction is allowed: the example is rejected with ``assume`` and counted. Any other exception fails, and so
does a ``ValueError`` raised inside the probe episode that construction runs to measure the spaces (a reset and
a step: that is an episode failing, not a config rejected). The env is then reset with a random seed and
stepped with random actions from the action spaces (dict and flat formats; with comms on, also ``send_message``
and ``assign_group`` from code) until every agent is done, which must happen by ``max_steps``; half of the
examples run a second episode. Checked on every step: no exception, no ``RuntimeWarning`` (turned into an error:
a silent NaN usually shows up as one), every observation inside its observation space and finite, every reward
finite, every info value a finite number, and (half of the time) ``state()`` finite and inside
``state_space``. A quarter of the examples run the array API instead (``BatchedEnv``, 1-3 worlds, for
``max_steps + 3`` steps, so across an automatic reset), with the same checks on its arrays.

A scenario registered without a strategy here fails the test: add one to ``STRATEGIES``.

Sizes: the fast profile (``make test``) runs ``FAST_EXAMPLES`` examples per scenario, derandomized (the same
examples every run), in about half a minute on 2 cores. ``AGENTSIM_FUZZ_EXAMPLES=N`` (``make fuzz``: 10,000)
selects the long profile instead: about N examples in all, split over the scenarios, randomized. Rejected
examples come on top (hypothesis counts valid examples only). A failure is shrunk to a minimal config, printed
as ``Draw 1 (config)`` with the seeds and the ``agentsim_env.make`` / ``BatchedEnv`` call that reproduces it.

Counts: every example that built an env and one rejected at construction is counted per scenario (the runs
hypothesis makes while shrinking a failure included). A
single-process run (``make fuzz``) prints them in a terminal-summary section "agentsim fuzz" (with the
commonest rejection messages); under pytest-xdist use ``--hypothesis-show-statistics``, whose "Events" lines
carry the same counts as percentages. Each test also records them as the ``fuzz`` user property (junit XML).

Ranges not bounded by the docs get a generous soft cap here (noted at the strategy), and a few sizes are kept
small for speed, not because larger values are invalid: at most 12 agents, episodes of at most 40 steps, at most
about 3,000 obstacles per world, zones of at most 300 m radius holding 1-12 sensors each, WSN coverage lattices
at least 0.5 m apart, at most 4 rings of rays (64 with at most 4 azimuths) and 1,024 azimuths with at most 2
rings.
"""

from __future__ import annotations

import functools
import inspect
import math
import os
import re
import warnings
from collections import Counter, defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st

import agentsim_env

# ----------------------------------------------------------------------------------------------- profiles
FAST_EXAMPLES = 100
"""Examples per scenario of the fast profile (``make test``)."""
ENV_VAR = "AGENTSIM_FUZZ_EXAMPLES"
"""Total examples over all scenarios of the long profile (``make fuzz`` sets 10,000)."""

_COMMON = {
    "deadline": None,
    "suppress_health_check": [
        HealthCheck.too_slow,
        HealthCheck.filter_too_much,
        HealthCheck.data_too_large,
        HealthCheck.function_scoped_fixture,
    ],
    "print_blob": True,
}
settings.register_profile("agentsim-fuzz", max_examples=FAST_EXAMPLES, derandomize=True, **_COMMON)


def _long_examples() -> int | None:
    raw = os.environ.get(ENV_VAR, "").strip()
    if not raw:
        return None
    total = int(raw)
    if total < 1:
        raise ValueError(f"{ENV_VAR} must be a positive integer, got {raw!r}")
    return total


_TOTAL = _long_examples()
_N_SCENARIOS = len(agentsim_env.list_scenarios())
settings.register_profile(
    "agentsim-fuzz-long",
    max_examples=max(1, math.ceil((_TOTAL or 10_000) / _N_SCENARIOS)),
    derandomize=False,
    **_COMMON,
)
PROFILE = "agentsim-fuzz-long" if _TOTAL is not None else "agentsim-fuzz"

# ----------------------------------------------------------------------------------------------- counting
_STATS: dict[str, Counter[str]] = defaultdict(Counter)
_REJECTIONS: dict[str, Counter[str]] = defaultdict(Counter)


def _reason(exc: BaseException) -> str:
    """A rejection message with its numbers blanked, so equal causes count together."""
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return re.sub(r"[-+]?\d[\d.,_]*(e[-+]?\d+)?", "#", text)[:110]


class _FuzzSummary:
    """Prints the example counts at the end of a single-process session (pytest-xdist workers cannot)."""

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if not _STATS:
            return
        tr = terminalreporter
        tr.section("agentsim fuzz")
        total = Counter[str]()
        for name in sorted(_STATS):
            c = _STATS[name]
            total.update(c)
            tr.write_line(
                f"{name:12s} {c['built']:6d} examples run, {c['rejected']:5d} rejected at construction "
                f"(ValueError), {c['steps']:7d} steps, {c['batched']:5d} via BatchedEnv, "
                f"{c['check_finite']:5d} with check_finite=True"
            )
        tr.write_line(
            f"{'total':12s} {total['built']:6d} examples run, {total['rejected']:5d} rejected at construction, "
            f"{total['steps']:7d} steps"
        )
        for name in sorted(_REJECTIONS):
            for reason, n in _REJECTIONS[name].most_common(8):
                tr.write_line(f"  rejected {name}: {n:4d} x {reason}")


@pytest.fixture(scope="session", autouse=True)
def _fuzz_summary_plugin(request: pytest.FixtureRequest) -> None:
    pm = request.config.pluginmanager
    if not hasattr(request.config, "workerinput") and not pm.has_plugin("agentsim-fuzz-summary"):
        pm.register(_FuzzSummary(), "agentsim-fuzz-summary")


# ------------------------------------------------------------------------------------- value strategies
# Strategies are built once and cached (building hypothesis strategies on every draw costs more than running a
# small episode); ranges that depend on an earlier draw are drawn as a fraction of the range instead.
@functools.cache
def real(
    lo: float,
    hi: float,
    *,
    lo_open: bool = False,
    typical: tuple[float, float] | None = None,
    edges: tuple[float, ...] = (),
) -> st.SearchStrategy[float]:
    """A float in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``).

    Drawn from, in this order (failing examples shrink toward the first): the ``typical`` sub-range, the edge
    values (the endpoints and ``edges``), anything in the range (hypothesis favours nasty values there: tiny
    and subnormal numbers next to an open zero bound, and the like).
    """
    inside = [e for e in edges if (lo < e if lo_open else lo <= e) and e <= hi]
    ends = ([] if lo_open else [lo]) + [hi] + inside
    options: list[st.SearchStrategy[float]] = []
    if typical is not None:
        options.append(st.floats(*typical, allow_nan=False, allow_infinity=False))
    options.append(st.sampled_from(ends))
    options.append(st.floats(lo, hi, exclude_min=lo_open, allow_nan=False, allow_infinity=False))
    return st.one_of(options)


def positive(
    hi: float, typical: tuple[float, float], edges: tuple[float, ...] = ()
) -> st.SearchStrategy[float]:
    """A float in ``(0, hi]`` with tiny edge values."""
    return real(0.0, hi, lo_open=True, typical=typical, edges=(1e-300, 1e-9, 1e-3, *edges))


@functools.cache
def pair(lo: float, hi: float, typical: tuple[float, float]) -> st.SearchStrategy:
    """``(low, high)`` with ``lo <= low <= high <= hi``: equal pairs, the endpoint pair and random ones."""
    one = real(lo, hi, typical=typical)

    @st.composite
    def draw_pair(draw: Any) -> tuple[float, float]:
        kind = draw(st.sampled_from(["random", "equal", "ends"]))
        if kind == "ends":
            return (lo, hi)
        a = draw(one)
        if kind == "equal":
            return (a, a)
        b = draw(one)
        return (min(a, b), max(a, b))

    return draw_pair()


@functools.cache
def optional(strategy: st.SearchStrategy) -> st.SearchStrategy:
    """``None`` or a value of ``strategy``."""
    return st.one_of(st.none(), strategy)


@functools.cache
def ints(lo: int, hi: int) -> st.SearchStrategy[int]:
    """An integer in ``[lo, hi]``, the endpoints drawn often."""
    return st.one_of(st.integers(lo, hi), st.sampled_from(sorted({lo, hi})))


UNIT = real(0.0, 1.0, typical=(0.0, 1.0), edges=(0.5,))
"""A fraction in [0, 1]: scales ranges that depend on earlier draws."""
MOSTLY = st.sampled_from([False, True, True, True])
"""Whether to set an optional key: usually (shrinks to "no")."""


def maybe(draw: Any, out: dict[str, Any], key: str, strategy: st.SearchStrategy) -> None:
    """Set ``out[key]`` most of the time (an omitted key keeps the default; shrinking omits keys it can)."""
    if draw(MOSTLY):
        out[key] = draw(strategy)


def within(draw: Any, lo: float, hi: float) -> float:
    """A float in ``[lo, hi]`` for bounds known only at draw time (the endpoints and the middle drawn often)."""
    return min(hi, max(lo, lo + (hi - lo) * draw(UNIT)))


# ---------------------------------------------------------------------------------- sub-config strategies
@st.composite
def body_dict(draw: Any) -> dict[str, Any]:
    """``BodyConfig``: radius, max_speed, max_accel in [0.01, 1e4]; altitude band >= 0.1 m high, <= 1e4 m."""
    out: dict[str, Any] = {}
    maybe(draw, out, "radius", real(0.01, 1e4, typical=(0.05, 1.5)))
    maybe(draw, out, "max_speed", real(0.01, 1e4, typical=(0.5, 20.0)))
    maybe(draw, out, "max_accel", real(0.01, 1e4, typical=(0.5, 20.0)))
    if draw(st.sampled_from([False, True, True])):
        low = draw(real(0.0, 1e4 - 0.1, typical=(0.0, 30.0)))
        span = draw(real(0.1, 1e4, typical=(0.1, 30.0), edges=(0.1000001,)))
        high = min(1e4, low + span)
        while high - low < 0.1 and high < 1e4:  # rounding: the narrowest band is exactly 0.1 m high
            high = math.nextafter(high, math.inf)
        out["altitude"] = (low, high)
    return out


@st.composite
def sensing_dict(draw: Any) -> dict[str, Any]:
    """``SensingConfig``: range in [0.01, 1e5], 1..1024 azimuths, 1..64 rings in [-90, 90] degrees.

    The ray count is kept small for speed: 1024 azimuths only with at most 2 rings, 64 rings only with at most
    4 azimuths.
    """
    out: dict[str, Any] = {}
    maybe(draw, out, "range", real(0.01, 1e5, typical=(1.0, 40.0)))
    n_az = draw(st.one_of(st.integers(1, 24), st.sampled_from([1, 2, 1024])))
    if draw(st.booleans()):
        out["n_azimuth"] = n_az
    n_rings_max = 64 if n_az <= 4 else (2 if n_az > 64 else 4)
    if draw(st.sampled_from([False, True, True])):
        n_rings = draw(ints(1, min(4, n_rings_max)) if draw(st.booleans()) else st.just(n_rings_max))
        elev = real(-90.0, 90.0, typical=(-45.0, 10.0), edges=(0.0,))
        out["elevations_deg"] = tuple(draw(elev) for _ in range(n_rings))
    return out


@st.composite
def reward_dict(draw: Any) -> dict[str, Any]:
    """``RewardConfig``: every weight >= 0 (unbounded; soft cap 1e6)."""
    out: dict[str, Any] = {}
    for name in ("task_weight", "group_share", "collision_penalty", "energy_weight", "message_cost"):
        maybe(draw, out, name, real(0.0, 1e6, typical=(0.0, 10.0)))
    return out


@st.composite
def comms_dict(draw: Any) -> dict[str, Any]:
    """``CommsConfig`` (soft caps: latency <= 5, bandwidth <= 4, ranges <= 1e4 m, heartbeat period <= 12)."""
    out: dict[str, Any] = {}
    maybe(draw, out, "payload_dim", st.one_of(st.sampled_from([0, 1, 64]), st.integers(0, 64)))
    maybe(draw, out, "inbox_size", st.one_of(st.sampled_from([1, 64]), st.integers(1, 16)))
    latency = draw(st.integers(0, 5))
    if latency or draw(st.booleans()):
        out["latency"] = latency
    maybe(draw, out, "loss", real(0.0, 1.0, typical=(0.0, 0.5)))
    maybe(draw, out, "bandwidth", st.integers(0, 4))
    maybe(draw, out, "max_range", optional(positive(1e4, (5.0, 100.0))))
    maybe(draw, out, "overlay_range", positive(1e4, (5.0, 100.0)))
    maybe(draw, out, "overlay_full", st.booleans())
    maybe(draw, out, "max_hops", st.one_of(st.sampled_from([1, 255]), st.integers(1, 12)))
    maybe(draw, out, "nearest_range", positive(1e4, (5.0, 100.0)))
    period = draw(st.integers(0, 12))
    if period or draw(st.booleans()):
        out["heartbeat_period"] = period
    if period or draw(st.booleans()):  # the timeout must be >= period + 2 * latency when heartbeats are on
        out["heartbeat_timeout"] = max(1, period + 2 * latency) + draw(st.integers(0, 20))
    return out


@st.composite
def gnss_dict(draw: Any) -> dict[str, Any]:
    """``GnssConfig``: sigma_h and sigma_v in [0, 1e3]."""
    out: dict[str, Any] = {}
    for name in ("sigma_h", "sigma_v"):
        maybe(draw, out, name, real(0.0, 1e3, typical=(0.0, 5.0), edges=(1e-300, 1e-3)))
    return out


@st.composite
def wind_dict(draw: Any) -> dict[str, Any]:
    """``WindConfig`` (soft caps: speeds <= 100 m/s, z0 <= 10 m, z_ref <= 1e4 m, gust_tau <= 1e3 s)."""
    out: dict[str, Any] = {}
    maybe(draw, out, "mean_speed", real(0.0, 100.0, typical=(0.0, 10.0)))
    maybe(draw, out, "direction", optional(real(-1e6, 1e6, typical=(-3.2, 3.2), edges=(0.0,))))
    maybe(draw, out, "randomise_speed", optional(pair(0.0, 100.0, (0.0, 10.0))))
    maybe(draw, out, "profile", st.sampled_from(["log", "power", "uniform"]))
    maybe(draw, out, "z0", positive(10.0, (0.001, 1.0)))
    z0 = out.get("z0", 0.03)
    if z0 >= 10.0 or draw(st.sampled_from([False, True, True])):  # z_ref must exceed z0 (default z_ref 10)
        out["z_ref"] = max(z0 + draw(positive(1e4, (1.0, 50.0))), math.nextafter(z0, math.inf))
    maybe(draw, out, "gust_sigma_frac", real(0.0, 2.0, typical=(0.0, 0.5)))
    maybe(draw, out, "gust_tau", positive(1e3, (0.1, 10.0)))
    return out


@st.composite
def scatter_dict(draw: Any) -> dict[str, Any]:
    """``ScatterConfig``: sigmas >= 0 (soft cap 100), gust_drift a bool."""
    out: dict[str, Any] = {}
    for name in ("sigma_gnss", "sigma_timing", "sigma_bounce"):
        maybe(draw, out, name, real(0.0, 100.0, typical=(0.0, 2.0), edges=(1e-300,)))
    maybe(draw, out, "gust_drift", st.booleans())
    return out


@st.composite
def wsn_dict(draw: Any, n_zones: int, map_size: tuple[float, float]) -> dict[str, Any]:
    """``WsnConfig`` (soft caps: radii <= 1e3 m; coverage_resolution in [0.5, 10] m for speed and memory)."""
    out: dict[str, Any] = {}
    maybe(draw, out, "r_s", positive(1e3, (1.0, 30.0)))
    maybe(draw, out, "r_c", positive(1e3, (5.0, 60.0)))
    maybe(draw, out, "coverage_resolution", real(0.5, 10.0, typical=(1.0, 4.0)))
    maybe(draw, out, "k", st.integers(1, 5))
    maybe(draw, out, "coverage_lifetime_threshold", real(0.0, 1.0, lo_open=True, typical=(0.5, 1.0)))
    maybe(draw, out, "knn_k", st.integers(1, 10))
    maybe(draw, out, "fiedler_max_n", st.one_of(st.sampled_from([0, 1, 300]), st.integers(0, 300)))
    if draw(MOSTLY):
        weight = positive(10.0, (0.1, 5.0))
        out["zone_weights"] = None if draw(st.booleans()) else tuple(draw(weight) for _ in range(n_zones))
    if draw(MOSTLY):
        w, h = map_size
        points = [(within(draw, 0.0, w), within(draw, 0.0, h)) for _ in range(draw(st.integers(1, 2)))]
        out["sink"] = draw(st.sampled_from(["centroid", points[0], tuple(points)]))
    return out


SIDE = real(1e-3, 1e5, typical=(60.0, 400.0), edges=(1.0, 30.0))
"""A zone map side: (0, 1e5] (at least 1 mm: a zone inside needs a radius > 0)."""


@st.composite
def zones_dict(draw: Any) -> dict[str, Any]:
    """A zone file as a dict (``docs/zones.md``): map sides in (0, 1e5], 1-3 zones fully inside the map.

    Kept small for speed: zone radii <= 300 m (coverage lattices grow with the area), 1-12 sensors per zone.
    """
    w = draw(SIDE)
    h = w if draw(st.booleans()) else draw(SIDE)
    zones = []
    for i in range(draw(st.integers(1, 3))):
        r_max = min(w, h, 600.0) / 2.0
        radius = r_max * draw(real(0.0, 1.0, lo_open=True, typical=(0.01, 1.0), edges=(1e-6,)))
        zone: dict[str, Any] = {
            "centre": [within(draw, radius, w - radius), within(draw, radius, h - radius)],
            "radius": radius,
            "n_sensors": draw(ints(1, 12)),
        }
        maybe(draw, zone, "profile", st.sampled_from(["gauss", "uniform", "power", "linear"]))
        maybe(draw, zone, "alpha", real(0.0, 2.0 - 1e-9, typical=(0.0, 1.5), edges=(1.0, 1.999)))
        if draw(MOSTLY):  # radius / 1000 .. 1000 x radius, or None (radius / 2)
            factor = draw(optional(real(1e-3, 1e3, typical=(0.1, 1.0), edges=(0.5,))))
            zone["sigma"] = None if factor is None else min(1e3 * radius, max(radius / 1e3, radius * factor))
        maybe(draw, zone, "floor", real(0.0, 1.0 - 1e-9, typical=(0.0, 0.3), edges=(0.5, 0.999)))
        maybe(draw, zone, "weight", positive(100.0, (0.5, 2.0)))
        maybe(draw, zone, "altitude", optional(positive(120.0, (5.0, 40.0))))
        if draw(st.booleans()):
            zone["name"] = f"z{i}"
        zones.append(zone)
    out: dict[str, Any] = {"map_size": [w, h], "zones": zones}
    if draw(st.booleans()):
        out["version"] = 1
    if draw(MOSTLY):
        corner = draw(st.sampled_from(["none", "random", "origin", "far"]))
        out["base"] = {"none": None, "origin": [0.0, 0.0], "far": [w, h]}.get(
            corner, [within(draw, 0.0, w), within(draw, 0.0, h)]
        )
    return out


# ------------------------------------------------------------------------------------ scenario strategies
BODY, SENSING, REWARD, COMMS = body_dict(), sensing_dict(), reward_dict(), comms_dict()
GNSS, WIND, SCATTER = gnss_dict(), wind_dict(), scatter_dict()
MAX_STEPS = st.one_of(st.integers(5, 40), st.sampled_from([1, 2]))
DT = real(1e-3, 10.0, typical=(0.02, 0.5))
N_AGENTS = ints(1, 12)


def shared(draw: Any, *, comms: str = "optional") -> dict[str, Any]:
    """The ``ScenarioConfig`` fields (``n_agents`` left to the caller); ``max_steps`` always set (<= 40).

    Args:
        comms: ``"optional"`` (None, absent or a dict) or ``"dict"`` (relay: never None).
    """
    out: dict[str, Any] = {"max_steps": draw(MAX_STEPS)}
    maybe(draw, out, "body", BODY)
    maybe(draw, out, "sensing", SENSING)
    maybe(draw, out, "action_mode", st.sampled_from(["velocity", "primitive"]))
    maybe(draw, out, "physics", st.sampled_from(["kinematic", "pymunk"]))
    maybe(draw, out, "collisions", st.booleans())
    maybe(draw, out, "dt", DT)
    maybe(draw, out, "reward", REWARD)
    maybe(draw, out, "comms", COMMS if comms == "dict" else optional(COMMS))
    return out


def capped_density(draw: Any, area: float) -> float:
    """Obstacle density in [0, 0.01], capped at about 3,000 obstacles per world (speed)."""
    return min(0.01, 3000.0 / max(area, 1.0)) * draw(real(0.0, 1.0, typical=(0.0, 0.2)))


GAP_EXTRA = real(0.0, 1e3, typical=(0.0, 30.0), edges=(15.0,))
MAP_SIZE = {
    "kinematic": optional(real(10.0, 1e5, typical=(10.0, 300.0))),
    "pymunk": optional(real(10.0, 2.5e4, typical=(10.0, 300.0))),
}


@st.composite
def navigation_config(draw: Any) -> dict[str, Any]:
    """``NavigationConfig`` (``agentsim_env/scenarios/navigation.py``)."""
    out = shared(draw)
    n = out["n_agents"] = draw(N_AGENTS)
    maybe(draw, out, "n_groups", optional(ints(1, n)))
    maybe(draw, out, "map_size", MAP_SIZE[out.get("physics", "kinematic")])
    maybe(draw, out, "area_per_agent", real(10.0, 1e6, typical=(10.0, 2000.0)))
    side = out.get("map_size") or max(60.0, math.sqrt(n * out.get("area_per_agent", 150.0)))
    if draw(st.sampled_from([False, True, True])):
        out["obstacle_density"] = capped_density(draw, side * side)
    elif side * side / 600.0 > 3000.0:  # the default density would put too many obstacles on a large map
        out["obstacle_density"] = 0.0
    maybe(draw, out, "obstacle_size", pair(0.01, 100.0, (0.01, 5.0)))
    maybe(draw, out, "obstacle_height", pair(0.01, 1e4, (0.01, 30.0)))
    maybe(draw, out, "goal_radius", positive(1e4, (0.5, 5.0)))
    maybe(draw, out, "arrival_bonus", real(0.0, 1e6, typical=(0.0, 20.0)))
    maybe(draw, out, "gnss", optional(GNSS))
    return out


@st.composite
def relay_config(draw: Any) -> dict[str, Any]:
    """``RelayConfig`` (``relay_config.py``)."""
    out = shared(draw, comms="dict")
    g = draw(st.integers(1, 4))
    size = draw(ints(2, 12 // g))
    out["n_groups"] = g
    how = draw(st.sampled_from(["group_size", "n_agents", "both", "neither"]))
    if how in ("group_size", "both"):
        out["group_size"] = size
    if how in ("n_agents", "both"):
        out["n_agents"] = g * size
    if how == "neither" and g > 3:
        out["n_groups"] = 3  # default group_size 4: 12 agents at most
    maybe(draw, out, "lateral_spread", real(0.0, 1e3, typical=(0.0, 10.0)))
    least = 2.0 * out.get("lateral_spread", 8.0) + 4.0  # corridor_width >= 2 x lateral_spread + 4
    if draw(st.sampled_from([False, True, True])):
        out["corridor_width"] = min(1e4, least + draw(real(0.0, 1e4, typical=(0.0, 40.0))))
    elif least > 40.0:
        out["corridor_width"] = least
    if draw(MOSTLY):  # 2 x body.radius + 0.5 <= low <= high <= 1e3
        least_gap = 2.0 * out.get("body", {}).get("radius", 0.5) + 0.5
        low = min(1e3, least_gap + draw(GAP_EXTRA))
        out["gap"] = (low, low) if draw(st.booleans()) else (low, min(1e3, low + draw(GAP_EXTRA)))
    maybe(draw, out, "target_offset", pair(0.0, 1e3, (0.0, 15.0)))
    width = out.get("corridor_width", 40.0)
    n = out.get("n_agents") or out["n_groups"] * (out.get("group_size") or 4)
    length = (n - 1) * out.get("gap", (12.0, 22.0))[1] + 2 * (out.get("target_offset", (4.0, 10.0))[1] + 5)
    if draw(st.sampled_from([False, True, True])):
        out["obstacle_density"] = capped_density(draw, width * length)
    elif width * length / 1000.0 > 3000.0:
        out["obstacle_density"] = 0.0
    maybe(draw, out, "obstacle_size", pair(0.01, 100.0, (0.01, 4.0)))
    maybe(draw, out, "obstacle_height", pair(0.01, 1e4, (0.01, 25.0)))
    maybe(draw, out, "arrival_radius", positive(1e3, (0.5, 5.0)))
    maybe(draw, out, "arrival_bonus", real(0.0, 1e6, typical=(0.0, 20.0)))
    return out


@st.composite
def rendezvous_config(draw: Any) -> dict[str, Any]:
    """``RendezvousConfig`` (``rendezvous.py``: no documented ranges for side, radius and bonus; here a side of
    10..300 m, a radius in (0, 50] m and a bonus in [0, 1e3])."""
    out = shared(draw)
    out["n_agents"] = draw(N_AGENTS)
    maybe(draw, out, "side", real(10.0, 300.0, typical=(20.0, 120.0)))
    maybe(draw, out, "radius", positive(50.0, (1.0, 10.0)))
    maybe(draw, out, "bonus", real(0.0, 1e3, typical=(0.0, 20.0)))
    return out


@st.composite
def uav_release_config(draw: Any) -> dict[str, Any]:
    """``UavReleaseConfig`` (``uav_config.py``): random zones; payload x UAVs covers the sensors most times."""
    zones = draw(zones_dict())
    out = shared(draw)
    need = sum(z["n_sensors"] for z in zones["zones"])
    n = draw(ints(1, 8))
    out["zones"] = zones
    out["n_uavs" if draw(st.booleans()) else "n_agents"] = n
    out["payload"] = max(1, -(-need // n) + draw(st.sampled_from([0, 0, 0, 1, 2, 3, -1])))  # -1: may be short
    maybe(draw, out, "sensor_mass", real(1e-4, 100.0, typical=(0.01, 0.5)))
    maybe(draw, out, "sensor_cd", real(0.01, 10.0, typical=(0.3, 2.0)))
    maybe(draw, out, "sensor_area", real(1e-6, 10.0, typical=(1e-4, 0.05)))
    maybe(draw, out, "battery_j", real(1.0, 1e9, typical=(1e3, 5e5)))
    maybe(draw, out, "target_scale", real(1e-3, 1e6, typical=(5.0, 100.0)))
    maybe(draw, out, "grid_cells", st.one_of(st.sampled_from([1, 64]), st.integers(1, 16)))
    maybe(draw, out, "grid_extent", real(1.0, 1e5, typical=(10.0, 150.0)))
    for name in ("w_coverage", "w_fidelity", "w_energy", "w_miss", "w_out", "w_lcc", "w_lifetime"):
        maybe(draw, out, name, real(0.0, 1e6, typical=(0.0, 10.0)))
    maybe(draw, out, "wind", WIND)
    maybe(draw, out, "scatter", SCATTER)
    maybe(draw, out, "wsn", wsn_dict(len(zones["zones"]), tuple(zones["map_size"])))
    return out


STRATEGIES: dict[str, st.SearchStrategy[dict[str, Any]]] = {
    "navigation": navigation_config(),
    "relay": relay_config(),
    "rendezvous": rendezvous_config(),
    "uav_release": uav_release_config(),
}
"""Scenario name -> config strategy. Every registered scenario needs one (the fuzz test fails without)."""


# ----------------------------------------------------------------------------------------------- checks
@functools.cache
def check_finite_supported() -> bool:
    """Whether ``agentsim_env.make`` accepts the ``check_finite`` keyword (being added to the env)."""
    try:
        env = agentsim_env.make("rendezvous", n_agents=1, max_steps=1, check_finite=True)
    except (TypeError, ValueError) as exc:
        if "check_finite" in str(exc):
            return False
        raise
    env.close()
    return True


@functools.cache
def batched_check_finite_supported() -> bool:
    """Whether ``BatchedEnv`` accepts the ``check_finite`` keyword."""
    from agentsim_env.env.vector import BatchedEnv

    return "check_finite" in inspect.signature(BatchedEnv.__init__).parameters


def check_box(box: spaces.Box, x: Any, where: str) -> None:
    """``x`` is a finite array of the box's shape and dtype inside its bounds (the message says where not)."""
    assert isinstance(x, np.ndarray), f"{where}: expected an ndarray, got {type(x).__name__}"
    assert x.shape == box.shape, f"{where}: shape {x.shape}, space {box.shape}"
    assert x.dtype == box.dtype, f"{where}: dtype {x.dtype}, space {box.dtype}"
    bad = ~np.isfinite(x)
    assert not bad.any(), f"{where}: non-finite values at {np.argwhere(bad)[:4].tolist()}: {x[bad][:4]}"
    out = (x < box.low) | (x > box.high)
    if out.any():
        idx = np.argwhere(out)[:4]
        vals = [
            (i.tolist(), float(x[tuple(i)]), float(box.low[tuple(i)]), float(box.high[tuple(i)])) for i in idx
        ]
        raise AssertionError(f"{where}: outside the space (index, value, low, high): {vals}")


def check_obs(space: spaces.Space, obs: Any, where: str) -> None:
    """An observation is finite and inside its space (``space.contains`` and a precise diagnosis)."""
    if isinstance(space, spaces.Dict):
        assert isinstance(obs, dict), f"{where}: expected a dict, got {type(obs).__name__}"
        assert set(obs) == set(space.spaces), f"{where}: parts {sorted(obs)}, space {sorted(space.spaces)}"
        for k, sub in space.spaces.items():
            check_box(sub, obs[k], f"{where}[{k!r}]")
    else:
        check_box(space, obs, where)
    assert space.contains(obs), f"{where}: space.contains() is False"


def check_number(x: Any, where: str) -> None:
    """A finite Python or numpy real number (not a bool)."""
    assert isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_)), (
        f"{where}: expected a number, got {type(x).__name__} {x!r}"
    )
    assert math.isfinite(x), f"{where}: non-finite {x!r}"


def random_part(rng: np.random.Generator, box: spaces.Box) -> np.ndarray:
    """A random point of an action box: uniform, with about 1 in 10 values at -1, 0 or 1 (box in [-1, 1])."""
    x = rng.uniform(box.low, box.high)
    edge = rng.random(box.shape) < 0.1
    x[edge] = rng.choice([-1.0, 0.0, 1.0], int(edge.sum()))
    return np.clip(x, box.low, box.high).astype(box.dtype)


def random_action(rng: np.random.Generator, space: spaces.Space) -> Any:
    """A random action of a Dict-of-Box or Box action space."""
    if isinstance(space, spaces.Dict):
        return {k: random_part(rng, sub) for k, sub in space.spaces.items()}
    return random_part(rng, space)


def random_payload(rng: np.random.Generator, d: int) -> np.ndarray:
    """``d`` finite floats (``send_message`` documents no range): mostly in [-1, 1], sometimes large."""
    scale = rng.choice([1.0, 1.0, 1.0, 1e3, 1e5, 1e30])
    return rng.uniform(-1.0, 1.0, d) * scale


# ------------------------------------------------------------------------------------------------ the runs
def run_parallel(env: Any, seed: int, rng: np.random.Generator, extras: bool, state: bool) -> int:
    """One episode of the ParallelEnv with every check; returns the steps taken."""
    obs, infos = env.reset(seed=seed)
    assert set(obs) == set(env.agents) == set(infos), "reset: observations, infos and agents differ"
    for a, o in obs.items():
        check_obs(env.observation_space(a), o, f"reset obs of {a}")
        for k, v in infos[a].items():
            check_number(v, f"reset info {k!r} of {a}")
    comms = env.world.comms is not None
    max_steps = env.scenario.max_steps
    steps = 0
    while env.agents and steps < max_steps:
        live = list(env.agents)
        actions = {a: random_action(rng, env.action_space(a)) for a in live}
        if comms and extras:
            code_api(env, rng, live)
        obs, rewards, terms, truncs, infos = env.step(actions)
        steps += 1
        where = f"step {steps}"
        assert set(obs) == set(rewards) == set(terms) == set(truncs) == set(infos) == set(live), (
            f"{where}: the returned dicts do not hold exactly the agents that acted"
        )
        for a in live:
            check_obs(env.observation_space(a), obs[a], f"{where}: obs of {a}")
            check_number(rewards[a], f"{where}: reward of {a}")
            assert isinstance(terms[a], bool) and isinstance(truncs[a], bool), f"{where}: flags of {a}"
            for k, v in infos[a].items():
                check_number(v, f"{where}: info {k!r} of {a}")
        assert set(env.agents) == {a for a in live if not (terms[a] or truncs[a])}, f"{where}: live agents"
        if state:
            s = env.state()
            check_box(env.state_space, np.asarray(s), f"{where}: state()")
    assert not env.agents, f"agents {env.agents[:3]} still live after max_steps = {max_steps} steps"
    return steps


def code_api(env: Any, rng: np.random.Generator, live: list[str]) -> None:
    """``send_message`` (unicast and group) and ``assign_group`` from code, on live agents."""
    d = env.world.comms.cfg.payload_dim
    for _ in range(int(rng.integers(0, 3))):
        sender = live[int(rng.integers(len(live)))]
        groups = np.unique(env.world.state.group[env.world.state.group >= 0]).tolist()
        if groups and rng.random() < 0.5:
            env.send_message(sender, random_payload(rng, d), group=int(rng.choice(groups)))
        else:
            env.send_message(sender, random_payload(rng, d), to=live[int(rng.integers(len(live)))])
    if rng.random() < 0.3:  # group ids run from -1 (none) to n_agents - 1
        env.assign_group(live[int(rng.integers(len(live)))], int(rng.integers(-1, env.scenario.n_agents)))


def run_batched(env: Any, seed: int, rng: np.random.Generator) -> int:
    """``max_steps + 3`` steps of the array API (across an automatic reset) with every check; returns steps."""
    from agentsim_env.env.spaces import observation_space_for

    b, n = env.n_worlds, env.n_agents
    box = observation_space_for(env.scenario.obs_parts(), "flat")
    obs = env.reset(seed=seed)
    assert obs.shape == (b, n, env.obs_dim) and obs.dtype == np.float32
    for w in range(b):
        for i in range(n):
            check_box(box, obs[w, i], f"reset obs of world {w} agent {i}")
    steps = env.scenario.max_steps + 3
    for t in range(1, steps + 1):
        actions = rng.uniform(-1.0, 1.0, (b, n, env.act_dim))
        alive = env.alive.copy()
        res = env.step(actions)
        for w in range(b):
            for i in range(n):
                if alive[w, i] or res.reset_worlds[w]:  # dead agents of running worlds read zeros
                    check_box(box, res.obs[w, i], f"step {t}: obs of world {w} agent {i}")
                if res.reset_worlds[w]:
                    check_box(box, res.final_obs[w, i], f"step {t}: final_obs of world {w} agent {i}")
        assert np.isfinite(res.rewards).all(), f"step {t}: non-finite rewards {res.rewards}"
        for k, v in res.info.items():
            assert v.shape == (b, n) and np.isfinite(v).all(), f"step {t}: info {k!r} {v}"
    return steps


PROBE_FRAMES = frozenset({"reset_worlds", "run_step", "reset_world", "score", "observe", "observation"})
"""Functions of a probe episode: construction measures the spaces on one (``Scenario.spec``)."""


def build_or_reject(name: str, make: Callable[[], Any]) -> Any:
    """Build the env; a ``ValueError`` of the config checks rejects the example (counted), anything else fails.

    Construction also runs a probe episode (a reset and a step, to measure the spaces): a ``ValueError`` raised
    inside it is a failure of that episode, not a rejected config, and fails the example.
    """
    try:
        return make()
    except ValueError as exc:
        tb, frames = exc.__traceback__, set()
        while tb is not None:
            frames.add(tb.tb_frame.f_code.co_name)
            tb = tb.tb_next
        if frames & PROBE_FRAMES:
            raise
        _STATS[name]["rejected"] += 1
        reason = _reason(exc)
        _REJECTIONS[name][reason] += 1
        event(f"rejected at construction: {reason}")
        assume(False)


@pytest.fixture
def _record(request: pytest.FixtureRequest, record_property: Callable[[str, Any], None]) -> Any:
    name = request.node.callspec.params["name"]
    before = Counter(_STATS[name])
    yield
    delta = {k: v - before.get(k, 0) for k, v in _STATS[name].items()}
    record_property("fuzz", delta)


# ------------------------------------------------------------------------------------------------- tests
def test_every_registered_scenario_has_a_strategy() -> None:
    missing = sorted(set(agentsim_env.list_scenarios()) - set(STRATEGIES))
    assert not missing, f"scenarios without a fuzz strategy in tests/test_fuzz.py: {missing}; add one"


@pytest.mark.parametrize("name", agentsim_env.list_scenarios())
@settings(settings.get_profile(PROFILE))
@given(data=st.data())
def test_fuzz_scenario(name: str, data: st.DataObject, _record: None) -> None:
    if name not in STRATEGIES:
        pytest.fail(f"scenario {name!r} has no fuzz strategy in tests/test_fuzz.py STRATEGIES; add one")
    config = data.draw(STRATEGIES[name], label="config")
    seed = data.draw(st.integers(0, 2**32 - 1), label="seed")
    action_seed = data.draw(st.integers(0, 2**32 - 1), label="action_seed")
    api = data.draw(st.sampled_from(["parallel", "parallel", "parallel", "batched"]), label="api")
    rng = np.random.default_rng(action_seed)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        if api == "batched":
            n_worlds = data.draw(st.integers(1, 3), label="n_worlds")
            from agentsim_env.env.vector import BatchedEnv

            kw = dict(config)
            if batched_check_finite_supported() and data.draw(st.booleans(), label="check_finite"):
                kw["check_finite"] = True
            note(f"BatchedEnv({name!r}, {n_worlds}, **{kw!r})")
            benv = build_or_reject(name, lambda: BatchedEnv(name, n_worlds, **kw))
            _STATS[name]["built"] += 1
            _STATS[name]["check_finite"] += "check_finite" in kw
            _STATS[name]["batched"] += 1
            event("built: BatchedEnv")
            _STATS[name]["steps"] += run_batched(benv, seed, rng)
            return
        env_kw = {
            "obs_format": data.draw(st.sampled_from(["dict", "flat"]), label="obs_format"),
            "action_format": data.draw(st.sampled_from(["dict", "flat"]), label="action_format"),
        }
        if check_finite_supported() and data.draw(st.booleans(), label="check_finite"):
            env_kw["check_finite"] = True
        extras = data.draw(st.booleans(), label="send_message/assign_group")
        state = data.draw(st.booleans(), label="check state()")
        note(f"agentsim_env.make({name!r}, **{ {**config, **env_kw}!r})")
        env = build_or_reject(name, lambda: agentsim_env.make(name, **config, **env_kw))
        _STATS[name]["built"] += 1
        _STATS[name]["check_finite"] += "check_finite" in env_kw
        event("built: ParallelEnv")
        try:
            _STATS[name]["steps"] += run_parallel(env, seed, rng, extras, state)
            if data.draw(st.booleans(), label="second episode"):  # a reset after a finished episode
                _STATS[name]["steps"] += run_parallel(env, seed + 1, rng, extras, state)
        finally:
            env.close()
