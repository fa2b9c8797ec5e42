"""One simulation over shards, in process (the local backend): equivalence with one process, hand-overs,
run-time objects, faults, and bad options. The same on a Ray cluster: tests/test_distributed_ray.py (slow)."""

from __future__ import annotations

import logging
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import agentsim_env
from agentsim_env.distributed import DistributedBatchedEnv, Strips
from agentsim_env.distributed import make as make_sharded
from agentsim_env.distributed.ray_backend import start_local_cluster
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.recorder import record
from agentsim_env.recorder.read import Store
from tests.distributed_helpers import compare, live_steps, random_actions, run

COMMS = {"loss": 0.1, "latency": 1, "heartbeat_period": 5, "heartbeat_timeout": 16}
CASES = [
    ("navigation", {"n_agents": 300}),
    ("navigation", {"n_agents": 300, "comms": COMMS}),
    ("navigation", {"n_agents": 300, "collisions": False, "comms": COMMS}),  # calls 2 and 3 as one
    ("navigation", {"n_agents": 200, "action_mode": "primitive", "comms": {"max_range": 40.0}}),
    ("navigation", {"n_agents": 120, "gnss": {"sigma_h": 2.0}, "comms": {}}),
    ("relay", {"n_groups": 4, "group_size": 6}),
]


@pytest.mark.parametrize("shards", [1, 2, 4])
@pytest.mark.parametrize(("name", "config"), CASES, ids=[f"{n}-{i}" for i, (n, _) in enumerate(CASES)])
def test_sharded_run_equals_one_process(name: str, config: dict, shards: int) -> None:
    ref, got = compare(name, shards, 120, **config)
    if shards > 1 and name == "navigation" and config["n_agents"] >= 200:
        assert got.handovers > 0, "no agent crossed a strip edge: the test would not check hand-overs"
    if config.get("comms"):
        assert any(ref.bus) and any(ref.overlay), "no message was delivered: the test would not check comms"


def _placed(env, x: list[float], y: float = 40.0):  # type: ignore[no-untyped-def]
    """Reset, then put the first agents at ``x`` (same y and altitude) in the env and, sharded, in every shard."""
    env.reset(seed=0)
    k = len(x)
    st = env.world.state
    st.pos[:k, 0], st.pos[:k, 1], st.pos[:k, 2] = x, y, 6.0
    if hasattr(env, "coordinator"):
        for shard in env.coordinator.backend.shards.values():
            shard.world.state.pos[:k] = st.pos[:k]


def _toward(env, vx: dict[int, float]):  # type: ignore[no-untyped-def]
    return {
        a: {"motion": np.array([vx.get(i, 0.0), 0.0, 0.0], dtype=np.float32)}
        for i, a in enumerate(env.possible_agents)
        if a in env.agents
    }


KW_EMPTY = {"n_agents": 4, "map_size": 120.0, "obstacle_density": 0.0}


def test_a_collision_across_a_strip_edge_is_counted_once() -> None:
    # agents 0 and 1 fly into each other over the edge at x = 60 (agent 0 in strip 0, agent 1 in strip 1)
    results = []
    for env in (
        agentsim_env.make("navigation", **KW_EMPTY),
        make_sharded("navigation", shards=2, backend="local", **KW_EMPTY),
    ):
        _placed(env, [59.2, 60.8])
        steps = [env.step(_toward(env, {0: 1.0, 1: -1.0})) for _ in range(3)]
        col = env.world.last_events.collisions
        results.append(([s[2] for s in steps], [s[4] for s in steps]))
        del col
    assert results[0] == results[1]
    terms = results[1][0]
    assert any(t.get("agent_0") and t.get("agent_1") for t in terms), "the two agents did not collide"
    hit = [i for i in results[1][1] if "agent_0" in i and i["agent_0"]["collided"]]
    assert len(hit) == 1 and hit[0]["agent_1"]["collided"] == 1


