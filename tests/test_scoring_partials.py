"""Stage 9 from per-group partial sums: any split of the slots into parts, each summing its own slots, gives the
rewards and terminations of one sum over every slot, bit for bit (exact fixed-point group sums)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import agentsim_env
from agentsim_env.scenarios.base import StepResult, reset_worlds, run_step
from agentsim_env.scenarios.rewards import (
    MAX_TASK_VALUE,
    RewardConfig,
    combine_partials,
    compose_rewards,
    group_mean,
    group_means,
    task_partials,
)
from tests.reference.rewards import compose_rewards_reference

SCENARIOS: dict[str, dict[str, Any]] = {
    "navigation": {
        "n_agents": 12,
        "n_groups": 3,
        "comms": {"loss": 0.2, "latency": 1, "heartbeat_period": 3},
    },
    "relay": {"n_groups": 2, "group_size": 4, "reward": {"group_share": 0.5, "message_cost": 0.01}},
}


def _split(labels: np.ndarray) -> list[np.ndarray]:
    return [labels == k for k in np.unique(labels)]


@given(st.integers(0, 2**32 - 1), st.integers(1, 6))
@settings(max_examples=60, deadline=None)
def test_group_sums_do_not_depend_on_the_split_or_the_order(seed: int, n_parts: int) -> None:
    rng = np.random.default_rng(seed)
    s, b, g = int(rng.integers(1, 60)), int(rng.integers(1, 3)), int(rng.integers(1, 4))
    # magnitudes far apart: a float sum of these depends on the order of its additions
    task = rng.normal(size=s) * 10.0 ** rng.integers(-8, 9, s)
    group = rng.integers(-1, g + 2, s)  # ids past n_groups too (assign_group allows up to n_agents - 1)
    world = rng.integers(0, b, s)
    acting = rng.random(s) < 0.8
    whole = task_partials(task, group, world, acting, g, b)
    labels = rng.integers(0, n_parts, s)
    parts = [task_partials(task, group, world, acting & m, g, b) for m in _split(labels)]
    rng.shuffle(parts)
    totals = combine_partials(parts)
    assert set(totals) == {
        "task_hi",
        "task_lo",
        "task_count",
        "task_nan",
        "task_pinf",
        "task_ninf",
        "task_big",
    }
    for k, v in whole.items():
        assert v.dtype == (np.float64 if k == "task_big" else np.int64) and b * g <= v.shape[0] <= b * (g + 2)
        np.testing.assert_array_equal(totals[k], v)
    cfg = RewardConfig(group_share=0.7, energy_weight=0.1)
    kw: dict[str, Any] = {
        "group": group,
        "world": world,
        "acting": acting,
        "n_groups": g,
        "energy": np.abs(task),
    }
    np.testing.assert_array_equal(compose_rewards(cfg, task, **kw), compose_rewards(cfg, task, totals=totals, **kw))


def test_the_group_mean_is_the_fixed_point_mean() -> None:
    task = np.array([1e12, 1e-5, -1e12, 0.25, 3.0])
    group, world, acting = np.array([0, 0, 0, 1, 1]), np.zeros(5, dtype=np.int64), np.ones(5, dtype=bool)
    assert (task[0] + task[1]) + task[2] == 0.0  # the float sum in slot order loses the small value
    mean = group_mean(task, group, world, acting, 2)
    assert mean[0] == mean[1] == mean[2] and abs(mean[0] - 1e-5 / 3) <= 2**-32
    assert mean[3] == mean[4] == 1.625
    small = np.array([0.1, 0.2, 0.3])
    got = group_mean(small, np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64), np.ones(3, dtype=bool), 1)
    assert abs(got[0] - 0.2) <= 2**-32


@pytest.mark.parametrize("big", [MAX_TASK_VALUE * 2, -1e13])
def test_a_task_value_out_of_the_fixed_point_range_is_summed_as_a_float(big: float) -> None:
    """A valid config with huge reward weights must still run: values over the fixed point's range are summed
    as floats apart (exact within one process)."""
    task = np.array([1.0, big, 2.0])
    zeros = np.zeros(3, dtype=np.int64)
    out = task_partials(task, zeros, zeros, np.ones(3, dtype=bool), 1, 1)
    assert out["task_count"].tolist() == [3] and out["task_big"].tolist() == [big]
    assert group_means(out)[0] == (3.0 + big) / 3.0
    # a slot outside the mask does not enter the sums
    out = task_partials(task, zeros, zeros, np.array([1, 0, 1], bool), 1, 1)
    assert out["task_count"].tolist() == [2] and out["task_hi"].tolist() == [3] and out["task_big"].tolist() == [0]


def test_non_finite_task_values_give_the_float_mean() -> None:
    """NaN and infinities are counted apart: the mean is what a float sum gives, in any split (check_finite then
    names the reward, as before)."""
    nan, inf = float("nan"), float("inf")
    task = np.array([1.0, nan, 2.0, inf, 3.0, inf, -inf, 4.0])
    group = np.array([0, 0, 1, 1, 2, 2, 2, 3])
    world, acting = np.zeros(8, dtype=np.int64), np.ones(8, dtype=bool)
    want = [nan, nan, inf, inf, nan, nan, nan, 4.0]
    np.testing.assert_array_equal(group_mean(task, group, world, acting, 4), want)
    parts = [task_partials(task, group, world, acting & (np.arange(8) % 2 == k), 4, 1) for k in (0, 1)]
    kw: dict[str, Any] = {"group": group, "world": world, "acting": acting, "n_groups": 4}
    cfg = RewardConfig(group_share=1.0)
    got = compose_rewards(cfg, task, totals=combine_partials(parts), **kw)
    np.testing.assert_array_equal(got, compose_rewards_reference(cfg, task, **kw))
    assert np.isnan(got[[0, 1, 4, 5, 6]]).all() and got[2] == got[3] == inf and got[7] == 8.0


def _world(name: str, seed: int) -> tuple[Any, Any]:
    scenario = agentsim_env.make(name, **SCENARIOS[name]).scenario
    world = scenario.build(1)
    reset_worlds(scenario, world, [0], [np.random.SeedSequence(seed)])
    return scenario, world


def _actions(scenario: Any, world: Any, rng: np.random.Generator) -> dict[str, np.ndarray]:
    n = world.state.n_slots
    return {k: rng.uniform(-1, 1, (n, p.size)) for k, p in scenario.act_parts().items()}


def _score_split(scenario: Any, world: Any, parts: dict, acting: np.ndarray, labels: np.ndarray) -> StepResult:
    """Stage 1 to 8 as ``run_step`` runs them, then stage 9 from the parts' partial sums."""
    scenario.apply_actions(world, parts, acting)
    if "comm" in parts:
        world.apply_comm(parts["comm"], acting)
    events = world.step(hooks=False)
    partials = [scenario.group_partials(world, events, acting, m) for m in _split(labels)]
    res = scenario.score(world, events, acting, combine_partials(partials[::-1]))
    terminated = acting & (res.terminated | ~world.state.online)
    if terminated.any():
        world.set_offline(np.flatnonzero(terminated))
    return res


