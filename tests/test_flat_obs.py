"""The flat observation rows (array API, rollouts) equal the observation parts concatenated in layout order, for
every scenario's test configs: the scenarios and the comms stack write parts straight into the flat rows."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.scenarios.base import reset_worlds, run_step
from agentsim_env.scenarios.flat_layout import INBOX_CLIP, flat_parts
from agentsim_env.scenarios.registry import scenario_class

CASES = [(name, cfg) for name in agentsim_env.list_scenarios() for cfg in scenario_class(name).test_configs]
CASES += [("navigation", {"n_agents": 12, "n_groups": 3, "gnss": {}, "comms": {"loss": 0.2, "heartbeat_period": 3}})]


def _flat_and_parts(name: str, cfg: dict[str, Any], steps: int, seed: int = 0) -> list[tuple[np.ndarray, ...]]:
    scenario = agentsim_env.make(name, **cfg).scenario
    world = scenario.build(2)
    reset_worlds(scenario, world, [0, 1], [np.random.SeedSequence(seed), np.random.SeedSequence(seed + 1)])
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        acts = {k: rng.uniform(-1, 1, (world.state.n_slots, p.size)) for k, p in scenario.act_parts().items()}
        run_step(scenario, world, acts, world.state.online.copy())
        flat = scenario.flat_observation(world).copy()
        reused = np.full_like(flat, np.nan)
        scenario.flat_observation(world, reused)
        out.append((flat, reused, flat_parts(scenario.observation(world), world.state.n_slots)))
    return out


@pytest.mark.parametrize(("name", "cfg"), CASES, ids=[f"{n}-{i}" for i, (n, _) in enumerate(CASES)])
def test_flat_rows_are_the_parts_in_layout_order(name: str, cfg: dict[str, Any]) -> None:
    for flat, reused, parts in _flat_and_parts(name, cfg, 6):
        np.testing.assert_array_equal(flat, parts)
        np.testing.assert_array_equal(reused, parts)


@pytest.mark.parametrize("gnss", [False, True])
def test_inbox_features_are_clipped_in_flat_rows_as_in_parts(gnss: bool) -> None:
    cfg: dict[str, Any] = {"n_agents": 6, "n_groups": 2, "comms": {"payload_dim": 3, "inbox_size": 3}}
    if gnss:
        cfg["gnss"] = {}  # a sensor part: the generic path of Scenario.flat_observation
    scenario = agentsim_env.make("navigation", **cfg).scenario
    world = scenario.build(1)
    reset_worlds(scenario, world, [0], [np.random.SeedSequence(0)])
    acts = {k: np.zeros((world.state.n_slots, p.size)) for k, p in scenario.act_parts().items()}
    run_step(scenario, world, acts, world.state.online.copy())
    pay = np.array([[3e6, -5e5, np.nan]], dtype=np.float32)
    world.comms.bus.inbox.push(np.array([0]), 1, np.array([1]), 0, np.array([world.tick - 1]), pay)
    flat = scenario.flat_observation(world)
    parts = scenario.observation(world)
    np.testing.assert_array_equal(flat, flat_parts(parts, world.state.n_slots))
    assert np.nanmax(np.abs(flat)) == INBOX_CLIP and np.isnan(flat).sum() == 1
    # the kernels clip as np.clip does (NaN kept), in the dict parts and a shard's rows alike
    raw = world.comms.bus.inbox.observe(world.state.pos, max(world.tick - 1, 0))
    np.testing.assert_array_equal(parts["inbox"], np.clip(raw, -INBOX_CLIP, INBOX_CLIP))
    rows = np.array([0, 3])
    np.testing.assert_array_equal(scenario.observation_rows(world, rows)["inbox"], parts["inbox"][rows])


def test_a_scenario_that_adds_parts_in_observation_keeps_them_in_its_flat_rows() -> None:
    """A subclass that overrides ``observation`` (here: one more part after the counters) gets flat rows of its
    own parts in order, not the written-in-place layout of the stock parts."""
    from agentsim_env.scenarios.navigation import NavigationScenario

    class Extra(NavigationScenario):
        def observation(self, world):  # type: ignore[no-untyped-def]
            out = super().observation(world)
            out["extra"] = np.full((world.state.n_slots, 2), 7.0, dtype=np.float32)
            return out

    base = agentsim_env.make("navigation", n_agents=5, comms={}).scenario
    scenario = Extra(base.config)
    world = scenario.build(1)
    reset_worlds(scenario, world, [0], [np.random.SeedSequence(0)])
    flat = scenario.flat_observation(world)
    np.testing.assert_array_equal(flat, flat_parts(scenario.observation(world), world.state.n_slots))
    assert (flat[:, -2:] == 7.0).all()


@pytest.mark.parametrize(
    ("make_out", "col", "match"),
    [
        (lambda n: np.zeros((n, 40), dtype=np.float64), 0, "float32"),
        (lambda n: np.zeros((n + 1, 40), dtype=np.float32), 0, "float32"),
        (lambda n: np.zeros((n, 80), dtype=np.float32)[:, ::2], 0, "unit column stride"),
        (lambda n: np.zeros((n, 40), dtype=np.float32)[:, :, None], 0, "float32"),
        (lambda n: np.zeros((n, 40), dtype=np.float32), 30, "col must leave 15 columns"),
        (lambda n: np.zeros((n, 40), dtype=np.float32), -1, "col must leave"),
    ],
)
def test_inbox_flat_write_refuses_bad_outputs_by_name(make_out: Any, col: int, match: str) -> None:
    from agentsim_env.comms.inbox import Inbox

    inbox = Inbox(6, 1, 4)
    with pytest.raises(ValueError, match=match):
        inbox.observe_flat(np.zeros((6, 3)), 0, make_out(6), col, 1e4)
    frozen = np.zeros((6, 40), dtype=np.float32)
    frozen.flags.writeable = False
    with pytest.raises(ValueError, match="writable"):
        inbox.observe_flat(np.zeros((6, 3)), 0, frozen, 0, 1e4)
    with pytest.raises(ValueError, match="pos must have shape"):
        inbox.observe_flat(np.zeros((5, 3)), 0, np.zeros((6, 40), dtype=np.float32), 0, 1e4)
    rows = np.array([0, 2, 5])  # the rows form a shard uses: the same checks over len(rows) rows
    with pytest.raises(ValueError, match=match):
        inbox.observe_rows_flat(np.zeros((6, 3)), 0, rows, make_out(3), col, 1e4)
    with pytest.raises(ValueError, match="writable"):
        inbox.observe_rows_flat(np.zeros((6, 3)), 0, rows, frozen[:3], 0, 1e4)


@pytest.mark.parametrize(
    ("at", "match"),
    [
        ([0, 1], "one row of out in \\[0, 6\\) per row of rows \\(3\\)"),
        ([0, 1, 6], "values 0..6"),
        ([-1, 0, 1], "values -1..1"),
    ],
)
def test_inbox_rows_at_given_rows_refuse_rows_out_of_range(at: list, match: str) -> None:
    from agentsim_env.comms.inbox import Inbox

    inbox = Inbox(6, 1, 4)
    out = np.full((6, 40), np.nan, dtype=np.float32)
    rows = np.array([0, 2, 5])
    with pytest.raises(ValueError, match=match):
        inbox.observe_rows_flat(np.zeros((6, 3)), 0, rows, out, 0, 1e4, np.array(at))
    assert np.isnan(out).all()  # nothing written
    inbox.observe_rows_flat(np.zeros((6, 3)), 0, rows, out, 0, 1e4, np.array([5, 0, 3]))
    expect = np.full((3, 40), np.nan, dtype=np.float32)
    inbox.observe_rows_flat(np.zeros((6, 3)), 0, rows, expect, 0, 1e4)
    np.testing.assert_array_equal(out[[5, 0, 3]], expect)
    assert np.isnan(out[[1, 2, 4]]).all()
