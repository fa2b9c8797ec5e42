"""The Ray cluster the shards run on: joining one by address, or starting a local one on loopback; where each
shard is placed (with ``ray_backend``, the only modules that import Ray: the ``ray`` extra).

Placement: on a cluster given by address, or joined before (``ray.init``), the shards are spread over its nodes
(not on the local cluster this module starts: one node). When nodes offer the custom resources
``agentsim_node_0``, ``agentsim_node_1``, ... (``ray start --resources '{"agentsim_node_<i>": 1}'``), shard k runs
on the node of ``agentsim_node_<k mod n>`` (n: the alive nodes offering one, less those where a shard of this env
died or went silent, so that a shard started anew after its node died lands on a node still alive), asked as a
node affinity; without such nodes Ray's ``"SPREAD"`` strategy places them. ``node_of(k)`` names the node, and
each shard's address (``env.shards``) ends with ``on node <first 12 hex digits of the node id>``. The local
cluster keeps Ray's default placement.

The local cluster listens on loopback only (``start_local_cluster``): Ray binds its gRPC servers (gcs_server,
the raylet's two ports, the driver's and every worker's) to 127.0.0.1 only when the node's address is literally
127.0.0.1, else to every interface, and its runtime-env agent to the node's address. ``ray.init`` replaces a
loopback ``_node_ip_address`` by the machine's outward address unless Ray treats the machine as one that cannot
join a cluster (its macOS and Windows default, ``ray_constants.ENABLE_RAY_CLUSTER``), so that flag is lowered
while the cluster starts. Where a Ray version no longer honours it, the start says in one warning what listens
beyond loopback.
"""

from __future__ import annotations

import contextlib
import importlib
import ipaddress
import logging
import os
import re
import socket
from collections.abc import Iterator
from typing import Any

INSTALL_HINT = "shards need Ray: pip install 'agentsim-env[ray]' (or pip install 'ray>=2.40')"
STARTUP_TIMEOUT_S = 300.0
"""Seconds a shard may take to start (import, kernels) and answer its first reset."""
EXCHANGE_WAIT_S = 60.0
"""Longest wait at one barrier of the exchange (the driver's deadline normally drops a late shard before)."""
_ADDRESS = re.compile(r"^(auto|local|(ray://)?[A-Za-z0-9_.\-]+:\d{1,5})$")
_users = 0  # envs using the local cluster this process started
LOOPBACK = "127.0.0.1"
NODE_RESOURCE = "agentsim_node_"
"""Prefix of the custom resource by which a node offers itself for shard placement (``agentsim_node_<i>``)."""
_NODE_RESOURCE = re.compile(rf"^{NODE_RESOURCE}(\d+)$")
log = logging.getLogger("agentsim_env.distributed")


def import_ray() -> Any:
    """The ``ray`` module, or an ImportError with the install hint."""
    try:
        import ray
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError(INSTALL_HINT) from e
    return ray


def check_reachable(address: str, timeout_s: float = 3.0) -> None:
    """Open a TCP connection to ``host:port`` (Ray itself would retry an unreachable address for minutes).

    Raises:
        ConnectionError: Naming ``ray_address`` and why it cannot be reached.
    """
    if address in ("auto", "local"):
        return
    host, port = address.removeprefix("ray://").rsplit(":", 1)
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as e:
        raise ConnectionError(f"cannot reach the Ray cluster at ray_address={address!r}: {e}") from None


def check_address(address: str) -> str:
    """``address`` when it is ``auto``, ``local``, ``host:port`` or ``ray://host:port``.

    Raises:
        ValueError: Naming ``ray_address`` and the allowed forms.
    """
    if not isinstance(address, str) or not _ADDRESS.match(address.strip()):
        raise ValueError(
            f"ray_address must be 'auto', 'host:port' or 'ray://host:port' (or None for a local "
            f"cluster on 127.0.0.1), got {address!r}"
        )
    return address.strip()


@contextlib.contextmanager
def _loopback_node_address() -> Iterator[None]:
    """While inside, Ray resolves this node's address to loopback instead of the machine's outward address."""
    try:
        constants: Any = importlib.import_module("ray._private.ray_constants")
    except ImportError:  # pragma: no cover - a Ray without the module: start_local_cluster warns
        yield
        return
    if not hasattr(constants, "ENABLE_RAY_CLUSTER"):  # pragma: no cover - as above
        yield
        return
    before = constants.ENABLE_RAY_CLUSTER
    constants.ENABLE_RAY_CLUSTER = False  # read when ray.init resolves the node address, not after
    try:
        yield
    finally:
        constants.ENABLE_RAY_CLUSTER = before


def is_loopback(address: str) -> bool:
    """Whether ``address`` (an IP address or ``localhost``) is a loopback address."""
    if address == "localhost":
        return True
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


def exposed_warning(node_address: str, version: str) -> str | None:
    """The warning for a local cluster whose node address is ``node_address``; ``None`` when it is loopback."""
    if is_loopback(node_address):
        return None
    return (
        f"the local Ray cluster is not on loopback (Ray {version} gave it the node address {node_address}): "
        f"gcs_server, both raylet ports, the driver and every shard worker listen on every interface and the "
        f"runtime-env agent on {node_address}; any machine that reaches them can run code here (firewall "
        f"them, or pass ray_address)"
    )