@pytest.mark.parametrize("name", sorted(SCENARIOS))
@given(seed=st.integers(0, 2**16), n_parts=st.integers(1, 5))
@settings(max_examples=8, deadline=None)
def test_any_split_of_the_slots_scores_like_the_whole(name: str, seed: int, n_parts: int) -> None:
    sa, wa = _world(name, seed)
    sb, wb = _world(name, seed)
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, n_parts, wa.state.n_slots)
    if name == "navigation":  # a few agents in groups past n_groups (assign_group allows ids up to n_agents - 1)
        some = rng.choice(wa.state.n_slots, 3, replace=False)
        wa.state.group[some] = wb.state.group[some] = rng.integers(-1, wa.n_agents, 3)
    if name == "relay":  # end every non-scout of group 0 but one now and then, so scouts end too
        t = wa.task
        gone = np.flatnonzero(~t.scout & (wa.state.group == 0))[: -1 if seed % 2 else None]
        wa.set_offline(gone)
        wb.set_offline(gone)
    for _ in range(4):
        parts = _actions(sa, wa, rng)
        acting = wa.state.online.copy()
        ra, _ = run_step(sa, wa, parts, acting)
        rb = _score_split(sb, wb, parts, acting, labels)
        np.testing.assert_array_equal(ra.rewards, rb.rewards)
        np.testing.assert_array_equal(ra.terminated, rb.terminated)
        for k in ra.info:
            np.testing.assert_array_equal(ra.info[k], rb.info[k])
        np.testing.assert_array_equal(wa.state.online, wb.state.online)


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_group_partials_change_no_state_and_have_the_documented_shape(name: str) -> None:
    scenario, world = _world(name, 3)
    acting = world.state.online.copy()
    scenario.apply_actions(world, _actions(scenario, world, np.random.default_rng(0)), acting)
    events = world.step(hooks=False)
    before = {k: getattr(world.task, k).copy() for k in ("prev_dist", "arrived")}
    energy = world.state.energy.copy()
    out = scenario.group_partials(world, events, acting, np.ones(world.state.n_slots, dtype=bool))
    assert out and all(
        v.dtype == (np.float64 if k == "task_big" else np.int64) and v.shape == (scenario.n_groups,)
        for k, v in out.items()
    )
    for k, v in before.items():
        np.testing.assert_array_equal(getattr(world.task, k), v)
    np.testing.assert_array_equal(world.state.energy, energy)
    none = scenario.group_partials(world, events, acting, np.zeros(world.state.n_slots, dtype=bool))
    assert all(not v.any() for v in none.values())


