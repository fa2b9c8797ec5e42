"""Shared by the Ray tests: a real two-node Ray cluster on loopback (a head and a second node joining it).

Each node is one ``ray start --block`` process in its own process group (``ray start`` without ``--block``
would leave its daemons orphaned): gcs_server, the raylet, the agents and, under the raylet, every worker
descend from it, so the node is stopped by killing that tree, never by ``ray stop`` (which kills every Ray
process of the user, another test's cluster too). Workers open their own process groups, so the tree is
walked in ``/proc`` rather than killed as one group.

Every port stays on 127.0.0.1: each node gets ``--node-ip-address 127.0.0.1`` and a free loopback port for
every server Ray would otherwise open on a fixed port (the dashboard's, the client server's, the agents'),
and ``ray start`` runs with Ray's loopback-to-outward-address rewrite of the node address turned off (Ray 2.60
replaces a literal 127.0.0.1 by the machine's outward address, and then binds every gRPC server to every
interface; see ``agentsim_env.distributed.ray_backend``). Token authentication follows this process
(``RAY_AUTH_MODE``): off, as for a driver that joins by address, unless a local cluster started here before
turned it on (Ray does when ``~/.ray/auth_token`` exists; the nodes then read that token too). With one side on
and the other off, every actor dies at creation.

Node ``i`` offers the custom resource ``agentsim_node_<i>``, which pins shard ``k`` to node ``k mod 2``.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from agentsim_env.distributed.ray_backend import NODE_RESOURCE, connect_driver
from tests.listening import process_tree

# ``ray start`` with the node address taken as given (see the module docstring), then Ray's own CLI
_RAY_START = (
    "import sys\n"
    "from ray._private import services\n"
    "services.resolve_ip_for_localhost = lambda host: host\n"
    "from ray.scripts.scripts import main\n"
    "sys.argv = ['ray', *sys.argv[1:]]\n"
    "main()\n"
)
START_TIMEOUT_S = 120.0


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _node_ports() -> list[str]:
    """``ray start`` options giving each server of a node its own free loopback port."""
    out = []
    for option in (
        "--node-manager-port",
        "--object-manager-port",
        "--dashboard-agent-listen-port",
        "--dashboard-agent-grpc-port",
        "--runtime-env-agent-port",
        "--metrics-export-port",
    ):
        out += [option, str(free_port())]
    return out


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _name(pid: int) -> str:
    try:
        argv0 = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
    except OSError:
        return "?"
    return os.path.basename(argv0)


@dataclass
class RayNode:
    """One ``ray start --block`` process and what descends from it.

    Attributes:
        index: Node index i (it offers ``agentsim_node_<i>``).
        proc: The ``ray start`` process (leader of its own process group).
        log: Its stdout and stderr.
        node_id: Ray's node id (hex), once the node joined.
    """

    index: int
    proc: subprocess.Popen[bytes]
    log: Path
    node_id: str = ""

    def pids(self) -> list[int]:
        """The ``ray start`` process and every process descended from it (gcs_server, raylet, workers)."""
        return [p for p in process_tree(self.proc.pid) if _alive(p)]

    def raylet_pid(self) -> int:
        """The pid of this node's raylet.

        Raises:
            LookupError: When it does not run.
        """
        for pid in self.pids():
            if _name(pid) == "raylet":
                return pid
        raise LookupError(f"node {self.index} has no raylet running")

    def stop(self) -> None:
        """Kill the node at once (SIGKILL to every process of its tree, its workers included) and reap it."""
        pids = self.pids()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(10)
        deadline = time.monotonic() + 10.0
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.05)

    def tail(self, chars: int = 2000) -> str:
        """The end of the node's log (for a failure message)."""
        try:
            return self.log.read_text(errors="replace")[-chars:]
        except OSError:
            return ""


