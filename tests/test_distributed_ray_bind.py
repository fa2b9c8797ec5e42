"""The local Ray cluster that ``distributed.make`` starts listens on loopback only (slow: it starts Ray).

Every TCP socket in LISTEN state held by this process (the driver) or any process it started (gcs_server, the
raylet, the runtime-env agent, the shard workers, the exchange actor with its data path for the shards), read from
``/proc/net/tcp*`` while an env runs.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from agentsim_env.distributed import make as make_sharded
from tests.distributed_helpers import live_steps
from tests.listening import Listener, listeners

pytestmark = pytest.mark.slow
ray = pytest.importorskip("ray")
if not sys.platform.startswith("linux"):  # pragma: no cover - /proc/net is Linux's
    pytest.skip("reads /proc/net/tcp*", allow_module_level=True)


@pytest.fixture(scope="module")
def running() -> Iterator[tuple[Any, list[Listener]]]:
    """One env over 2 Ray shards on the local cluster it starts itself; the sockets opened meanwhile."""
    assert not ray.is_initialized(), "another test left Ray running: this module must start its own cluster"
    before = {s.inode for s in listeners()}
    env = make_sharded("navigation", shards=2, n_agents=50)
    try:
        env.reset(seed=0)
        yield env, [s for s in listeners() if s.inode not in before]
    finally:
        env.close()


def test_every_port_of_the_local_cluster_is_on_loopback(running: tuple[Any, list[Listener]]) -> None:
    _, opened = running
    names = {s.process for s in opened}
    # the walk found every kind of Ray process that listens, and the driver (else the check would prove nothing)
    assert {"gcs_server", "raylet", "ray::RuntimeEnvAgent", "ray::Shard", "ray::ExchangeActor"} <= names, sorted(
        map(str, opened)
    )
    assert any(s.pid == os.getpid() for s in opened), sorted(map(str, opened))
    assert sum(s.process == "ray::Shard" for s in opened) == 2  # one worker per shard
    # the exchange's Ray port and its data path for the shards (``distributed.wire``)
    assert sum(s.process == "ray::ExchangeActor" for s in opened) == 2, sorted(map(str, opened))
    exposed = [str(s) for s in opened if not s.loopback]
    assert not exposed, f"the local Ray cluster listens beyond loopback: {exposed}"


def test_the_loopback_cluster_runs_the_shards(running: tuple[Any, list[Listener]]) -> None:
    env, _ = running
    assert len(live_steps(env, 3, np.random.default_rng(0))) == 3
    assert all(s.alive for s in env.shards)
    assert env.coordinator.backend.address == "local cluster on 127.0.0.1"


def test_the_exchange_data_path_serves_only_peers_with_its_token(running: tuple[Any, list[Listener]]) -> None:
    import socket
    import struct

    from agentsim_env.distributed import wire

    env, _ = running
    host, port, token = env.coordinator.backend.wire
    assert host == "127.0.0.1" and len(token) == wire.TOKEN_BYTES
    with socket.create_connection((host, port), timeout=10) as s:
        s.sendall(struct.pack(f"!4s{wire.TOKEN_BYTES}sI", wire.AUTH_MAGIC, bytes(wire.TOKEN_BYTES), 0))
        assert s.recv(16) == b""  # closed unanswered
    assert len(live_steps(env, 2, np.random.default_rng(1))) == 2  # the shards' own connections still work
