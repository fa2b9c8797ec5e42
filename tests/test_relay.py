"""Task and property tests of the ``relay`` scenario and its two scripted baselines.

Success measure: an (episode, group) succeeds when at least half of the group's non-scouts reached the target
(``RelayScenario.group_success``); a policy's success rate is the mean over seeds x groups.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.comms.messages import OVERLAY
from agentsim_env.policies.registry import make_policy
from agentsim_env.policies.rollout import run_episode

SEEDS = range(20)
NO_COMMS = {"loss": 1.0, "overlay_range": 1e-3}  # the bus loses everything, the overlay reaches nobody


def success_rate(policy: str, seeds: range = SEEDS, **config: Any) -> tuple[float, list[int]]:
    """Mean group success of ``policy`` over ``seeds`` and the step count of each episode."""
    env = agentsim_env.make("relay", **config)
    pol = make_policy("relay", env, policy)
    wins, steps = [], []
    for seed in seeds:
        steps.append(run_episode(env, pol, seed).steps)
        wins.append(env.scenario.group_success(env.world))
    return float(np.mean(wins)), steps


@pytest.fixture(scope="module")
def rates() -> dict[str, tuple[float, list[int]]]:
    return {"flood": success_rate("flood"), "silent": success_rate("silent")}


def test_flooding_doubles_the_success_of_silence(rates: dict) -> None:
    flood, flood_steps = rates["flood"]
    silent, _ = rates["silent"]
    assert flood >= 0.8, f"flood succeeded in {flood:.0%} of group-episodes"
    assert flood >= 2.0 * silent, f"flood {flood:.0%} vs silent {silent:.0%}"
    # scouts end once their group is done, so successful episodes finish before the time limit
    assert min(flood_steps) < agentsim_env.make("relay").scenario.max_steps


def test_without_messages_flooding_falls_to_the_silent_level(rates: dict) -> None:
    """Information travels only through messages: cut the channels and the flood baseline learns nothing."""
    silent, _ = rates["silent"]
    cut, _ = success_rate("flood", range(8), comms=NO_COMMS)
    assert cut <= silent + 0.05, f"flood with dead channels {cut:.0%} vs silent {silent:.0%}"
    assert cut < rates["flood"][0] / 2


def test_non_scouts_cannot_see_the_target() -> None:
    env = agentsim_env.make("relay")
    sc = env.scenario
    diag = np.hypot(sc.config.length, sc.config.corridor_width)
    for seed in range(5):
        obs, _ = env.reset(seed=seed)
        for _ in range(3):
            for i, a in enumerate(env.agents):
                task = obs[a]["task"]
                if env.world.task.scout[i]:
                    assert task[0] == 1.0
                    rel = env.world.task.target[i] - env.world.state.pos[i, :2]
                    np.testing.assert_allclose(task[1:3] * diag, rel, atol=1e-3)
                else:
                    assert not task.any(), f"non-scout {a} sees {task}"
            assert env.world.task.scout.reshape(-1, sc.n_groups).sum(axis=0).tolist() == [1] * sc.n_groups
            obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})


def test_most_members_start_beyond_one_bus_hop_on_a_connected_chain() -> None:
    env = agentsim_env.make("relay")
    cfg = env.scenario.config.comms
    far = []
    for seed in SEEDS:
        env.reset(seed=seed)
        pos = env.world.state.pos
        scout_of = pos[np.flatnonzero(env.world.task.scout)[env.world.state.group]]
        member = ~env.world.task.scout
        far.append(np.linalg.norm(pos[member] - scout_of[member], axis=1) > cfg.max_range)
        chain = pos[np.argsort(pos[:, 0])]
        assert np.linalg.norm(np.diff(chain, axis=0), axis=1).max() <= cfg.overlay_range
    assert np.mean(far) >= 0.6, f"only {np.mean(far):.0%} of members start beyond the bus range"


def _trace(seed: int, steps: int) -> tuple[list[dict], list[np.ndarray], int]:
    env = agentsim_env.make("relay", n_groups=2, group_size=3, comms={"loss": 0.5, "latency": 2})
    pol = make_policy("relay", env, "flood")
    obs, _ = env.reset(seed=seed)
    pol.reset(seed)
    rewards, inboxes, dropped = [], [], 0
    for _ in range(steps):
        if not env.agents:
            break
        obs, rew, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
        rewards.append(rew)
        inboxes.append(np.stack([o["inbox"] for o in obs.values()]))
        dropped += sum(float(o["comms"][1] > 0) for o in obs.values())
    return rewards, inboxes, dropped


def test_lossy_channel_is_deterministic() -> None:
    r1, i1, dropped = _trace(11, 120)
    r2, i2, _ = _trace(11, 120)
    assert dropped > 0, "the channel should have lost messages"
    assert r1 == r2
    assert len(i1) == len(i2) and all(np.array_equal(a, b) for a, b in zip(i1, i2))
    r3, i3, _ = _trace(12, 120)
    assert r3 != r1 or not all(np.array_equal(a, b) for a, b in zip(i1, i3))


def test_overlay_reports_carry_the_target_position() -> None:
    """The flood payload decodes to the group's target (the policy's documented encoding)."""
    env = agentsim_env.make("relay")
    sc = env.scenario
    pol = make_policy("relay", env, "flood")
    obs, _ = env.reset(seed=3)
    pol.reset(3)
    seen = 0
    for _ in range(15):
        obs, *_ = env.step(pol.act({a: obs[a] for a in env.agents}))
        for a, o in obs.items():
            i = env.possible_agents.index(a)
            rows = o["inbox"][(o["inbox"][:, 0] > 0) & (o["inbox"][:, OVERLAY] > 0)]
            mine = rows[np.abs(rows[:, 13] - o["self"][8]) < 0.1]
            for row in mine:
                xy = (row[11:13] + 1.0) / 2.0 * np.array([sc.config.length, sc.config.corridor_width])
                np.testing.assert_allclose(xy, env.world.task.target[i], atol=1e-3)
                seen += 1
    assert seen > 0


@pytest.mark.parametrize(
    ("key", "value", "field"),
    [
        ("group_size", 1, "group_size"),
        ("n_groups", 0, "n_groups"),
        ("gap", (30.0, 20.0), "gap[1]"),
        ("gap", (0.0, 20.0), "gap[0]"),
        ("corridor_width", 10.0, "corridor_width"),
        ("arrival_radius", -1.0, "arrival_radius"),
        ("physics", "bullet", "physics"),
        ("comms", None, "comms"),
        ("comms", {"bogus": 1}, "bogus"),
        ("comms", {"loss": 2.0}, "comms.loss"),
        ("reward", {"message_cost": -1.0}, "reward.message_cost"),
        ("no_such_key", 1, "no_such_key"),
    ],
)
def test_config_errors_name_the_field(key: str, value: Any, field: str) -> None:
    with pytest.raises(ValueError, match=field.replace("[", r"\[").replace(".", r"\.")):
        agentsim_env.make("relay", **{key: value})


def test_comms_dict_overrides_the_relay_defaults() -> None:
    cfg = agentsim_env.make("relay", comms={"loss": 0.2}).scenario.config.comms
    assert cfg.loss == 0.2 and cfg.max_range == 35.0 and cfg.max_hops == 8