@dataclass
class TwoNodes:
    """A head node and a second node on 127.0.0.1, and this process connected to them as a driver.

    Attributes:
        address: The head's GCS address (``127.0.0.1:<port>``), for ``ray_address``.
        nodes: Head (index 0) and second node (index 1).
        temp_dir: Ray's ``--temp-dir`` of both (removed on close).
        start_s: Seconds from the first ``ray start`` to both nodes alive.
        stopped_at: ``time.monotonic()`` when the second node was last killed.
        dead_after_s: Seconds from that kill until the cluster listed the node dead (seen by ``restart_second``).
    """

    address: str
    nodes: list[RayNode] = field(default_factory=list)
    temp_dir: Path = Path()
    start_s: float = 0.0
    stopped_at: float = 0.0
    dead_after_s: float = 0.0

    @property
    def head(self) -> RayNode:
        """The head node (index 0)."""
        return self.nodes[0]

    @property
    def second(self) -> RayNode:
        """The second node (index 1)."""
        return self.nodes[1]

    def stop_second(self) -> None:
        """Kill the second node's raylet, agents and workers (a machine that dies); the head goes on."""
        self.second.stop()
        self.stopped_at = time.monotonic()

    def restart_second(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Start the second node anew (a new node id) unless it runs; wait until the cluster sees it alive.

        The cluster must first have marked the killed node dead (``dead_after_s``): until then both would
        offer ``agentsim_node_1`` and a shard could be sent to the dead one.
        """
        if self.second.proc.poll() is None:
            return
        import ray

        deadline = time.monotonic() + timeout_s
        while any(n["NodeID"] == self.second.node_id and n["Alive"] for n in ray.nodes()):
            if time.monotonic() > deadline:
                raise RuntimeError(f"the killed node was not marked dead within {timeout_s:g} s")
            time.sleep(0.1)
        self.dead_after_s = time.monotonic() - self.stopped_at
        self.nodes[1] = _start_node(1, ["--address", self.address], self.temp_dir)
        _wait_alive(self, deadline)

    def close(self) -> None:
        """Disconnect this process and kill both nodes (nothing else: no ``ray stop``)."""
        ray = sys.modules.get("ray")
        if ray is not None and ray.is_initialized():
            ray.shutdown()
        for node in reversed(self.nodes):
            node.stop()
        shutil.rmtree(self.temp_dir, ignore_errors=True)


def _start_node(index: int, args: list[str], temp_dir: Path) -> RayNode:
    log = temp_dir / f"node{index}.log"
    env = dict(os.environ)
    # the driver's mode, else off: a local cluster started earlier in this process (ray.init) switched it to
    # token when ~/.ray/auth_token exists, and the nodes then read the same token file
    env.setdefault("RAY_AUTH_MODE", "disabled")
    resources = json.dumps({f"{NODE_RESOURCE}{index}": 8})
    argv = [
        sys.executable,
        "-c",
        _RAY_START,
        "start",
        "--block",
        "--node-ip-address",
        "127.0.0.1",
        "--num-cpus",
        "2",
        "--resources",
        resources,
        "--disable-usage-stats",
        "--temp-dir",
        str(temp_dir),
        *args,
        *_node_ports(),
    ]
    with log.open("wb") as out:
        proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    return RayNode(index, proc, log)


def start_two_nodes(timeout_s: float = START_TIMEOUT_S) -> TwoNodes:
    """Start a head and a second node on loopback, connect this process, wait until both are alive.

    Raises:
        RuntimeError: With the nodes' logs, when they are not both alive within ``timeout_s``.
    """
    ray = pytest.importorskip("ray")
    assert not ray.is_initialized(), "this process is already connected to a Ray cluster"
    port = free_port()
    # short: Ray's unix sockets live under it and their paths are limited to 107 bytes
    temp_dir = Path(tempfile.mkdtemp(prefix="agentsim-ray-", dir="/tmp"))
    two = TwoNodes(f"127.0.0.1:{port}", temp_dir=temp_dir)
    t0 = time.perf_counter()
    try:
        two.nodes.append(
            _start_node(
                0,
                [
                    "--head",
                    "--port",
                    str(port),
                    "--include-dashboard",
                    "false",
                    "--dashboard-port",
                    str(free_port()),
                    "--ray-client-server-port",
                    str(free_port()),
                ],
                temp_dir,
            )
        )
        deadline = time.monotonic() + timeout_s
        while True:  # the second node needs the head's GCS up
            if two.head.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"the head node did not start:\n{two.head.tail()}")
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=1.0):
                break
            time.sleep(0.1)
        two.nodes.append(_start_node(1, ["--address", two.address], temp_dir))
        connect_driver(ray, two.address)
        _wait_alive(two, deadline)
    except BaseException:
        two.close()
        raise
    two.start_s = time.perf_counter() - t0
    return two


def _wait_alive(two: TwoNodes, deadline: float) -> None:
    """Wait until the cluster lists both nodes alive (by their resources); record their node ids.

    Raises:
        RuntimeError: With the nodes' logs, when a node exits or ``deadline`` (``time.monotonic``) passes.
    """
    import ray

    while True:
        alive = {r: n["NodeID"] for n in ray.nodes() if n["Alive"] for r in n["Resources"]}
        ids = [alive.get(f"{NODE_RESOURCE}{n.index}") for n in two.nodes]
        if all(ids):
            break
        if any(n.proc.poll() is not None for n in two.nodes) or time.monotonic() > deadline:
            logs = "\n".join(f"node {n.index}:\n{n.tail()}" for n in two.nodes)
            raise RuntimeError(f"the two Ray nodes are not both alive in time:\n{logs}")
        time.sleep(0.1)
    for node, node_id in zip(two.nodes, ids, strict=True):
        node.node_id = str(node_id)


@pytest.fixture(scope="module")
def two_nodes() -> Iterator[TwoNodes]:
    """Two Ray nodes on loopback for the module, this process their driver; both killed at the end."""
    two = start_two_nodes()
    try:
        yield two
    finally:
        two.close()


def node_of_pid(two: TwoNodes, pid: int) -> int | None:
    """The index of the node whose raylet is the parent of ``pid`` (a worker), or ``None``."""
    try:
        ppid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
    except OSError:
        return None
    for node in two.nodes:
        with contextlib.suppress(LookupError):
            if node.raylet_pid() == ppid:
                return node.index
    return None
