"""Shards as Ray actors: the only module of the project that imports Ray (the ``ray`` extra).

``RayShards`` starts one actor per shard on a Ray cluster (a local one bound to 127.0.0.1 when no address is
given, started here, stopped when the last env using it closes; or the cluster at ``ray_address``) and the
exchange the shards meet at during a step (``distributed.exchange.ExchangeActor``, an asyncio actor using no CPU,
next to the driver; each shard posts to it over one TCP connection, ``distributed.wire``, with a token the driver
makes). A call runs on every shard at once; ``ray.wait`` bounds it by the deadline, so a step never
hangs on a dead or slow machine: a shard that misses it is killed and reported as a
:class:`~agentsim_env.distributed.backends.Failure`, as is one whose process died, and one whose code raised (its
actor is killed: its state is unknown after it); each is dropped from the exchange at once, so the others finish
their step.

When this process has already called ``ray.init`` (a test's cluster, a trainer's), the shards join that cluster
and ``ray_address`` is not used.

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
import secrets
import socket
import time
from collections.abc import Iterator
from typing import Any

import numpy as np

import agentsim_env.distributed.obs_shm as obs_shm
from agentsim_env.distributed.backends import Failure, raised
from agentsim_env.distributed.bridge import Bridge, Packed
from agentsim_env.distributed.exchange import ExchangeActor
from agentsim_env.distributed.obs_shm import ObsSegment, ObsWriter, RowReader, RowSegment, reply_layouts
from agentsim_env.distributed.partition import Strips
from agentsim_env.distributed.shard import Shard as _Shard
from agentsim_env.distributed.wire import TOKEN_BYTES, WireClient

INSTALL_HINT = "shards need Ray: pip install 'agentsim-env[ray]' (or pip install 'ray>=2.40')"
STARTUP_TIMEOUT_S = 300.0
EXCHANGE_WAIT_S = 60.0
"""Longest wait at one barrier of the exchange (the driver's deadline normally drops a late shard before)."""
"""Seconds a shard may take to start (import, kernels) and answer its first reset."""
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


class Shard(OnNode):
    """A ``Shard`` in a Ray actor, posting to the exchange over its TCP connection (``distributed.wire``); its
    address also names the Ray node it runs on."""

    def __init__(
        self,
        index: int,
        name: str,
        config: dict[str, Any],
        strips: Strips,
        wire: tuple[str, int, bytes],
        wait_s: float,
    ) -> None:
        host, port, token = wire
        self.wire = WireClient(host, port, token, index, wait_s)
        self.worker = _Shard(index, name, config, strips, self.wire.swap)
        self.obs: ObsWriter | None = None
        self.worker.address = f"{self.worker.address} on node {self.node()[:12]}"

    def attach_rows(
        self,
        node: str,
        obs: tuple[str, int, int, int],
        act: tuple[str, int, int, Any],
        reply: tuple[tuple[str, int, int, Any], tuple[str, int, int, Any]],
    ) -> bool:
        """Read the step API's actions from and write its observation rows and per-agent reply rows into region
        ``index`` of the driver's segments (``distributed.obs_shm``: ``obs`` = name, shards, slots, row length;
        ``act`` and each of ``reply`` = name, shards, slots, layout) when this actor runs on the driver's node
        ``node``; whether it does."""
        if node != self.node():
            return False
        k = self.worker.index
        for old in (self.obs, self.worker.act_in, *(self.worker.reply_out or ())):
            if old is not None:
                old.close()
        self.obs = ObsWriter(obs[0], k, *obs[1:])
        self.worker.obs_out, self.worker.obs_full = self.obs.array, self.obs.full
        self.worker.act_in = RowReader(act[0], k, act[1], act[2], tuple(tuple(p) for p in act[3]))
        acted, own = (RowReader(r[0], k, r[1], r[2], tuple(tuple(p) for p in r[3]), "reply") for r in reply)
        self.worker.reply_out = (acted, own)
        return True

    def reset(self, *args: Any) -> Packed:
        """``Shard.reset``."""
        return self.worker.reset(*args)

    def step(self, *args: Any) -> Packed:
        """``Shard.step``."""
        return self.worker.step(*args)

    def begin(self, *args: Any) -> Packed:
        """``Shard.begin``."""
        return self.worker.begin(*args)

    def act(self, *args: Any) -> Packed:
        """``Shard.act``."""
        return self.worker.act(*args)

    def finish(self) -> Packed:
        """``Shard.finish``."""
        return self.worker.finish()

    def send(self, *args: Any) -> Packed:
        """``Shard.send``."""
        return self.worker.send(*args)

    def assign_group(self, *args: Any) -> Packed:
        """``Shard.assign_group``."""
        return self.worker.assign_group(*args)

    def set_delay(self, delay_s: float) -> None:
        """``Shard.set_delay``."""
        self.worker.set_delay(delay_s)


class RayShards:
    """K worker actors and their exchange on a Ray cluster.

    Args:
        name: Scenario name.
        config: The scenario's config fields.
        strips: The partition.
        n_shards: Number of workers K.
        address: Cluster address, or ``None`` for a local cluster on 127.0.0.1.
        bridge: The routing the exchange runs.
        spread: Place the workers on different nodes (``ray_backend.Placement``); ``None``: unless the cluster
            is the local one this process started.
    """

    def __init__(
        self,
        name: str,
        config: dict[str, Any],
        strips: Strips,
        n_shards: int,
        address: str | None,
        bridge: Bridge,
        spread: bool | None = None,
    ) -> None:
        ray = import_ray()
        self.n_shards = int(n_shards)
        self._ray = ray
        self._own = join_cluster(ray, address, self.n_shards)
        self._cls = ray.remote(num_cpus=1 if address is not None else 0, max_restarts=0)(Shard)
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=False)
        self.exchange = (
            ray.remote(num_cpus=0, max_restarts=0)(ExchangeActor)
            .options(scheduling_strategy=here)
            .remote(bridge, self.n_shards, EXCHANGE_WAIT_S)
        )  # next to the driver
        # the barriers' data path (``distributed.wire``): on loopback for the local cluster, else on the driver
        # node's address, where Ray's own ports are
        host = LOOPBACK if self._own else str(ray.util.get_node_ip_address())
        token = secrets.token_bytes(TOKEN_BYTES)
        self.wire = (host, int(ray.get(self.exchange.serve.remote(host, token))), token)
        self.placement = Placement(ray, not self._own if spread is None else bool(spread))
        self._args = (name, config, strips)
        self.actors: dict[int, Any] = {k: self._start(k) for k in range(self.n_shards)}
        self.address = address or "local cluster on 127.0.0.1"
        self.obs_segment: ObsSegment | None = None
        self.act_segment: RowSegment | None = None
        self.reply_segments: tuple[RowSegment, RowSegment] | None = None
        self._shm_warned = False
        self.shared: dict[int, bool] = {}
        """Which workers take their actions from ``act_segment`` and write their observation rows into
        ``obs_segment`` (those on the driver's node)."""

    def share_rows(
        self, n_slots: int, obs_dim: int, act_layout: tuple[tuple[str, int, str], ...], n_info: int = 0
    ) -> None:
        """Workers on the driver's node exchange the step API's actions, observation rows and per-agent reply
        rows (``n_info``: the scenario's info keys) through shared-memory segments (``distributed.obs_shm``)
        instead of Ray's object store; the others keep Ray."""
        need = obs_shm.rows_bytes(n_slots, obs_dim, act_layout, n_info)
        room = obs_shm.shm_room()
        if self.obs_segment is None and room is not None and 2 * need > room:  # a full /dev/shm kills its writer
            if not self._shm_warned:
                log.warning(
                    "%s holds %d MB free, the step API's shared rows need about %d MB (twice that kept free): "
                    "their rows go through Ray's object store instead (slower; a larger /dev/shm, e.g. docker "
                    "--shm-size, brings them back)",
                    obs_shm.SHM_DIR,
                    room >> 20,
                    need >> 20,
                )
                self._shm_warned = True
            self.shared = dict.fromkeys(self.actors, False)
            return
        if self.obs_segment is None or self.act_segment is None or self.reply_segments is None:
            self._close_segments()
            self.obs_segment = ObsSegment(self.n_shards, n_slots, obs_dim)
            self.act_segment = RowSegment(self.n_shards, n_slots, act_layout)
            acted, own = reply_layouts(n_info)
            self.reply_segments = (
                RowSegment(self.n_shards, n_slots, acted, "acted"),
                RowSegment(self.n_shards, n_slots, own, "own"),
            )
        for k in self.actors:
            if k not in self.shared:
                self._attach_rows(k)

    def _close_segments(self) -> None:
        for seg in (self.obs_segment, self.act_segment, *(self.reply_segments or ())):
            if seg is not None:
                seg.close()
        self.obs_segment, self.act_segment, self.reply_segments = None, None, None

    def _attach_rows(self, k: int) -> None:
        obs, act, reply = self.obs_segment, self.act_segment, self.reply_segments
        assert obs is not None and act is not None and reply is not None
        here = str(self._ray.get_runtime_context().get_node_id())
        ref = self.actors[k].attach_rows.remote(
            here,
            (obs.name, obs.n_shards, obs.n_slots, obs.obs_dim),
            (act.name, act.n_shards, act.n_slots, act.layout),
            tuple((r.name, r.n_shards, r.n_slots, r.layout) for r in reply),
        )
        try:
            self.shared[k] = bool(self._ray.get(ref, timeout=STARTUP_TIMEOUT_S))
        except Exception:  # a worker that cannot map them uses Ray (a dead one fails its next call)
            self.shared[k] = False

    def write_actions(self, k: int, slots: Any, parts: dict[str, Any]) -> int | None:
        """Worker ``k``'s acting slots and action rows into its region of the action segment: their count, or
        None when the worker does not share (its call then carries them)."""
        if self.act_segment is None or not self.shared.get(k):
            return None
        return self.act_segment.write(k, slots, parts)

    def reply_rows(self, k: int, reply: Packed) -> None:
        """Worker ``k``'s per-agent reply rows, written into its regions of the reply segments, into ``reply``
        as the keys a reply through Ray carries (views: read them before the worker's next call)."""
        if self.reply_segments is None or not self.shared.get(k):
            raise RuntimeError(f"shard {k} does not share its reply rows")
        acted, own = self.reply_segments
        slots, cols = acted.rows(k, int(reply.pop("rows_n")))
        reply["slots"], reply["rewards"], reply["terminated"] = slots, cols["rewards"][:, 0], cols["terminated"][:, 0]
        reply["info"] = {
            key: cols[f"info{i}"][:, 0].astype(np.dtype(dt), copy=False)
            for i, (key, dt) in enumerate(reply.pop("info_dtypes"))
        }
        mine, kin = own.rows(k, int(reply.pop("own_n")))
        reply["own"] = mine
        if reply.pop("own_kin"):
            reply["pos"], reply["vel"] = kin["pos"], kin["vel"]
            reply["heading"], reply["online"] = kin["heading"][:, 0], kin["online"][:, 0]

    def obs_rows(self, k: int, n: int) -> Any:
        """The ``n`` observation rows worker ``k`` wrote into the segment in its latest call (a view)."""
        if self.obs_segment is None or not self.shared.get(k):
            raise RuntimeError(f"shard {k} does not share its observation rows")
        return self.obs_segment.rows(k, n)

    def obs_buffer(self, avoid: Any = None) -> Any:
        """An array of every slot's observation row in the observation segment that no one else holds and that is
        not ``avoid`` (``ObsSegment.free_full``): a step given it has the workers beside the driver write their
        rows straight there; None when there is none."""
        return None if self.obs_segment is None else self.obs_segment.free_full(avoid)

    def full_index(self, out: Any) -> int:
        """Which of the segment's full arrays ``out`` is (-1: none)."""
        return -1 if self.obs_segment is None else self.obs_segment.full_index(out)

    def retire(self, b: int) -> None:
        """Never hand full array ``b`` out again (a worker lost while it may have been writing into it)."""
        if self.obs_segment is not None:
            self.obs_segment.retired.add(int(b))

    def _start(self, k: int) -> Any:
        name, config, strips = self._args
        return self.placement.start(k, self._cls, k, name, config, strips, self.wire, EXCHANGE_WAIT_S + 30.0)

    def node_of(self, k: int) -> str:
        """The id (hex) of the Ray node worker ``k`` runs on (or last ran on); ``""`` when it never said."""
        return self.placement.node_of(k)

    def _drop(self, k: int) -> None:
        self._ray.get(self.exchange.drop.remote(k))

    def call(
        self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float, on_reply: Any = None
    ) -> dict[int, Packed | Failure]:
        """Run ``method`` on every named worker at once; a reply or a ``Failure`` per worker. ``on_reply(k, reply)``
        is called with each reply (not with failures) as it comes in, while slower workers still run."""
        ray = self._ray
        if method == "reset":
            timeout_s = max(timeout_s, STARTUP_TIMEOUT_S)
        refs = {getattr(self.actors[k], method).remote(*args): k for k, args in calls.items()}
        out: dict[int, Packed | Failure] = {}
        pending = list(refs)
        deadline = time.monotonic() + timeout_s
        while pending:
            ready, pending = ray.wait(pending, num_returns=1, timeout=max(0.0, deadline - time.monotonic()))
            if not ready:
                break
            for ref in ready:
                got = out[refs[ref]] = self._answer(ref, refs[ref])
                if on_reply is not None and not isinstance(got, Failure):
                    on_reply(refs[ref], got)
        if pending:  # late: the ones not waiting at the exchange are killed and dropped; the others then finish
            waiting = ray.get(self.exchange.waiting.remote())
            late = [ref for ref in pending if refs[ref] not in waiting] or pending
            for ref in late:
                k = refs[ref]
                self.placement.failed(k)
                self.kill(k)
                out[k] = Failure(f"missed the {timeout_s:g} s deadline of {method}")
            rest = [ref for ref in pending if ref not in late]
            if rest:
                out.update(self.call_rest(rest, refs, timeout_s))
        return out

    def _answer(self, ref: Any, k: int) -> Packed | Failure:
        """Worker ``k``'s reply, or its failure (a dead one is dropped, one that raised is killed and dropped)."""
        ray = self._ray
        try:
            return dict(ray.get(ref))
        except ray.exceptions.RayActorError as e:
            self.placement.failed(k)
            self._drop(k)
            return Failure(f"died: {type(e).__name__}")
        except ray.exceptions.RayTaskError as e:
            self.kill(k)
            return raised(e.cause if isinstance(e.cause, BaseException) else e)

    def call_rest(self, pending: list[Any], refs: dict[Any, int], timeout_s: float) -> dict[int, Packed | Failure]:
        """The answers of the calls that waited at the exchange for a late shard (one more deadline)."""
        ray, out = self._ray, {}
        done, late = ray.wait(pending, num_returns=len(pending), timeout=timeout_s)
        for ref in done:
            out[refs[ref]] = self._answer(ref, refs[ref])
        for ref in late:
            k = refs[ref]
            self.kill(k)
            out[k] = Failure(f"missed the {timeout_s:g} s deadline")
        return out

    def restart(self, index: int) -> None:
        """A new actor for worker ``index`` (the old one is killed if it still runs)."""
        self.kill(index)
        self.actors[index] = self._start(index)
        self._ray.get(self.exchange.revive.remote(index))
        if self.obs_segment is not None:
            self._attach_rows(index)

    def kill(self, index: int) -> None:
        """Kill worker ``index``'s actor at once and drop it from the exchange."""
        try:
            self._ray.kill(self.actors[index], no_restart=True)
        except Exception:  # already gone
            pass
        self.shared.pop(index, None)
        self._drop(index)

    def set_delay(self, index: int, delay_s: float) -> None:
        """Test hook: worker ``index`` sleeps ``delay_s`` in every call."""
        self._ray.get(self.actors[index].set_delay.remote(delay_s))

    def set_owner(self, owner: Any) -> None:
        """The shard owning each strip (for the exchange's routing)."""
        self._ray.get(self.exchange.set_owner.remote(owner))

    def set_slot_owner(self, owner: Any) -> None:
        """The shard owning each slot (for routing bus messages)."""
        self._ray.get(self.exchange.set_slot_owner.remote(owner))

    def exchange_bytes(self) -> dict[str, int]:
        """The bytes the exchange routed since the previous call, by phase."""
        return dict(self._ray.get(self.exchange.take_bytes.remote()))

    def close(self) -> None:
        """Kill every actor and the exchange; stop the local cluster when no other env uses it."""
        for k in list(self.actors):
            try:
                self._ray.kill(self.actors[k], no_restart=True)
            except Exception:  # already gone
                pass
        self.actors = {}
        try:
            self._ray.kill(self.exchange, no_restart=True)
        except Exception:  # already gone
            pass
        self._close_segments()
        self.shared = {}
        leave_cluster(self._ray, self._own)
        self._own = False
