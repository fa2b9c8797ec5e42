"""The step pipeline's owner and contracts: subsystems and sensors, step hooks, the scenario contract, the GNSS
sensor, and regression tests of the defects found when the project was tried as a new user would."""

from __future__ import annotations

import numpy as np
import pytest

import agentsim_env
from agentsim_env.core.pipeline import Part, Sensor, Subsystem
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.scenarios.base import Scenario
from agentsim_env.scenarios.registry import list_scenarios, make_scenario, scenario_class
from agentsim_env.sensors.proximity import ProximitySensor
from agentsim_env.sim import StepEvents, World


def test_every_stage_is_a_subsystem_and_sensors_are_sensors() -> None:
    env = agentsim_env.make("uav_release", zones="tiny", n_agents=2, payload=12)
    w = env.world
    names = [s.name for s in w.subsystems]
    assert names == ["motion", "payloads", "collisions", "groups", "comms", "proximity"]
    assert all(isinstance(s, Subsystem) for s in w.subsystems)
    assert all(isinstance(s, Sensor) for s in w.sensors)


def test_step_hooks_run_after_every_step_with_the_events() -> None:
    env = agentsim_env.make("navigation", n_agents=3)
    env.reset(seed=0)
    seen: list[tuple[int, StepEvents]] = []

    def hook(world: World, events: StepEvents) -> None:
        seen.append((world.tick, events))

    env.world.add_hook(hook)
    for _ in range(3):
        env.step({a: {"motion": np.zeros(3)} for a in env.agents})
    assert [t for t, _ in seen] == [1, 2, 3] and "proximity" in seen[-1][1].readings
    scores = seen[-1][1].scores  # stage 10 runs after stage 9: the hook sees the step's rewards
    assert scores is not None and scores.acting.all() and scores.rewards.shape == (3,) and "arrived" in scores.info
    env.world.remove_hook(hook)
    env.step({a: {"motion": np.zeros(3)} for a in env.agents})
    assert len(seen) == 3


def test_the_contract_has_four_required_methods() -> None:
    required = sorted(Scenario.__abstractmethods__)
    assert required == ["make_world", "observe", "reset_world", "score"]
    for name in list_scenarios():  # derived, never written by hand
        cls = scenario_class(name)
        for derived in ("obs_parts", "act_parts", "state_size", "observation", "state"):
            assert getattr(cls, derived) is getattr(Scenario, derived), f"{name} overrides {derived}"


@pytest.mark.parametrize("name", list_scenarios())
def test_derived_sizes_match_what_the_env_returns(name: str) -> None:
    cfg = scenario_class(name).test_configs[0]
    env = agentsim_env.make(name, **cfg)
    obs, infos = env.reset(seed=1)
    a = env.agents[0]
    assert env.observation_space(a).contains(obs[a])
    assert env.state().shape == env.state_space.shape
    _, _, _, _, step_infos = env.step({x: env.action_space(x).sample() for x in env.agents})
    # reset infos carry the same keys as step infos (TorchRL keeps only keys present at reset)
    for agent, info in step_infos.items():
        assert set(infos[agent]) == set(info), f"{name}: reset info keys differ from step info keys"


def test_gnss_sensor_adds_its_part_and_measures_with_the_configured_noise() -> None:
    env = agentsim_env.make("navigation", n_agents=8, gnss={"sigma_h": 2.0, "sigma_v": 0.5}, map_size=100.0)
    obs, _ = env.reset(seed=3)
    assert list(obs["agent_0"]) == ["self", "lidar", "task", "gnss"]
    errs = []
    for _ in range(200):
        env.step({a: {"motion": np.zeros(3)} for a in env.agents})
        reading = env.world.readings["gnss"]
        errs.append(reading[env.world.state.online] - env.world.state.pos[env.world.state.online])
    err = np.concatenate(errs)
    np.testing.assert_allclose(err.std(axis=0), [2.0, 2.0, 0.5], rtol=0.1)
    np.testing.assert_allclose(err.mean(axis=0), 0.0, atol=0.15)
    with pytest.raises(ValueError, match="gnss.sigma_h"):
        agentsim_env.make("navigation", gnss={"sigma_h": -1.0})


