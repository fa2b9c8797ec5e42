"""One simulation over Ray shard actors on two real Ray nodes on 127.0.0.1 (slow: it starts them).

The module's envs join the two-node cluster of ``tests.ray_nodes`` (this process is its driver), so shard k runs
on node ``k mod 2`` and shard traffic crosses nodes. Equivalence with one process for 1, 2 and 4 shards over 200
steps on every shardable scenario; a shard killed mid-episode (``ray.kill``); a shard that sleeps past its
deadline; a restart for the next episode; a bad address. The local cluster an env starts itself:
tests/test_distributed_ray_bind.py; a whole node that dies: tests/test_distributed_ray_nodes.py. The same logic
in process, faster and in more cases: tests/test_distributed.py.
"""

from __future__ import annotations

import logging
import os
import stat
import subprocess
import sys
import time

import numpy as np
import pytest

from agentsim_env.distributed import make as make_sharded
from agentsim_env.recorder import record
from agentsim_env.recorder.read import Store
from agentsim_env.scenarios.registry import list_scenarios, scenario_class
from tests.distributed_helpers import compare, live_steps, random_actions
from tests.ray_nodes import TwoNodes, two_nodes  # noqa: F401 - the fixture

pytestmark = pytest.mark.slow
ray = pytest.importorskip("ray")

SHARDABLE = {
    "navigation": {
        "n_agents": 300,
        "comms": {"loss": 0.1, "latency": 1, "heartbeat_period": 5, "heartbeat_timeout": 16},
    },
    "relay": {"n_groups": 4, "group_size": 6},
}


@pytest.fixture(scope="module", autouse=True)
def cluster(two_nodes: TwoNodes) -> TwoNodes:  # noqa: F811
    """Two Ray nodes on loopback for the module (each env then joins them instead of starting a cluster)."""
    return two_nodes


def test_every_shardable_scenario_is_covered() -> None:
    assert sorted(n for n in list_scenarios() if scenario_class(n).shardable) == sorted(SHARDABLE)


@pytest.mark.parametrize("shards", [1, 2, 4])
@pytest.mark.parametrize("name", sorted(SHARDABLE))
def test_ray_shards_equal_one_process_over_200_steps(name: str, shards: int) -> None:
    ref, got = compare(name, shards, 200, backend="ray", **SHARDABLE[name])
    assert len(ref.obs) == 200 or not ref.obs[-1]
    if shards > 1 and name == "navigation":
        assert got.handovers > 0


@pytest.mark.parametrize(("name", "policy"), [("navigation", "go_to_goal"), ("relay", "flood")])
def test_a_rollout_inside_ray_shards_on_two_nodes_equals_one_process(name: str, policy: str) -> None:
    import agentsim_env

    ref = agentsim_env.make(name, **SHARDABLE[name]).rollout(policy, 150, seed=4)
    env = make_sharded(name, shards=2, **SHARDABLE[name])
    try:
        got = env.rollout(policy, 150, seed=4)
        assert len({s.address.split(" on node ")[1] for s in env.shards}) == 2  # traffic crosses nodes
    finally:
        env.close()
    assert got.steps == ref.steps and got.events == ref.events and got.info_sums == ref.info_sums
    assert np.array_equal(got.returns, ref.returns) and np.array_equal(got.final_pos, ref.final_pos)


def test_the_shard_beside_the_driver_takes_actions_and_sends_rows_and_replies_through_shared_memory() -> None:
    env = make_sharded("navigation", shards=2, n_agents=200, collisions=False)
    try:
        env.reset(seed=0)
        live_steps(env, 3, np.random.default_rng(0))
        backend = env.coordinator.backend
        here = ray.get_runtime_context().get_node_id()
        # the shard on this node writes into the segment; the one on the other node returns its rows
        assert backend.shared == {0: backend.node_of(0) == here, 1: backend.node_of(1) == here}
        assert sorted(backend.shared.values()) == [False, True]
        segments = (backend.obs_segment, backend.act_segment, *backend.reply_segments)
        paths = [os.path.join("/dev/shm", seg.name) for seg in segments]
        assert len(paths) == 4
        for path in paths:
            st = os.stat(path)
            assert stat.S_IMODE(st.st_mode) == 0o600 and st.st_uid == os.getuid()
    finally:
        env.close()
    assert not any(os.path.exists(path) for path in paths)  # removed with the env