def test_agents_cross_back_and_forth() -> None:
    kw = {**KW_EMPTY, "collisions": False}
    owners: list[list[int]] = []

    def trace(env):  # type: ignore[no-untyped-def]
        _placed(env, [58.5, 59.0, 59.5, 60.5], y=40.0)
        env.world.state.pos[:4, 1] = [20.0, 40.0, 60.0, 80.0]
        if hasattr(env, "coordinator"):
            for shard in env.coordinator.backend.shards.values():
                shard.world.state.pos[:4] = env.world.state.pos[:4]
        out = []
        way = np.ones(4)
        for _ in range(80):  # east until x > 61.5, then west until x < 58.5, and again
            x = env.world.state.pos[:4, 0]
            way = np.where(x > 61.5, -1.0, np.where(x < 58.5, 1.0, way))
            env.step(_toward(env, dict(enumerate(way.tolist()))))
            out.append(env.world.state.pos[:4].copy())
            if hasattr(env, "coordinator"):
                owners.append(env.coordinator.owner[:4].tolist())
        return out

    ref = trace(agentsim_env.make("navigation", **kw))
    got = trace(make_sharded("navigation", shards=2, backend="local", **kw))
    for t, (a, b) in enumerate(zip(ref, got, strict=True)):
        assert np.array_equal(a, b), f"step {t}"
    changes = sum(o1 != o2 for o1, o2 in zip(owners, owners[1:]))
    assert changes >= 5, f"the agents changed shard only {changes} times"


def test_objects_added_at_run_time_reach_every_shard() -> None:
    kw = {"n_agents": 200}
    box = ("box", [[0.0, 0.0, 0.0]], [[6.0, 6.0, 30.0]])

    def add(env, t):  # type: ignore[no-untyped-def]
        if t == 5:  # a tall box on the first live agent, wherever it is
            centre = [[*env.world.state.pos[0, :2], 0.0]]
            if hasattr(env, "add_objects"):
                env.add_objects(box[0], centre, box[2])
            else:
                env.world.scene.add(box[0], centre, box[2], 0)

    ref = run(agentsim_env.make("navigation", **kw), 30, hook=add)
    env = make_sharded("navigation", shards=4, backend="local", **kw)
    got = run(env, 30, hook=add)
    from tests.distributed_helpers import first_difference

    assert first_difference(ref, got) is None
    new_id = env.world.scene.n_objects - 1
    assert all(sh.world.scene.n_objects == new_id + 1 for sh in env.coordinator.backend.shards.values())
    assert any(info.get("collided") for info in got.infos[5].values()), "nothing hit the new box"
    del new_id


@pytest.mark.parametrize("hold", [True, False])
def test_batched_front_end_equals_one_process(hold: bool) -> None:
    # hold: the caller keeps the previous step's result (the step writes into a fresh array) or lets it go (the
    # step writes its rows into the same array again); agents terminate on the way (their last rows stay)
    kw = {"n_agents": 150, "comms": COMMS}
    a, b = BatchedEnv("navigation", 1, **kw), DistributedBatchedEnv("navigation", 2, backend="local", **kw)
    oa, ob = a.reset(seed=1), b.reset(seed=1)
    assert np.array_equal(oa, ob)
    rng = np.random.default_rng(0)
    held, ended = None, 0
    for _ in range(40):
        act = rng.uniform(-1, 1, (1, 150, a.act_dim))
        ra, rb = a.step(act), b.step(act)
        for f in ("obs", "rewards", "terminated", "truncated", "alive"):
            assert np.array_equal(getattr(ra, f), getattr(rb, f)), f
        assert (rb.obs is not getattr(held, "obs", None)) or not hold
        ended = int((~rb.alive).sum())
        held = rb if hold else None
        del ra, rb
    assert ended > 0  # the rows of agents that no longer act were compared too
    b.close()


