"""The bad-input table: every input that once crashed, hung, allocated without bound or misbehaved silently.

Each row gives the input, the exception type and the words its message must contain; after each row the env
(or a fresh one of the same scenario) is used normally, so a bad input never leaves anything broken behind.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.env.vector import BatchedEnv

ZONE = {"centre": [100, 100], "radius": 30, "n_sensors": 10}


def zones(**zone: Any) -> dict[str, Any]:
    """A one-zone set on a 200 m map (fields of the zone overridden by ``zone``)."""
    return {"map_size": [200, 200], "zones": [{**ZONE, **zone}]}


def env(name: str = "navigation", **config: Any) -> Any:
    """A reset env of ``name`` (small)."""
    e = agentsim_env.make(name, **config)
    e.reset(seed=0)
    return e


def use(e: Any, steps: int = 3) -> None:
    """Use an env normally: reset, random steps; every value finite (the tests run with check_finite on)."""
    e.reset(seed=1)
    for _ in range(steps):
        if not e.agents:
            break
        e.step({a: e.action_space(a).sample() for a in e.agents})


def motion(e: Any, value: Any) -> dict[str, Any]:
    """Valid actions of every live agent with ``value`` as their ``motion`` part."""
    return {a: {**e.action_space(a).sample(), "motion": value} for a in e.agents}


# (id, call, exception, words the message must contain, scenario used afterwards)
Case = tuple[str, Callable[[], Any], type[BaseException], tuple[str, ...]]

CONSTRUCTION: list[Case] = [
    # 1. unbounded sizes
    (
        "map_size 1e6",
        lambda: agentsim_env.make("navigation", map_size=1e6),
        ValueError,
        ("map_size", "100000"),
    ),
    ("map_size 1e12", lambda: agentsim_env.make("navigation", map_size=1e12), ValueError, ("map_size", "<=")),
    (
        "n_agents 1e7",
        lambda: agentsim_env.make("navigation", n_agents=10**7),
        ValueError,
        ("n_agents", "1000000"),
    ),
    ("n_worlds 1e7", lambda: BatchedEnv("navigation", 10**7), ValueError, ("n_worlds", "1000000")),
    (
        "map grows too big",
        lambda: agentsim_env.make("navigation", n_agents=10**6, area_per_agent=1e6),
        ValueError,
        ("area_per_agent", "map_size", "limit"),
    ),
    (
        "too many obstacles",
        lambda: agentsim_env.make("navigation", map_size=1e5, obstacle_density=0.01),
        ValueError,
        ("obstacle_density", "obstacles per world"),
    ),
    (
        "pymunk map",
        lambda: agentsim_env.make("navigation", map_size=5e4, physics="pymunk"),
        ValueError,
        ("map_size", "20000"),
    ),
    (
        "relay corridor",
        lambda: agentsim_env.make("relay", n_groups=64, group_size=256, gap=(900, 1000)),
        ValueError,
        ("corridor", "gap", "limit"),
    ),
    (
        "uav payload",
        lambda: agentsim_env.make("uav_release", payload=10**9),
        ValueError,
        ("payload", "100000"),
    ),
    (
        "sensing rings",
        lambda: agentsim_env.make("navigation", sensing={"elevations_deg": [0.0] * 65}),
        ValueError,
        ("sensing.elevations_deg", "1..64"),
    ),
    # 2. accepted configs that crashed: now the value works or is rejected at construction
    (
        "crowded map",
        lambda: agentsim_env.make("navigation", n_agents=30, map_size=20),
        ValueError,
        ("n_agents", "cannot place 30", "map_size"),
    ),
    # 3. silent NaN
    (
        "altitude flat",
        lambda: agentsim_env.make("navigation", body={"altitude": (5, 5)}),
        ValueError,
        ("body.altitude",),
    ),
    (
        "altitude thin",
        lambda: agentsim_env.make("navigation", body={"altitude": (5, 5.05)}),
        ValueError,
        ("body.altitude", "0.1"),
    ),
    (
        "sigma 1e-3",
        lambda: agentsim_env.make("uav_release", zones=zones(sigma=0.001)),
        ValueError,
        ("zones[0]", "sigma", ">= 0.03"),
    ),
    (
        "sigma 1e-300",
        lambda: agentsim_env.make("uav_release", zones=zones(sigma=1e-300)),
        ValueError,
        ("zones[0]", "sigma"),
    ),
    (
        "sigma huge",
        lambda: agentsim_env.make("uav_release", zones=zones(sigma=1e300)),
        ValueError,
        ("zones[0]", "sigma", "<="),
    ),
    # 4. wrong behaviour with no error: booleans are booleans
    (
        "collisions 'False'",
        lambda: agentsim_env.make("navigation", collisions="False"),
        ValueError,
        ("collisions", "True or False"),
    ),
    (
        "collisions 0",
        lambda: agentsim_env.make("navigation", collisions=0),
        ValueError,
        ("collisions", "bool"),
    ),
    (
        "overlay_full 'yes'",
        lambda: agentsim_env.make("navigation", comms={"overlay_full": "yes"}),
        ValueError,
        ("comms.overlay_full", "bool"),
    ),
    (
        "n_agents 2.0",
        lambda: agentsim_env.make("navigation", n_agents=2.0),
        ValueError,
        ("n_agents", "integer"),
    ),
    ("dt '0.1'", lambda: agentsim_env.make("navigation", dt="0.1"), ValueError, ("dt", "number")),
    (
        "check_finite 1",
        lambda: agentsim_env.make("navigation", check_finite=1),
        ValueError,
        ("check_finite",),
    ),
    # 7. errors that name what is wrong
    (
        "altitude 5",
        lambda: agentsim_env.make("navigation", body={"altitude": 5}),
        ValueError,
        ("body.altitude",),
    ),
    (
        "altitude triple",
        lambda: agentsim_env.make("navigation", body={"altitude": (1, 2, 3)}),
        ValueError,
        ("body.altitude", "pair"),
    ),
    (
        "zones ''",
        lambda: agentsim_env.make("uav_release", zones=""),
        ValueError,
        ("zones", "empty", "JSON path"),
    ),
    ("zones 42", lambda: agentsim_env.make("uav_release", zones=42), ValueError, ("zones", "int", "dict")),
    (
        "zones list",
        lambda: agentsim_env.make("uav_release", zones=[ZONE]),
        ValueError,
        ("zones", "list", "map_size"),
    ),
    (
        "zones missing file",
        lambda: agentsim_env.make("uav_release", zones="/nonexistent/z.json"),
        ValueError,
        ("zones", "/nonexistent/z.json"),
    ),
    ("BatchedEnv n_worlds 0", lambda: BatchedEnv("navigation", 0), ValueError, ("n_worlds", ">= 1")),
]


@pytest.mark.parametrize("case", CONSTRUCTION, ids=[c[0] for c in CONSTRUCTION])
def test_bad_config_is_a_clear_error(case: Case) -> None:
    _, call, exc, words = case
    with pytest.raises(exc) as info:
        call()
    msg = str(info.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    assert len(msg) < 600, f"message of {len(msg)} characters"
    use(agentsim_env.make("navigation", n_agents=3))  # nothing global was left broken


@pytest.mark.parametrize("name", ["deep", "latin1", "many", "huge", "folder", "not json"])
def test_bad_zone_files(tmp_path: Path, name: str) -> None:
    path = tmp_path / "zones.json"
    words: tuple[str, ...]
    if name == "deep":
        path.write_text("[" * 100_000 + "]" * 100_000)
        words = ("nested too deeply",)
    elif name == "latin1":
        path.write_bytes('{"map_size": [200, 200], "description": "caf\xe9", "zones": []}'.encode("latin-1"))
        words = ("not UTF-8", "0xe9")
    elif name == "many":
        many = [{"centre": [3 * i + 2, 5], "radius": 1, "n_sensors": 1} for i in range(100_000)]
        path.write_text(json.dumps({"map_size": [100_000, 10], "zones": many}))
        words = ("100,000 zones", "1,000")
    elif name == "huge":
        path.write_text(" " * (17 << 20) + "{}")
        words = ("bytes", "at most")
    elif name == "folder":
        path = tmp_path
        words = ("folder",)
    else:
        path.write_text("{not json")
        words = ("not valid JSON",)
    with pytest.raises(ValueError) as info:
        agentsim_env.make("uav_release", zones=str(path))
    msg = str(info.value)
    for w in words:
        assert w in msg, f"{w!r} not in {msg!r}"
    assert len(msg) < 600


def test_memory_estimate_is_checked_before_allocating(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AGENTSIM_MEMORY_LIMIT_GB", "0.01")
    with pytest.raises(ValueError) as info:
        agentsim_env.make("navigation", n_agents=10_000)
    for w in ("n_agents=10000", "n_worlds=1", "MiB", "limit", "AGENTSIM_MEMORY_LIMIT_GB"):
        assert w in str(info.value)
    with pytest.raises(ValueError, match="n_worlds=2000"):
        BatchedEnv("navigation", 2000, n_agents=8)
    monkeypatch.setenv("AGENTSIM_MEMORY_LIMIT_GB", "lots")
    with pytest.raises(ValueError, match="AGENTSIM_MEMORY_LIMIT_GB must be a positive number"):
        agentsim_env.make("navigation")
    monkeypatch.delenv("AGENTSIM_MEMORY_LIMIT_GB")
    use(agentsim_env.make("navigation", n_agents=3))


def test_spaces_are_built_once() -> None:
    e = agentsim_env.make("navigation", n_agents=50)
    assert e.observation_space("agent_0") is e.observation_space("agent_49")
    assert e.action_space("agent_0") is e.action_space("agent_49")


def test_numpy_scalars_are_numbers() -> None:
    e = agentsim_env.make("navigation", n_agents=np.int64(3), dt=np.float32(0.1), body={"radius": np.float64(0.4)})
    c = e.scenario.config
    assert type(c.n_agents) is int and type(c.dt) is float and type(c.body.radius) is float
    use(e)


# ---------------------------------------------------------------- 2. configs that crashed inside a run
@pytest.mark.parametrize("payload_dim", [0, 1, 2])
def test_collision_message_with_narrow_payload(payload_dim: int) -> None:
    e = env(n_agents=3, comms={"payload_dim": payload_dim})
    st = e.world.state
    st.pos[0] = st.pos[1]  # agent_0 inside agent_1: both collide in the next step
    _, rew, term, _, infos = e.step({a: e.action_space(a).sample() for a in e.agents})
    assert term["agent_0"] and term["agent_1"] and infos["agent_0"]["collided"] == 1
    assert np.isfinite(rew["agent_0"])
    inbox = e.world.comms.bus.inbox
    assert (inbox.sender[0] == -1).any()  # the environment's collision message reached agent_0
    if payload_dim:
        assert inbox.payload[0][inbox.sender[0] == -1][0][0] in (1, 2)
    use(e)


@pytest.mark.parametrize(
    "config",
    [
        {"gap": (15.0, 15.0)},
        {"corridor_width": 20.0, "lateral_spread": 8.0},
        {"lateral_spread": 0.0, "corridor_width": 4.0},
    ],
)
def test_relay_edge_configs_reset_and_run(config: dict[str, Any]) -> None:
    e = agentsim_env.make("relay", **config)
    for seed in range(5):
        e.reset(seed=seed)
        e.step({a: e.action_space(a).sample() for a in e.agents})


def test_narrowest_gaussian_zone_is_finite() -> None:
    e = agentsim_env.make("uav_release", n_agents=1, zones=zones(radius=1, sigma=0.001), max_steps=20)
    use(e, steps=20)  # check_finite is on in the tests: any NaN reward or observation raises
    assert np.isfinite(e.world.task.tracker.phi).all()


# ---------------------------------------------------------------- 3. the check_finite switch
def test_check_finite_names_part_agent_and_step() -> None:
    e = agentsim_env.make("navigation", n_agents=3, check_finite=True)
    e.reset(seed=0)
    e.world.state.pos[2, 0] = np.nan
    with pytest.raises(FloatingPointError, match=r"observation part 'self' of agent 'agent_2' .*step 1"):
        e.step({a: e.action_space(a).sample() for a in e.agents})
    b = BatchedEnv("navigation", 2, n_agents=3, check_finite=True)
    b.reset(seed=0)
    b.world.state.pos[4, 1] = np.nan
    with pytest.raises(FloatingPointError, match=r"agent 'agent_1' \(world 1\)"):
        b.step(np.zeros((2, 3, b.act_dim)))
    off = agentsim_env.make("navigation", n_agents=3, check_finite=False)
    off.reset(seed=0)
    off.world.state.pos[2, 0] = np.nan
    off.step({a: off.action_space(a).sample() for a in off.agents})  # off: no check


# ---------------------------------------------------------------- 5. reset is a clean start
def _trajectory(e: Any, steps: int) -> list[Any]:
    out = []
    zero = {a: {k: np.zeros(sp.shape) for k, sp in e.action_space(a).items()} for a in e.agents}
    for _ in range(steps):
        if not e.agents:
            break
        obs, rew, _, _, _ = e.step({a: zero[a] for a in e.agents})
        out.append((obs, rew))
    return out


def _same(a: list[Any], b: list[Any]) -> bool:
    if len(a) != len(b):
        return False
    for (oa, ra), (ob, rb) in zip(a, b):
        if ra != rb or oa.keys() != ob.keys():
            return False
        for agent in oa:
            if any(not np.array_equal(oa[agent][k], ob[agent][k]) for k in oa[agent]):
                return False
    return True


def test_reset_with_heartbeats_is_a_clean_start() -> None:
    cfg = {"n_agents": 6, "comms": {"heartbeat_period": 3, "heartbeat_timeout": 6, "loss": 0.3, "latency": 1}}
    used = agentsim_env.make("navigation", **cfg)
    used.reset(seed=1)
    for _ in range(7):
        used.step({a: used.action_space(a).sample() for a in used.agents})
    used.reset(seed=7)
    fresh = agentsim_env.make("navigation", **cfg)
    fresh.reset(seed=7)
    assert _same(_trajectory(used, 30), _trajectory(fresh, 30))


def test_assign_group_lasts_one_episode() -> None:
    e = env(n_agents=6, comms={})
    before = e.world.state.group.copy()
    e.assign_group("agent_0", 5)
    e.assign_group("agent_1", -1)
    assert e.world.state.group[0] == 5 and e.world.state.group[1] == -1
    e.reset(seed=3)
    np.testing.assert_array_equal(e.world.state.group, before)
    fresh = agentsim_env.make("navigation", n_agents=6, comms={})
    fresh.reset(seed=3)
    e.reset(seed=3)
    assert _same(_trajectory(e, 10), _trajectory(fresh, 10))


# ---------------------------------------------------------------- 6, 7. env calls
ENV_CALLS: list[tuple[str, Callable[[Any], Any], tuple[str, ...]]] = [
    ("group 1e9", lambda e: e.assign_group("agent_0", 10**9), ("group", "-1..3")),
    ("group -2", lambda e: e.assign_group("agent_0", -2), ("group", "-1..3")),
    ("group True", lambda e: e.assign_group("agent_0", True), ("group",)),
    ("seed -1", lambda e: e.reset(seed=-1), ("seed", ">= 0")),
    ("seed 1.5", lambda e: e.reset(seed=1.5), ("seed", "float")),
    ("seed '3'", lambda e: e.reset(seed="3"), ("seed", "str")),
    ("seed True", lambda e: e.reset(seed=True), ("seed", "bool")),
    ("action (3, 1)", lambda e: e.step(motion(e, np.zeros((3, 1)))), ("agent_0", "shape (3,)", "(3, 1)")),
    ("action (1, 3)", lambda e: e.step(motion(e, np.zeros((1, 3)))), ("agent_0", "shape (3,)", "(1, 3)")),
    ("action scalar", lambda e: e.step(motion(e, 0.0)), ("agent_0", "shape (3,)")),
    (
        "action complex",
        lambda e: e.step(motion(e, np.array([1j, 0, 0]))),
        ("agent_0", "real numbers", "complex"),
    ),
    ("action strings", lambda e: e.step(motion(e, ["0.1", "0", "0"])), ("agent_0", "real numbers")),
    ("action bools", lambda e: e.step(motion(e, [True, False, True])), ("agent_0", "real numbers", "bool")),
    ("action ragged", lambda e: e.step(motion(e, [[0.1], 0, 0])), ("agent_0", "real numbers")),
]


@pytest.mark.parametrize("case", ENV_CALLS, ids=[c[0] for c in ENV_CALLS])
def test_bad_env_call_is_a_clear_error_and_the_env_keeps_working(case: Any) -> None:
    _, call, words = case
    e = env(n_agents=4, comms={})
    before = e.world.state.pos.copy()
    with pytest.raises(ValueError) as info:
        call(e)
    for w in words:
        assert w in str(info.value), f"{w!r} not in {str(info.value)!r}"
    np.testing.assert_array_equal(e.world.state.pos, before)  # nothing moved
    use(e)


def test_accepted_action_forms() -> None:
    e = env(n_agents=2)
    e.step(motion(e, [0.1, 0, 1]))  # a list of ints and floats
    e.step(motion(e, np.zeros(3, dtype=np.float32)))
    e.step(motion(e, np.array([1, 0, 0], dtype=np.int8)))
    f = env(n_agents=2, action_format="flat")
    f.step({a: np.zeros(3) for a in f.agents})
    with pytest.raises(ValueError, match="shape"):
        f.step({a: np.zeros((1, 3)) for a in f.agents})


def test_step_before_reset() -> None:
    e = agentsim_env.make("navigation", n_agents=2)
    with pytest.raises(ValueError, match=r"call reset\(\) before step\(\)"):
        e.step({})
    with pytest.raises(ValueError, match=r"call reset\(\) before step\(\)"):
        BatchedEnv("navigation", 1, n_agents=2).step(np.zeros((1, 2, 3)))
    use(e)


@pytest.mark.parametrize("seed", [-1, 1.5, "3", [0, -2], [0]])
def test_batched_seeds(seed: Any) -> None:
    b = BatchedEnv("navigation", 2, n_agents=2)
    with pytest.raises(ValueError, match="seed"):
        b.reset(seed=seed)
    b.reset(seed=[3, 4])
    b.step(np.zeros((2, 2, b.act_dim)))