def start_local_cluster(ray: Any, num_cpus: int) -> str:
    """``ray.init`` a local cluster whose every port listens on loopback (see the module docstring).

    Args:
        ray: The ``ray`` module.
        num_cpus: CPUs the cluster offers.

    Returns:
        The node's address (127.0.0.1; if this Ray version gave it another one, a warning named what listens
        beyond loopback).
    """
    with _loopback_node_address():
        ray.init(
            num_cpus=num_cpus,
            include_dashboard=False,
            _node_ip_address=LOOPBACK,
            logging_level="ERROR",
            log_to_driver=False,
        )
    address = str(ray.util.get_node_ip_address())
    warning = exposed_warning(address, getattr(ray, "__version__", "?"))
    if warning is not None:
        log.warning(warning)
    return address


def connect_driver(ray: Any, address: str) -> None:
    """``ray.init`` this process as a driver of the cluster at ``address``, checked reachable first.

    A cluster on loopback (``127.0.0.1:port``, ``localhost:port``) is joined on loopback: Ray would otherwise
    rewrite the address to the machine's outward one, where nothing of that cluster listens.

    Raises:
        ConnectionError: Naming ``ray_address`` and why it cannot be reached.
    """
    check_reachable(address)
    host = address.removeprefix("ray://").rsplit(":", 1)[0]
    local = _loopback_node_address() if is_loopback(host) else contextlib.nullcontext()
    try:
        with local:
            ray.init(address=address, logging_level="ERROR", log_to_driver=False)
    except Exception as e:  # ray raises ConnectionError, RuntimeError or its own kinds here
        raise ConnectionError(
            f"cannot reach the Ray cluster at ray_address={address!r}: {type(e).__name__}: {e}"
        ) from e


def pinned_nodes(ray: Any) -> list[str]:
    """Ids of the alive nodes offering ``agentsim_node_<i>``, ordered by i (empty when none does)."""
    found = []
    for node in ray.nodes():
        if not node.get("Alive"):
            continue
        for resource in node.get("Resources", {}):
            m = _NODE_RESOURCE.match(resource)
            if m:
                found.append((int(m.group(1)), str(node["NodeID"])))
                break
    return [node_id for _, node_id in sorted(found)]


class OnNode:
    """Mixed into an actor class: ``node()`` answers the id of the Ray node the actor runs on."""

    def node(self) -> str:
        """The id (hex) of the Ray node this actor runs on."""
        return str(import_ray().get_runtime_context().get_node_id())


class Placement:
    """Where shard actors start on a cluster, and which node each one runs on (see the module docstring).

    Args:
        ray: The ``ray`` module (connected).
        spread: Place the shards on different nodes; ``False`` keeps Ray's default placement.
    """

    def __init__(self, ray: Any, spread: bool) -> None:
        self._ray = ray
        self.spread = bool(spread)
        self._nodes: dict[int, Any] = {}  # shard -> the reference of its answer to ``node()``
        self._avoid: set[str] = set()  # nodes where a shard died or went silent

    def start(self, k: int, remote_cls: Any, *args: Any) -> Any:
        """Start shard ``k`` as ``remote_cls.remote(*args)`` (an ``OnNode`` actor class) where it belongs."""
        if not self.spread:
            actor = remote_cls.remote(*args)
        else:
            # read at every start, minus the nodes where a shard failed: Ray marks a node dead only after it
            # misses its health checks (about 15 s here), and an actor sent there meanwhile dies with it
            nodes = [n for n in pinned_nodes(self._ray) if n not in self._avoid]
            strategy: Any = "SPREAD"
            if nodes:
                from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

                # hard: Ray 2.60 let a soft affinity fall back to another node although the target was alive
                strategy = NodeAffinitySchedulingStrategy(nodes[k % len(nodes)], soft=False)
            actor = remote_cls.options(scheduling_strategy=strategy).remote(*args)
        self._nodes[k] = actor.node.remote()  # answered before the shard's first call
        return actor

    def node_of(self, k: int, timeout_s: float = STARTUP_TIMEOUT_S) -> str:
        """The id (hex) of the Ray node shard ``k`` runs on (or last ran on); ``""`` when it never said."""
        try:
            return str(self._ray.get(self._nodes[k], timeout=timeout_s))
        except Exception:  # it died (or is still starting after timeout_s): unknown
            return ""

    def failed(self, k: int) -> None:
        """Shard ``k`` died or went silent: later starts avoid its node (when it is known)."""
        node = self.node_of(k, timeout_s=0.0)
        if node:
            self._avoid.add(node)


def join_cluster(ray: Any, address: str | None, n_shards: int) -> bool:
    """Join the Ray cluster at ``address``, or start a local one on 127.0.0.1 (``None``), unless joined already.

    Returns:
        Whether this env counts as a user of the local cluster this process started (``leave_cluster`` stops it
        when its last user leaves).

    Raises:
        ConnectionError: When the cluster at ``address`` cannot be reached.
    """
    global _users
    if address is not None:
        address = check_address(address)
    if not ray.is_initialized():
        if address is None:
            start_local_cluster(ray, num_cpus=max(os.cpu_count() or 1, n_shards))
            _users += 1
            return True
        connect_driver(ray, address)
        return False
    if _users:
        _users += 1
        return True
    return False


def leave_cluster(ray: Any, user: bool) -> None:
    """One user of the local cluster leaves (``user`` from ``join_cluster``); the last one shuts it down."""
    global _users
    if user:
        _users -= 1
        if _users == 0 and ray.is_initialized():
            ray.shutdown()