@pytest.mark.parametrize("hold", [True, False])
def test_the_batched_front_end_hands_a_lost_shards_agents_their_last_rows(hold: bool) -> None:
    env = DistributedBatchedEnv("navigation", 2, backend="local", n_agents=200, collisions=False)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        res = env.step(rng.uniform(-1, 1, (1, 200, env.act_dim)))
    doomed = np.flatnonzero(env.coordinator.owner == 1)
    assert doomed.size
    last = res.obs[0, doomed].copy()
    if not hold:
        del res  # the next step writes into the same array
    env.coordinator.backend.kill(1)
    for i in range(3):
        got = env.step(rng.uniform(-1, 1, (1, 200, env.act_dim)))
        assert got.terminated[0, doomed].all() == (i == 0)
        assert not got.alive[0, doomed].any()
        # the step of the loss hands out the row of the step before; later the rows of agents gone are zeros
        assert np.array_equal(got.obs[0, doomed], last if i == 0 else np.zeros_like(last))
        assert got.alive[0].sum() == 200 - doomed.size
    env.close()


# ---------------------------------------------------------------------------------------------- faults
def test_a_dead_shard_terminates_its_agents_once_and_the_rest_goes_on(tmp_path) -> None:  # type: ignore[no-untyped-def]
    env = record(
        make_sharded("navigation", shards=2, backend="local", n_agents=200, collisions=False),
        tmp_path / "run.db",
    )
    inner = env.env
    co = inner.coordinator
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    live_steps(env, 5, rng)
    doomed = {inner.possible_agents[i] for i in np.flatnonzero(co.owner == 1)}
    assert doomed
    co.backend.kill(1)
    obs, rew, term, trunc, info = env.step(random_actions(env, rng))
    assert {a for a, t in term.items() if t} == doomed
    assert set(obs) >= doomed  # their last observation is handed out with the termination
    assert not doomed & set(env.agents)
    assert not inner.shards[1].alive and "died" in inner.shards[1].reason
    assert inner.shards[0].alive
    later = live_steps(env, 10, rng)
    assert len(later) == 10 and all(not (set(s[2]) & doomed) for s in later)  # never reported again
    env.close()
    store = Store(tmp_path / "run.db")
    ev = store.events().reset_index()
    lost = ev[ev.event == "shard_offline"]
    assert len(lost) == len(doomed) and (lost.step == 6).all()
    steps = store.steps().reset_index()
    assert steps.step.max() == 16  # nothing recorded before or after the fault is lost


def test_a_shard_that_raises_is_offline_like_a_dead_one(monkeypatch: pytest.MonkeyPatch) -> None:
    env = make_sharded("navigation", shards=2, backend="local", n_agents=100, collisions=False)
    co = env.coordinator
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    live_steps(env, 3, rng)
    doomed = {env.possible_agents[i] for i in np.flatnonzero(co.owner == 1)}
    assert doomed

    def fault(*args: object) -> None:  # a persistent fault: every later call of the shard raises
        raise ZeroDivisionError("a fault inside the shard")

    monkeypatch.setattr(co.backend.shards[1], "step", fault)
    _, _, term, _, _ = env.step(random_actions(env, rng))
    assert {a for a, t in term.items() if t} == doomed  # its agents terminate once
    assert not env.shards[1].alive and env.shards[0].alive
    assert "raised ZeroDivisionError: a fault inside the shard" in env.shards[1].reason
    later = live_steps(env, 5, rng)  # the rest goes on
    assert len(later) == 5 and all(not (set(s[2]) & doomed) for s in later)
    env.reset(seed=1)  # the next episode starts the shard anew (without the fault)
    assert all(s.alive for s in env.shards) and env.shards[1].restarts == 1 and len(env.agents) == 100
    assert len(live_steps(env, 3, rng)) == 3
    env.close()