def test_navigation_with_one_agent_needs_no_group_count() -> None:
    env = agentsim_env.make("navigation", n_agents=1)
    obs, _ = env.reset(seed=0)
    assert list(obs) == ["agent_0"] and env.scenario.config.n_groups == 1
    assert agentsim_env.make("navigation", n_agents=7).scenario.config.n_groups == 2


def test_every_scenario_takes_the_agent_count_as_n_agents() -> None:
    assert len(agentsim_env.make("relay", n_agents=6, n_groups=2).possible_agents) == 6
    assert agentsim_env.make("relay", n_agents=6, n_groups=2).scenario.config.group_size == 3
    uav = agentsim_env.make("uav_release", zones="tiny", n_agents=3, payload=8)
    assert len(uav.possible_agents) == 3 and uav.scenario.config.n_uavs == 3
    alias = agentsim_env.make("uav_release", zones="tiny", n_uavs=3, payload=8)  # the old key still works
    assert alias.scenario.config.n_agents == 3
    with pytest.raises(ValueError, match="multiple of n_groups"):
        agentsim_env.make("relay", n_agents=7, n_groups=2)
    with pytest.raises(ValueError, match="n_groups x group_size"):
        agentsim_env.make("relay", n_agents=6, n_groups=2, group_size=4)
    with pytest.raises(ValueError, match="not both"):
        agentsim_env.make("uav_release", zones="tiny", n_agents=3, n_uavs=3, payload=8)


def test_sub_configs_merge_over_the_scenario_defaults() -> None:
    relay = agentsim_env.make("relay", body={"radius": 0.8}).scenario.config
    assert relay.body.radius == 0.8 and relay.body.max_speed == 6.0  # relay's default speed kept
    with pytest.raises(ValueError, match=r"unknown body key\(s\) \['speed'\]"):
        agentsim_env.make("navigation", body={"speed": 3.0})
    with pytest.raises(ValueError, match="sensing.n_azimuth"):
        agentsim_env.make("navigation", sensing={"n_azimuth": 0})


def test_parallel_env_has_no_code_generation() -> None:
    import inspect

    from agentsim_env.env import parallel_env

    src = inspect.getsource(parallel_env)
    assert "eval(" not in src and "exec(" not in src


def test_batched_env_runs_every_scenario() -> None:
    for name in list_scenarios():
        b = BatchedEnv(name, 2, **scenario_class(name).test_configs[0])
        obs = b.reset(seed=0)
        out = b.step(np.zeros((2, b.n_agents, b.act_dim)))
        assert obs.shape == out.obs.shape == (2, b.n_agents, b.obs_dim)


def test_a_world_draws_nothing_before_its_reset() -> None:
    """No placeholder generators: a random draw for a world that was never reset is an error naming the fix."""
    scenario = agentsim_env.make("navigation", n_agents=2, gnss={}).scenario
    world = scenario.build(1)
    with pytest.raises(ValueError, match="reset"):
        world.refresh()  # the GNSS sensor would draw its noise
    uav = agentsim_env.make("uav_release", zones="tiny", n_agents=2, payload=12).scenario
    world = uav.build(1)
    with pytest.raises(ValueError, match="reset"):  # release scatter
        world.payloads.release(0, 0, [10.0, 10.0, 20.0], [0.0, 0.0, 0.0], 0.0)


@pytest.mark.parametrize("name", list_scenarios())
def test_the_lidar_part_is_the_one_the_proximity_sensor_declares(name: str) -> None:
    scenario = make_scenario(name, **scenario_class(name).test_configs[0])
    world = scenario.build(1)
    sensors = [s for s in world.sensors if isinstance(s, ProximitySensor)]
    parts = scenario.obs_parts()
    assert ("lidar" in parts) == bool(sensors), name
    if sensors:
        assert parts["lidar"] == sensors[0].part == Part((scenario.lidar.n_rays, 2), 0.0, 1.0)


def test_a_lidar_part_of_another_shape_than_declared_is_refused() -> None:
    from agentsim_env.scenarios.rendezvous import Rendezvous

    class HalfLidar(Rendezvous):
        def observe(self, world: World) -> dict[str, np.ndarray]:
            out = super().observe(world)
            out["lidar"] = out["lidar"][:, ::2]
            return out

    with pytest.raises(ValueError, match="'lidar' has shape"):
        HalfLidar(Rendezvous.config_cls()).obs_parts()