def test_a_small_dev_shm_sends_the_rows_through_ray_with_one_warning(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    # a /dev/shm too small for the segments (docker's default is 64 MB): writing past it would kill the shard
    from agentsim_env.distributed import obs_shm

    monkeypatch.setattr(obs_shm, "shm_room", lambda: 4096)  # bytes: less than 200 agents' rows need
    with caplog.at_level(logging.WARNING, logger="agentsim_env.distributed"):
        compare("navigation", 2, 20, backend="ray", n_agents=200, collisions=False)
        env = make_sharded("navigation", shards=2, n_agents=200, collisions=False)
        try:
            env.reset(seed=0)
            live_steps(env, 3, np.random.default_rng(0))
            env.reset(seed=1)
            backend = env.coordinator.backend
            assert backend.obs_segment is None and backend.reply_segments is None
            assert backend.shared == {0: False, 1: False}
        finally:
            env.close()
    warned = [r for r in caplog.records if "object store instead" in r.getMessage()]
    assert len(warned) == 2  # once per env, not once per reset


def _in_full(obs: np.ndarray, backend: object) -> int:
    """Which of the observation segment's full arrays ``obs`` lies in (-1: none)."""
    seg = backend.obs_segment  # type: ignore[attr-defined]
    return next((b for b, a in enumerate(seg.full) if np.shares_memory(obs, a)), -1)


@pytest.mark.parametrize("hold", [0, 1, 2])
def test_the_batched_front_end_fills_the_shared_arrays_and_equals_one_process(hold: int) -> None:
    # hold: how many earlier results the caller keeps. The shard beside the driver writes its observation rows
    # straight into a shared array the step returns (the other shard's rows come through Ray and are copied in);
    # an array the caller still holds, or the previous step's, is never written: when both are held, the step
    # falls back to an array of its own. Agents terminate on the way (their last rows stay).
    from agentsim_env.distributed import DistributedBatchedEnv
    from agentsim_env.env.vector import BatchedEnv

    kw = {"n_agents": 150, "comms": SHARDABLE["navigation"]["comms"]}
    a, b = BatchedEnv("navigation", 1, **kw), DistributedBatchedEnv("navigation", 2, **kw)
    try:
        assert np.array_equal(a.reset(seed=1), b.reset(seed=1))
        backend = b.coordinator.backend
        assert sorted(backend.shared.values()) == [False, True]
        rng = np.random.default_rng(0)
        held: list[tuple[object, np.ndarray]] = []
        used, ended = [], 0
        for _ in range(30):
            act = rng.uniform(-1, 1, (1, 150, a.act_dim))
            ra, rb = a.step(act), b.step(act)
            for f in ("obs", "rewards", "terminated", "truncated", "alive"):
                assert np.array_equal(getattr(ra, f), getattr(rb, f)), f
            assert all(np.array_equal(r.obs, snap) for r, snap in held)  # what the caller holds did not change
            used.append(_in_full(rb.obs, backend))
            ended = int((~rb.alive).sum())
            if hold:
                held = [*held, (rb, rb.obs.copy())][-hold:]
            del ra, rb
        assert ended > 0
        if hold < 2:  # the two arrays in turn
            assert used == [i % 2 for i in range(30)]
        else:  # when both are held, an array of its own; never the previous step's again
            assert used[:3] == [0, 1, -1] and {0, 1} <= set(used[3:])
            assert all(u == -1 or u != v for u, v in zip(used[1:], used, strict=False))
    finally:
        b.close()


def test_a_shard_lost_while_filling_the_shared_array_leaves_the_step_its_last_rows() -> None:
    # the shard beside the driver sleeps past the deadline in the step it was told to fill a shared array: it may
    # still write there until its process is gone, so the step's rows come from a copy, the agents of the lost
    # shard get the rows of the step before, and that array is never handed out again
    from agentsim_env.distributed import DistributedBatchedEnv

    env = DistributedBatchedEnv("navigation", 2, n_agents=200, collisions=False, timeout_s=1.0)
    try:
        env.reset(seed=0)
        backend = env.coordinator.backend
        k = next(k for k, shared in backend.shared.items() if shared)
        rng = np.random.default_rng(0)
        for _ in range(3):
            res = env.step(rng.uniform(-1, 1, (1, 200, env.act_dim)))
        doomed = np.flatnonzero(env.coordinator.owner == k)
        last = res.obs[0, doomed].copy()
        b = 1 - _in_full(res.obs, backend)  # the array the next step fills
        del res
        backend.set_delay(k, 30.0)
        got = env.step(rng.uniform(-1, 1, (1, 200, env.act_dim)))
        assert not env.shards[k].alive and "deadline" in env.shards[k].reason
        assert _in_full(got.obs, backend) == -1 and backend.obs_segment.retired == {b}
        assert got.terminated[0, doomed].all() and np.array_equal(got.obs[0, doomed], last)
        used = []
        for _ in range(4):  # the other array in turn with arrays of the front end's own; no more copies
            got = env.step(rng.uniform(-1, 1, (1, 200, env.act_dim)))
            used.append(_in_full(got.obs, backend))
        assert used == [1 - b, -1, 1 - b, -1] and backend.obs_segment.retired == {b}
    finally:
        env.close()


def _wait_dead(actor: object, timeout_s: float = 60.0) -> None:
    """Return once calls to ``actor`` fail because it died."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            ray.get(actor.node.remote(), timeout=10)  # type: ignore[attr-defined]
        except ray.exceptions.RayActorError:
            return
        time.sleep(0.05)
    raise AssertionError(f"the actor still answered {timeout_s:g} s after ray.kill")


def test_a_killed_shard_actor_loses_only_its_agents(tmp_path) -> None:  # type: ignore[no-untyped-def]
    env = record(make_sharded("navigation", shards=2, n_agents=200, collisions=False), tmp_path / "run.db")
    inner = env.env
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    live_steps(env, 5, rng)
    assert len({s.address.split(" on node ")[1] for s in inner.shards}) == 2  # one shard on each node
    doomed = {inner.possible_agents[i] for i in np.flatnonzero(inner.coordinator.owner == 0)}
    victim = inner.coordinator.backend.actors[0]
    ray.kill(victim, no_restart=True)
    _wait_dead(victim)  # ray.kill is asynchronous: a step sent before it lands would still be answered
    _, _, term, _, _ = env.step(random_actions(env, rng))
    assert {a for a, t in term.items() if t} == doomed
    assert not inner.shards[0].alive and "died" in inner.shards[0].reason
    later = live_steps(env, 10, rng)
    assert len(later) == 10 and len(env.agents) == 200 - len(doomed)
    env.reset(seed=1)  # the next episode restarts the shard
    assert all(s.alive for s in inner.shards) and len(env.agents) == 200
    live_steps(env, 3, rng)
    env.close()
    ev = Store(tmp_path / "run.db").events().reset_index()
    assert (ev.event == "shard_offline").sum() == len(doomed)


def test_a_shard_sleeping_past_the_deadline_does_not_hang_the_step() -> None:
    env = make_sharded("navigation", shards=2, n_agents=100, timeout_s=1.0)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    live_steps(env, 2, rng)
    env.coordinator.backend.set_delay(1, 30.0)
    t0 = time.perf_counter()
    _, _, term, _, _ = env.step(random_actions(env, rng))
    took = time.perf_counter() - t0
    assert took < 25.0, f"the step waited {took:.1f} s for a shard that sleeps 30 s"
    assert any(term.values()) and not env.shards[1].alive and "deadline" in env.shards[1].reason
    assert len(live_steps(env, 5, rng)) == 5
    env.close()


def test_a_shard_actor_that_raises_is_offline_like_a_dead_one() -> None:
    env = make_sharded("navigation", shards=2, n_agents=100, collisions=False)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    live_steps(env, 2, rng)
    doomed = {env.possible_agents[i] for i in np.flatnonzero(env.coordinator.owner == 1)}
    # a persistent fault inside the actor: time.sleep(1e300) raises OverflowError in every later call
    env.coordinator.backend.set_delay(1, 1e300)
    _, _, term, _, _ = env.step(random_actions(env, rng))
    assert {a for a, t in term.items() if t} == doomed
    assert not env.shards[1].alive and "raised OverflowError" in env.shards[1].reason
    assert len(live_steps(env, 5, rng)) == 5
    env.reset(seed=1)  # a new actor, without the fault
    assert all(s.alive for s in env.shards) and len(env.agents) == 100
    assert len(live_steps(env, 3, rng)) == 3
    env.close()


def test_an_unreachable_address_is_one_clear_error() -> None:
    # a fresh process (this one has a cluster already); port 1 on loopback: nothing listens there
    code = (
        "from agentsim_env.distributed import make\n"
        "make('navigation', shards=2, ray_address='127.0.0.1:1', n_agents=10)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "ConnectionError: cannot reach the Ray cluster at ray_address='127.0.0.1:1'" in out.stderr


def test_cli_run_over_two_shards(capsys: pytest.CaptureFixture[str]) -> None:
    from agentsim_env.cli import main

    argv = [
        "run",
        "navigation",
        "--shards",
        "2",
        "--episodes",
        "1",
        "--out",
        "",
        "--quiet",
        "--set",
        "n_agents=300",
        "max_steps=30",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "2 shards" in out and "navigation: 1 episodes x 300 agents" in out
