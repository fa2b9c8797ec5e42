"""Config strategies of the fuzz test (``tests/test_fuzz.py``): one per registered scenario, in ``STRATEGIES``.

Each draws a config inside the ranges the config docstrings and validators document, with the range endpoints and
other edge values drawn often; sizes are kept small for speed (see ``tests/test_fuzz.py``'s docstring).
"""

from __future__ import annotations

import functools
import math
from typing import Any

from hypothesis import strategies as st


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


def positive(hi: float, typical: tuple[float, float], edges: tuple[float, ...] = ()) -> st.SearchStrategy[float]:
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