def test_a_shard_that_raises_in_its_reset_loses_its_agents_and_the_rest_goes_on(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    env = make_sharded("navigation", shards=2, backend="local", n_agents=100, collisions=False)
    co = env.coordinator

    def fault(*args: object) -> None:
        raise RuntimeError("no memory for the world")

    monkeypatch.setattr(co.backend.shards[0], "reset", fault)
    env.reset(seed=0)
    assert not env.shards[0].alive and "raised RuntimeError: no memory for the world" in env.shards[0].reason
    rng = np.random.default_rng(0)
    assert len(live_steps(env, 3, rng)) == 3
    assert (co.owner[np.flatnonzero(env.world.state.online)] == 1).all()
    env.reset(seed=1)
    assert all(s.alive for s in env.shards) and len(env.agents) == 100
    env.close()


def test_every_shard_raising_is_an_error_from_the_fault(monkeypatch: pytest.MonkeyPatch) -> None:
    env = make_sharded("navigation", shards=2, backend="local", n_agents=50, collisions=False)
    env.reset(seed=0)
    rng = np.random.default_rng(0)

    def fault(*args: object) -> None:
        raise ValueError("a bug in the shard")

    for shard in env.coordinator.backend.shards.values():
        monkeypatch.setattr(shard, "step", fault)
    with pytest.raises(RuntimeError, match="every shard is offline.*a bug in the shard.*reset") as err:
        env.step(random_actions(env, rng))
    assert isinstance(err.value.__cause__, ValueError)  # the shard's own traceback is kept
    env.close()


def test_a_slow_shard_is_declared_offline_at_its_deadline() -> None:
    env = make_sharded("navigation", shards=2, backend="local", n_agents=100, timeout_s=0.5)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    env.step(random_actions(env, rng))
    env.coordinator.backend.set_delay(0, 0.8)
    _, _, term, _, _ = env.step(random_actions(env, rng))
    assert any(term.values())
    assert not env.shards[0].alive and "deadline" in env.shards[0].reason
    assert len(live_steps(env, 5, rng)) == 5
    # the next episode starts the shard anew with every agent
    env.reset(seed=1)
    assert all(s.alive for s in env.shards) and env.shards[0].restarts == 1
    assert len(env.agents) == 100
    assert len(live_steps(env, 3, rng)) == 3


def test_every_shard_offline_is_an_error_naming_reset() -> None:
    env = make_sharded("navigation", shards=2, backend="local", n_agents=50)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    env.coordinator.backend.kill(0)
    env.coordinator.backend.kill(1)
    with pytest.raises(RuntimeError, match="every shard is offline.*reset"):
        env.step(random_actions(env, rng))


# ---------------------------------------------------------------------------------------------- bad input
BAD = [
    ({"shards": 0}, ValueError, "shards"),
    ({"shards": "2"}, ValueError, "shards"),
    ({"shards": 2.5}, ValueError, "shards"),
    ({"backend": "mpi"}, ValueError, "backend"),
    ({"timeout_s": 0}, ValueError, "timeout_s"),
    ({"timeout_s": "fast"}, ValueError, "timeout_s"),
    ({"ray_address": "not an address"}, ValueError, "ray_address"),
    ({"ray_address": "127.0.0.1:6379", "backend": "local"}, ValueError, "ray_address"),
    ({"physics": "pymunk"}, ValueError, "physics='pymunk'"),
    ({"comms": {"overlay_full": True}}, ValueError, "overlay_full"),
    ({"shards": 64, "map_size": 100.0}, ValueError, "narrower than the halo"),
    ({"n_agents": 0}, ValueError, "n_agents"),
]


@pytest.mark.parametrize(("kw", "exc", "match"), BAD, ids=[str(b[0]) for b in BAD])
def test_bad_options_name_the_field(kw: dict, exc: type, match: str) -> None:
    args = {"shards": 2, "backend": "local", "n_agents": 20, **kw}
    with pytest.raises(exc, match=match):
        make_sharded("navigation", **args)


def test_a_scenario_that_cannot_be_sharded_is_refused_with_the_ones_that_can() -> None:
    with pytest.raises(ValueError, match=r"'uav_release' cannot run over shards.*navigation.*relay"):
        make_sharded("uav_release", shards=2, backend="local")


def test_missing_ray_gives_the_install_hint(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(ImportError, match=r"pip install 'agentsim-env\[ray\]'"):
        make_sharded("navigation", shards=2, n_agents=20)


def test_a_local_cluster_off_loopback_warns_naming_what_listens(caplog: pytest.LogCaptureFixture) -> None:
    constants = pytest.importorskip("ray._private.ray_constants")
    seen: list[dict] = []

    # what ray.init is given, and the flag it reads while it resolves the node's address
    def init(**kw: object) -> None:
        seen.append({**kw, "cluster_flag": constants.ENABLE_RAY_CLUSTER})

    flag = constants.ENABLE_RAY_CLUSTER
    for node, warned in (("127.0.0.1", False), ("192.0.2.7", True)):
        fake = SimpleNamespace(init=init, util=SimpleNamespace(get_node_ip_address=lambda n=node: n), __version__="9.9")
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="agentsim_env.distributed"):
            assert start_local_cluster(fake, num_cpus=2) == node
        assert seen[-1]["_node_ip_address"] == "127.0.0.1" and seen[-1]["include_dashboard"] is False
        assert seen[-1]["cluster_flag"] is False  # lowered while ray.init runs, and only then:
        assert constants.ENABLE_RAY_CLUSTER == flag
        assert len(caplog.records) == int(warned)
    msg = caplog.records[0].getMessage()
    assert "Ray 9.9" in msg and "192.0.2.7" in msg and "gcs_server" in msg and "every interface" in msg


def test_strips_and_halos() -> None:
    st = Strips.build((0.0, 100.0, 0.0, 50.0), 4, 5.0)
    x = np.array([0.0, 24.9, 25.0, 60.0, 99.0, 100.0])
    assert st.strip_of(x).tolist() == [0, 0, 1, 2, 3, 3]
    slots = np.arange(6)
    assert st.ghosts(x, slots, 1).tolist() == [1]  # 24.9 is within 5 m of strip 1 (25..50)
    assert st.ghosts(x, slots, 2).tolist() == []
    st.reassign(2, np.array([True, True, False, True]))
    assert st.owner.tolist() == [0, 1, 1, 3]  # nearest live strip, the left one on a tie


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--shards", "0"], "--shards must be an integer >= 1"),
        (["--ray-address", "127.0.0.1:6379"], "--ray-address needs --shards"),
        (["--shards", "2", "--set", "physics=pymunk"], "physics='pymunk'"),
    ],
)
def test_cli_run_shards_bad_options(argv: list[str], match: str, capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    assert main(["run", "navigation", "--episodes", "1", "--out", "", "--quiet", *argv]) == 2
    assert match in capsys.readouterr().err


def test_the_mirror_serves_render_state_and_messages_as_one_process() -> None:
    kw = {"n_agents": 40, "comms": {}, "render_mode": "rgb_array"}
    one, two = (
        agentsim_env.make("navigation", **kw),
        make_sharded("navigation", shards=2, backend="local", **kw),
    )
    got = []
    for env in (one, two):
        env.reset(seed=5)
        assert env.send_message("agent_0", [0.5, 0.5, 0.5, 0.5], to="agent_1")
        got.append(env.step(random_actions(env, np.random.default_rng(0)))[0])
    one_obs, two_obs = got
    assert one_obs["agent_1"]["inbox"][0, 0] == 1.0  # the message arrived
    assert np.array_equal(one.render(), two.render())
    assert np.array_equal(one.state(), two.state())
    # inboxes live on the agents' shards: the observations that read them agree
    assert all(np.array_equal(one_obs[a]["inbox"], two_obs[a]["inbox"]) for a in one_obs)


def test_sb3_trains_over_shards_as_over_one_process() -> None:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from agentsim_env.env.sb3 import AgentSimVecEnv

    kw = {"n_agents": 16, "max_steps": 40}
    runs = []
    for batch in (
        BatchedEnv("navigation", 1, **kw),
        DistributedBatchedEnv("navigation", 2, backend="local", **kw),
    ):
        venv = AgentSimVecEnv("navigation", 1, seed=0, batch=batch)
        model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
        model.learn(total_timesteps=16 * 64)
        runs.append([p.detach().numpy().copy() for p in model.policy.parameters()])
        venv.close()
    assert all(np.array_equal(a, b) for a, b in zip(runs[0], runs[1], strict=True))


ROLLOUTS = [
    ("navigation", "go_to_goal", {"n_agents": 300, "comms": COMMS}),
    ("navigation", "random", {"n_agents": 200, "action_mode": "primitive", "comms": {"max_range": 40.0}}),
    ("relay", "flood", {"n_groups": 4, "group_size": 6}),
]


@pytest.mark.parametrize("shards", [1, 2, 4])
@pytest.mark.parametrize(("name", "policy", "config"), ROLLOUTS, ids=[f"{n}-{p}" for n, p, _ in ROLLOUTS])
def test_a_rollout_inside_the_shards_equals_one_process(name: str, policy: str, config: dict, shards: int) -> None:
    ref = agentsim_env.make(name, **config).rollout(policy, 120, seed=5)
    env = make_sharded(name, shards=shards, backend="local", **config)
    try:
        got = env.rollout(policy, 120, seed=5)
        assert got.steps == ref.steps and got.events == ref.events and got.info_sums == ref.info_sums
        assert np.array_equal(got.returns, ref.returns) and np.array_equal(got.final_pos, ref.final_pos)
        if config.get("comms") and name == "navigation" and policy != "random":
            assert ref.events["delivered"] > 0
        # the coordinator got counts, not observations: a heartbeat and a few counts per shard, far less than one
        # float per agent a step (an observation is hundreds)
        assert env.coordinator.traffic.replies < 100 * shards + 4 * env.scenario.n_agents
        # step() goes on from where the rollout left the agents
        live = list(env.agents)
        assert live and set(env.step(random_actions(env, np.random.default_rng(1)))[1]) == set(live)
    finally:
        env.close()


def test_a_bad_rollout_policy_is_one_error_before_the_shards_run() -> None:
    env = make_sharded("navigation", shards=2, backend="local", n_agents=40)
    with pytest.raises(ValueError, match="go_to_goal"):
        env.rollout("no_such_policy", 5)
    with pytest.raises(ValueError, match="steps"):
        env.rollout("go_to_goal", 0)
    assert all(s.alive for s in env.shards)
    env.close()


def test_a_rollout_observer_over_shards_sees_what_it_sees_in_one_process() -> None:
    from agentsim_env.render.trajectories import TrajectoryRecorder

    got = []
    kw = {"n_agents": 300, "comms": {}, "max_steps": 60}  # to the episode's end: some agents are truncated
    for env in (
        agentsim_env.make("navigation", **kw),
        make_sharded("navigation", shards=2, backend="local", **kw),
    ):
        rec = TrajectoryRecorder()
        res = env.rollout("go_to_goal", 60, seed=3, on_step=rec.on_rollout)
        got.append((res, rec.result(env)))
        env.close()
    (a, ta), (b, tb) = got
    assert np.array_equal(a.returns, b.returns) and a.events == b.events and a.events["collisions"] > 0
    assert np.array_equal(np.asarray(ta.xy), np.asarray(tb.xy))  # every agent's position at every step
    assert np.array_equal(ta.last, tb.last) and list(ta.outcome) == list(tb.outcome)
    assert "active" in list(ta.outcome)  # truncated agents are still flying, not offline


def test_a_policy_object_is_copied_to_every_shard() -> None:
    from agentsim_env.policies.registry import make_policy

    cfg = {"n_groups": 4, "group_size": 6}
    ref = agentsim_env.make("relay", **cfg).rollout("flood", 80, seed=2)
    env = make_sharded("relay", shards=2, backend="local", **cfg)
    policy = make_policy("relay", env, "flood")
    got = env.rollout(policy, 80, seed=2)  # each shard acts with its own copy (its state apart from the other's)
    env.close()
    assert np.array_equal(got.returns, ref.returns) and got.events == ref.events
