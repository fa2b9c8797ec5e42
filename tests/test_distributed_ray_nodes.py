"""Shards on two real Ray nodes on loopback, so shard traffic crosses nodes (slow: it starts two Ray nodes).

The nodes come from ``tests.ray_nodes`` (a head and a second node joining it, each a ``ray start`` process
killed by the fixture); the env joins them through ``ray_address``. Only the public API is used here
(``make``, ``step``, ``reset``, ``shards``, ``close``): each shard's address in ``env.shards`` names its process
and its Ray node.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from typing import Any

import numpy as np
import pytest

import agentsim_env
from agentsim_env.distributed import make as make_sharded
from tests.distributed_helpers import first_difference, live_steps, random_actions, run
from tests.listening import listeners
from tests.ray_nodes import TwoNodes, node_of_pid, two_nodes  # noqa: F401 - the fixture

pytestmark = pytest.mark.slow
ray = pytest.importorskip("ray")
if not sys.platform.startswith("linux"):  # pragma: no cover - the nodes are found in /proc
    pytest.skip("reads /proc", allow_module_level=True)

NAV_COMMS: dict[str, Any] = {
    "n_agents": 300,
    "comms": {"loss": 0.1, "latency": 1, "heartbeat_period": 5, "heartbeat_timeout": 16},
}
_WHERE = re.compile(r":(\d+) on node ([0-9a-f]+)$")


def where(env: Any) -> list[tuple[int, str]]:
    """Each shard's (pid, node id prefix), read from its address in ``env.shards``."""
    out = []
    for info in env.shards:
        m = _WHERE.search(info.address)
        assert m, f"shard {info.index}'s address {info.address!r} names no node"
        out.append((int(m.group(1)), m.group(2)))
    return out


def node_index(two: TwoNodes, prefix: str) -> int:
    """The index of the node whose id starts with ``prefix``."""
    found = [n.index for n in two.nodes if n.node_id.startswith(prefix)]
    assert len(found) == 1, (prefix, [n.node_id for n in two.nodes])
    return found[0]


def test_the_two_shards_run_on_two_different_nodes(two_nodes: TwoNodes) -> None:  # noqa: F811
    env = make_sharded("navigation", shards=2, ray_address=two_nodes.address, n_agents=100)
    try:
        env.reset(seed=0)
        placed = where(env)
        nodes = [node_index(two_nodes, prefix) for _, prefix in placed]
        assert nodes == [0, 1]  # shard k on the node offering agentsim_node_<k mod 2>
        # and each shard's process is a worker of that node's raylet
        assert [node_of_pid(two_nodes, pid) for pid, _ in placed] == [0, 1]
        assert len(live_steps(env, 3, np.random.default_rng(0))) == 3
    finally:
        env.close()


def test_two_nodes_equal_one_process_over_120_steps_with_comms(two_nodes: TwoNodes) -> None:  # noqa: F811
    ref = run(agentsim_env.make("navigation", **NAV_COMMS), 120)
    env = make_sharded("navigation", shards=2, ray_address=two_nodes.address, **NAV_COMMS)
    try:
        got = run(env, 120)
        assert sorted(node_index(two_nodes, prefix) for _, prefix in where(env)) == [0, 1]
    finally:
        env.close()
    assert len(ref.obs) == 120
    assert sum(len(b) for b in ref.bus) > 0  # messages did flow (and crossed nodes)
    diff = first_difference(ref, got)
    assert diff is None, f"navigation over two Ray nodes differs from one process at {diff}"


def test_every_port_of_the_two_node_cluster_is_on_loopback(two_nodes: TwoNodes) -> None:  # noqa: F811
    env = make_sharded("navigation", shards=2, ray_address=two_nodes.address, n_agents=50)
    try:
        env.reset(seed=0)
        pids = {os.getpid()} | {p for n in two_nodes.nodes for p in n.pids()}
        opened = [s for s in listeners() if s.pid in pids]
    finally:
        env.close()
    names = [s.process for s in opened]
    # both nodes' servers, the head's GCS, the shard workers and the driver (else the check proves nothing)
    assert {"gcs_server", "raylet", "ray::RuntimeEnvAgent", "ray::Shard"} <= set(names), sorted(map(str, opened))
    assert len({s.pid for s in opened if s.process == "raylet"}) == 2, sorted(map(str, opened))
    assert names.count("ray::Shard") == 2 and any(s.pid == os.getpid() for s in opened)
    exposed = [str(s) for s in opened if not s.loopback]
    assert not exposed, f"the two-node Ray cluster listens beyond loopback: {exposed}"


def test_a_dead_node_ends_only_its_shards_agents(two_nodes: TwoNodes) -> None:  # noqa: F811
    timeout_s = 3.0
    env = make_sharded(
        "navigation",
        shards=2,
        ray_address=two_nodes.address,
        n_agents=200,
        collisions=False,
        timeout_s=timeout_s,
    )
    rng = np.random.default_rng(0)
    try:
        env.reset(seed=0)
        assert len(live_steps(env, 5, rng)) == 5 and len(env.agents) == 200
        doomed_shard = [node_index(two_nodes, prefix) for _, prefix in where(env)].index(1)
        two_nodes.stop_second()
        t0 = time.perf_counter()
        _, _, term, _, _ = env.step(random_actions(env, rng))
        took = time.perf_counter() - t0
        assert took < timeout_s + 10.0, f"the step waited {took:.1f} s for a dead node (deadline {timeout_s} s)"
        ended = {a for a, t in term.items() if t}
        assert ended and len(ended) < 200, len(ended)
        assert not env.shards[doomed_shard].alive and env.shards[1 - doomed_shard].alive
        assert set(env.agents) == set(env.possible_agents) - ended
        for _, _, term, _, _ in live_steps(env, 10, rng):  # the rest goes on; the ended never report again
            assert not ended & set(term) and not any(term.values())
        assert len(env.agents) == 200 - len(ended)
        t0 = time.perf_counter()
        env.reset(seed=1)  # the dead node's shard starts anew on the node still alive
        reset_s = time.perf_counter() - t0
        assert all(s.alive for s in env.shards) and len(env.agents) == 200
        assert [node_index(two_nodes, prefix) for _, prefix in where(env)] == [0, 0], reset_s
        assert len(live_steps(env, 3, rng)) == 3
    finally:
        env.close()
        two_nodes.restart_second()  # the next tests of the module get two nodes again
    print(
        f"two nodes started in {two_nodes.start_s:.1f} s; the step after the kill took {took:.2f} s; the "
        f"reset {reset_s:.1f} s; the cluster marked the node dead {two_nodes.dead_after_s:.1f} s after the kill"
    )


def test_a_fresh_process_joins_the_loopback_cluster_by_address(two_nodes: TwoNodes) -> None:  # noqa: F811
    # a new driver: Ray would rewrite 127.0.0.1 to the machine's outward address, where nothing listens
    code = (
        "import numpy as np\n"
        "from agentsim_env.distributed import make\n"
        "from tests.distributed_helpers import live_steps\n"
        f"env = make('navigation', shards=2, ray_address={two_nodes.address!r}, n_agents=50)\n"
        "env.reset(seed=0)\n"
        "print(len(live_steps(env, 2, np.random.default_rng(0))), sorted(s.alive for s in env.shards))\n"
        "env.close()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=150)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().splitlines()[-1] == "2 [True, True]", out.stdout
