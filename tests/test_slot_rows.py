"""Per-slot hand-over rows (``sim.slot_rows``): packing some slots of one world and unpacking them into another
world of the same config carries every per-slot array, and a world built from hand-overs steps on identically."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.scenarios.base import reset_worlds, run_step, slot
from agentsim_env.scenarios.navigation import NavigationSlots
from agentsim_env.sim.slot_rows import pack_slot_rows, slot_arrays, unpack_slot_rows

CONFIGS: dict[str, tuple[str, dict[str, Any]]] = {
    "navigation-comms": (
        "navigation",
        {
            "n_agents": 12,
            "n_groups": 3,
            "gnss": {},
            "comms": {"loss": 0.2, "latency": 2, "heartbeat_period": 3},
        },
    ),
    "relay": ("relay", {"n_groups": 2, "group_size": 4}),
}
# Arrays a brute-force walk of the world finds that are not an agent's state: scratch buffers, state rebuilt from
# positions every step, constants, and tables whose rows are not slots (see the module docstring).
NOT_STATE = {
    "agent_grid",
    "graph",
    "_inbox_out",
    "_no_near",
    "_newest",
    "_taken",
    "_scratch",
    "directions",
    "_out",
    "last_events",
    "events",
    "_box",
    "_obs",
}


def _every_slot_array(world: Any) -> dict[str, np.ndarray]:
    """Every array of length S reachable from the world (attributes, tuples, lists, dicts), first path wins."""
    n, out, seen = world.state.n_slots, {}, set()

    def walk(path: str, obj: Any, depth: int) -> None:
        if id(obj) in seen or depth > 6 or path.rsplit(".", 1)[-1].split("[")[0] in NOT_STATE:
            return
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):
            if obj.ndim and obj.shape[0] == n:
                out[path] = obj
        elif isinstance(obj, (list, tuple)):
            for i, v in enumerate(obj):
                walk(f"{path}[{i}]", v, depth + 1)
        elif isinstance(obj, dict):
            for k, v in obj.items():
                walk(f"{path}[{k!r}]", v, depth + 1)
        elif type(obj).__module__.startswith("agentsim_env."):
            names = set(getattr(obj, "__dict__", {}))
            names |= {s for c in type(obj).__mro__ for s in getattr(c, "__slots__", ())}
            for k in sorted(names):
                if hasattr(obj, k) and not k.startswith("__"):
                    walk(f"{path}.{k}", getattr(obj, k), depth + 1)

    walk("world", world, 0)
    return out


def _world(key: str, seed: int = 4) -> tuple[Any, Any]:
    name, cfg = CONFIGS[key]
    scenario = agentsim_env.make(name, **cfg).scenario
    world = scenario.build(1)
    reset_worlds(scenario, world, [0], [np.random.SeedSequence(seed)])
    return scenario, world


def _run(scenario: Any, world: Any, rng: np.random.Generator, steps: int, comm: bool = True) -> list[Any]:
    out = []
    for _ in range(steps):
        parts = {k: rng.uniform(-1, 1, (world.state.n_slots, p.size)) for k, p in scenario.act_parts().items()}
        if not comm and "comm" in parts:
            parts["comm"][:, 0] = -1.0  # the "no message" channel
        res, _ = run_step(scenario, world, parts, world.state.online.copy())
        out.append((res, scenario.flat_observation(world)))
    return out


@pytest.mark.parametrize("key", sorted(CONFIGS))
def test_copied_slots_carry_every_per_slot_array(key: str) -> None:
    sa, wa = _world(key, seed=4)
    sb, wb = _world(key, seed=9)
    _run(sa, wa, np.random.default_rng(1), 5)
    _run(sb, wb, np.random.default_rng(2), 3)
    slots = np.array([7, 0, 3])
    every_a, every_b = _every_slot_array(wa), _every_slot_array(wb)
    assert every_a.keys() == every_b.keys()
    differ = [p for p in every_a if not np.array_equal(every_a[p][slots], every_b[p][slots], equal_nan=True)]
    assert len(differ) > 10, differ  # the two worlds really are in different states
    rows = pack_slot_rows(wa, slots)
    assert all(v.shape[0] == slots.size for v in rows.values())
    unpack_slot_rows(wb, slots, rows)
    for path in every_a:
        np.testing.assert_array_equal(every_b[path][slots], every_a[path][slots], err_msg=path)
    others = np.setdiff1d(np.arange(wa.state.n_slots), slots)  # the other slots keep their own rows
    assert not np.array_equal(wb.state.pos[others], wa.state.pos[others])


def test_the_generic_walk_finds_the_known_owners_and_skips_scratch() -> None:
    _, world = _world("navigation-comms")
    paths = set(slot_arrays(world))
    for want in (
        "state.pos",
        "state.online",
        "motion.state.waypoints",
        "task.goal",
        "task.prev_dist",
        "groups.last_answer",
        "comms.bus.inbox.payload",
        "comms.bus.inbox.received",
        "comms.sent",
        "sensors.gnss._reading",
        "readings.proximity.distance",
    ):
        assert want in paths, want
    assert not {"comms._inbox_out", "comms.bus.inbox._newest", "groups.group"} & paths  # group is state.group

    @dataclass(slots=True)
    class Grown(NavigationSlots):  # a scenario adds a per-slot field and a per-world one: no edits needed
        extra: np.ndarray = slot((2,))
        tally: np.ndarray = slot(per_world=True)

    grown = Grown.allocate(world.state.n_slots, world.n_worlds)
    world.task = grown
    paths = set(slot_arrays(world))
    assert "task.extra" in paths and "task.goal" in paths and "task.tally" not in paths


def test_bad_slots_and_mismatched_rows_are_errors() -> None:
    _, wa = _world("navigation-comms")
    _, wr = _world("relay")
    with pytest.raises(ValueError, match=r"slots must be in \[0, 12\)"):
        pack_slot_rows(wa, np.array([12]))
    with pytest.raises(ValueError, match="integers"):
        pack_slot_rows(wa, np.array([0.5]))
    with pytest.raises(ValueError, match="task.goal"):
        unpack_slot_rows(wr, np.array([0]), pack_slot_rows(wa, np.array([0])))
    rows = pack_slot_rows(wa, np.array([0, 1]))
    with pytest.raises(ValueError, match="shape"):
        unpack_slot_rows(wa, np.array([0]), rows)


@pytest.mark.parametrize("key", sorted(CONFIGS))
def test_a_world_built_from_hand_overs_steps_on_identically(key: str) -> None:
    """World B (same episode, stepped with other actions) takes over every slot of world A in two hand-overs;
    from then on both step the same actions to the same rewards, terminations, observations and state."""
    sa, wa = _world(key)
    sb, wb = _world(key)
    _run(sa, wa, np.random.default_rng(1), 4, comm=False)
    _run(sb, wb, np.random.default_rng(2), 4, comm=False)
    n = wa.state.n_slots
    for part in (np.arange(0, n, 2), np.arange(1, n, 2)):
        unpack_slot_rows(wb, part, pack_slot_rows(wa, part))
    ra = _run(sa, wa, np.random.default_rng(3), 6)
    rb = _run(sb, wb, np.random.default_rng(3), 6)
    for (a, oa), (b, ob) in zip(ra, rb, strict=True):
        np.testing.assert_array_equal(a.rewards, b.rewards)
        np.testing.assert_array_equal(a.terminated, b.terminated)
        np.testing.assert_array_equal(oa, ob)
    for path, arr in slot_arrays(wa).items():
        np.testing.assert_array_equal(slot_arrays(wb)[path], arr, err_msg=path)