def test_relay_scouts_end_from_the_combined_pending_counts() -> None:
    """A part that holds no member of a group must not end that group's scout on its own."""
    scenario, world = _world("relay", 5)
    t, g = world.task, world.state.group
    members = np.flatnonzero(~t.scout & (g == 0))
    world.set_offline(members[1:])  # one member of group 0 is still live
    acting = world.state.online.copy()
    parts = _actions(scenario, world, np.random.default_rng(1))
    parts["motion"][:] = 0.0
    scenario.apply_actions(world, parts, acting)
    world.apply_comm(parts["comm"], acting)
    events = world.step(hooks=False)
    scout = int(np.flatnonzero(t.scout & (g == 0))[0])
    alone = np.zeros(world.state.n_slots, dtype=bool)
    alone[scout] = True
    mine = scenario.group_partials(world, events, acting, alone)
    assert mine["pending"][0] == 0  # the scout's own part sees nobody pending
    totals = combine_partials([mine, scenario.group_partials(world, events, acting, ~alone)])
    assert totals["pending"][0] == 1
    assert not scenario.score(world, events, acting, totals).terminated[scout]


def test_run_step_scores_from_the_partials_of_one_part(monkeypatch: pytest.MonkeyPatch) -> None:
    scenario, world = _world("navigation", 0)
    seen: list[np.ndarray] = []
    original = scenario.group_partials

    def spy(world: Any, events: Any, acting: np.ndarray, mine: np.ndarray) -> dict[str, np.ndarray]:
        seen.append(mine.copy())
        return original(world, events, acting, mine)

    monkeypatch.setattr(scenario, "group_partials", spy)
    parts = _actions(scenario, world, np.random.default_rng(2))
    run_step(scenario, world, parts, world.state.online.copy())
    assert len(seen) == 1 and seen[0].all()


@given(st.integers(0, 2**32 - 1), st.integers(2, 5))
@settings(max_examples=60, deadline=None)
def test_group_sums_and_rewards_do_not_depend_on_the_thread_count(seed: int, k: int) -> None:
    """The partial sums and the composed rewards over slot ranges on threads equal the one-thread ones, with
    non-finite values and values past the fixed point's range among them."""
    from agentsim_env.core import threads as threads_mod
    from agentsim_env.core.threads import RowThreads

    rng = np.random.default_rng(seed)
    s, b, g = int(rng.integers(0, 200)), int(rng.integers(1, 3)), int(rng.integers(1, 4))
    task = rng.normal(size=s) * 10.0 ** rng.integers(-8, 9, s)
    odd = rng.random(s)
    task[odd < 0.05] = np.nan
    task[(odd >= 0.05) & (odd < 0.08)] = np.inf
    task[(odd >= 0.08) & (odd < 0.1)] = 4.0 * MAX_TASK_VALUE
    group = rng.integers(-1, g + 2, s)
    world = rng.integers(0, b, s)
    acting = rng.random(s) < 0.8
    cfg = RewardConfig(group_share=0.5, collision_penalty=0.3, energy_weight=0.01)
    kw = dict(
        group=group,
        world=world,
        acting=acting,
        n_groups=g,
        n_worlds=b,
        collided=(odd < 0.3) * 1.0,
        energy=rng.random(s),
    )
    one_sums = task_partials(task, group, world, acting, g, b)
    one = compose_rewards(cfg, task, **kw)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(threads_mod, "MIN_ROWS", 3)
        many_sums = task_partials(task, group, world, acting, g, b, RowThreads(k))
        many = compose_rewards(cfg, task, threads=RowThreads(k), **kw)
    assert one_sums.keys() == many_sums.keys()
    for name in one_sums:
        np.testing.assert_array_equal(one_sums[name], many_sums[name], err_msg=name)
    np.testing.assert_array_equal(one, many)
    ref_kw = {k: v for k, v in kw.items() if k != "n_worlds"}
    np.testing.assert_array_equal(one, compose_rewards_reference(cfg, task, **ref_kw))
