"""One world over shards that step themselves: speed-up over one process, the coordinator's share, the bytes.

``navigation`` with the full-stack comms config of ``bench_comms`` (collisions off, so the population stays
constant), "full" traffic (every agent sends one message every step, a quarter of them overlay floods with hop
limit 2, as in ``bench_comms``). The actions come from a fixed cycle of ``bench_comms`` action arrays, played by a
row policy (``Cycle``): the same actions in every system, so the results can be compared.

Tables:

a. 100,000 and 200,000 agents: one process vs 2 shards on Ray (a local cluster on 127.0.0.1), through
   ``env.rollout`` (the policy runs inside the shards, only counts come back) and through the step API (the array
   front end ``BatchedEnv`` / ``DistributedBatchedEnv``, which gathers every agent's observation). Wall ms per step,
   env-steps/s, the speed-up, each shard's busy time (its call minus its waits at the exchange), the exchange
   (waits, routing, transfers), the coordinator's share of the step (the step's wall time outside the slowest
   shard's call: the coordinator's own work and the calls' overhead) and the bytes per step between processes
   (between shards through the exchange; coordinator calls apart). The rollout rows also say whether the results
   (returns, final positions, events) equal one process's.
b. Bytes per step against the number of agents near the strip edge (2 shards, ``backend="local"``: the bytes do
   not depend on the backend): the halo grows with the map side, i.e. with sqrt(N) at fixed density.
c. On paper: 1,000,000 agents on 16 machines, from the measurements of table a (assumptions printed).

Timing is wall time (the shards run in other processes); on a shared machine the numbers move with its load.
Ray is started once for the whole run and stopped at the end; without Ray the Ray rows are skipped.

Run: ``python benchmarks/bench_distributed.py [--quick]``.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import fmt_num, machine_description, markdown_table  # noqa: E402, I001

import numpy as np  # noqa: E402  (after common: it pins the thread pools before numpy loads)

import bench_comms as bc  # noqa: E402

SHARD_TIMEOUT_S = 120.0  # per call: a loaded shared machine must not declare a slow shard offline mid-benchmark
GHOST_BYTES = 80  # a ghost: its int64 slot id, x and 3 float64 coordinates, posted by its shard and routed on
TRAFFIC = ("full", "silent")


def _bytes(x: float) -> str:
    """A byte count for a table cell (a mean over steps, rounded to a whole byte)."""
    return f"{x:,.0f}"


def config(n: int) -> dict[str, Any]:
    """The scenario config of ``bench_comms`` with comms on (collisions off, heartbeats, groups of 8)."""
    return bc._config(n, True)


def actions(n: int, traffic: str) -> list[np.ndarray]:
    """``bc.CYCLE`` action arrays ``(1, n, 10)``; ``"silent"``: the comm channel is "none" for every agent."""
    acts = bc._actions(n, True, np.random.default_rng(0))
    if traffic == "silent":
        for a in acts:
            a[:, 3] = -1.0  # the first comm column: channel bin "none"
    return [a[None] for a in acts]


def start_ray() -> Any:
    """Start a local Ray cluster for the whole run (the shards join it), or ``None`` when Ray is not installed.

    Started here rather than by the first env, so that closing an env does not stop it (and the next env does
    not pay the start again). The options are those of ``agentsim_env.distributed.ray_backend``.
    """
    from agentsim_env.distributed.ray_backend import import_ray

    try:
        ray = import_ray()
    except ImportError:
        return None
    if not ray.is_initialized():
        ray.init(
            num_cpus=max(os.cpu_count() or 1, 2),
            include_dashboard=False,
            _node_ip_address="127.0.0.1",
            logging_level="ERROR",
            log_to_driver=False,
        )
    return ray


class Cycle:
    """A row policy that plays a fixed cycle of action arrays ``(n, act_dim)``: row ``slot`` of array ``step``."""

    def __init__(self, acts: list[np.ndarray], parts: dict[str, Any]) -> None:
        self.acts = [np.asarray(a).reshape(a.shape[-2], a.shape[-1]) for a in acts]
        self.parts = [(k, p.size, tuple(p.shape)) for k, p in parts.items()]

    def reset(self, seed: int | None = None) -> None:
        """Nothing to reset: the cycle depends on the step only."""

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The rows ``slots`` of the cycle's array for ``step``, split into the action parts."""
        a = self.acts[step % len(self.acts)][slots]
        out, c = {}, 0
        for key, size, shape in self.parts:
            out[key] = a[:, c : c + size].reshape(len(slots), *shape)
            c += size
        return out


def build(n: int, shards: int | None, backend: str = "ray", api: str = "step") -> Any:
    """One process (``shards=None``) or ``shards`` shards on ``backend``, as the ParallelEnv (``api="rollout"``)
    or the array front end (``api="step"``, reset with seed 0)."""
    if api == "rollout":
        if shards is None:
            import agentsim_env

            return agentsim_env.make("navigation", **config(n))
        from agentsim_env.distributed import make

        return make("navigation", shards=shards, backend=backend, timeout_s=SHARD_TIMEOUT_S, **config(n))
    if shards is None:
        from agentsim_env.env.vector import BatchedEnv

        env = BatchedEnv("navigation", 1, **config(n))
    else:
        from agentsim_env.distributed import DistributedBatchedEnv

        env = DistributedBatchedEnv("navigation", shards, backend=backend, timeout_s=SHARD_TIMEOUT_S, **config(n))
    env.reset(seed=0)
    return env


def close(env: Any) -> None:
    """Stop the shards (if any) and free the worlds before the next system is built."""
    if hasattr(env, "coordinator"):
        env.close()
    del env
    gc.collect()


def _shard_times(env: Any) -> dict[str, float]:
    """Per step, the first one left out (as the rollout's time): the step call's wall time, the slowest shard's
    call, its busy part (without exchange waits) and the mean exchange time."""
    steps = env.coordinator.profile["steps"][1:]
    wall = np.array([s[0] for s in steps]) * 1e3
    call = np.array([s[1] for s in steps]) * 1e3
    wait = np.array([s[2] for s in steps]) * 1e3
    return {
        "call_wall_ms": float(wall.mean()),
        "max_call_ms": float(call.max(axis=1).mean()),
        "busy_ms": float((call - wait).max(axis=1).mean()),
        "wait_ms": float(wait.mean()),
    }


def run_rollout(n: int, shards: int | None, traffic: str, steps: int, backend: str = "ray") -> dict[str, Any]:
    """``env.rollout`` of the action cycle after a 2-step warm-up rollout: wall ms per step, the mean over steps 2..
    ``steps`` (the reset and the first step left out, the same way for every system: one process times its steps
    with an ``on_step`` observer that only reads the clock, the shards with the coordinator's per-step profile, which
    times each step's call to the shards)."""
    env = build(n, shards, backend, api="rollout")
    policy = Cycle(actions(n, traffic), env.scenario.act_parts())
    env.rollout(policy, 2, seed=0)
    stamps: list[float] = []

    def clock(env: Any, taken: int, view: Any) -> bool:
        stamps.append(time.perf_counter())
        return False

    res = env.rollout(policy, steps, seed=0, on_step=clock if shards is None else None)
    out: dict[str, Any] = {"result": res}
    if shards is None:
        out["step_ms"] = float(np.mean(np.diff(stamps[1:]))) * 1e3  # stamps: after the reset, then each step
    else:
        out.update(_shard_times(env))
        out["step_ms"] = out["call_wall_ms"]
        # the coordinator's part of a step call: its wall time outside the slowest shard's call
        out["coord_ms"] = max(0.0, out["call_wall_ms"] - out["max_call_ms"])
        tr = env.coordinator.traffic
        out["bytes"], out["calls_bytes"] = tr.between_shards, tr.actions + tr.replies
    close(env)
    return out


def run_steps(n: int, shards: int | None, traffic: str, steps: int, backend: str = "ray") -> dict[str, Any]:
    """The step API: 1 warm-up step, then ``steps`` timed steps; medians."""
    env = build(n, shards, backend, api="step")
    acts = actions(n, traffic)
    env.step(acts[0])
    rec: dict[str, list[float]] = {
        k: [] for k in ("step_ms", "max_call_ms", "busy_ms", "wait_ms", "bytes", "calls_bytes")
    }
    for i in range(1, steps + 1):
        t0 = time.perf_counter()
        env.step(acts[i % bc.CYCLE])
        rec["step_ms"].append((time.perf_counter() - t0) * 1e3)
        if shards is not None:
            live = [s for s in env.shards if s.alive]
            rec["max_call_ms"].append(max(s.step_s for s in live) * 1e3)
            rec["busy_ms"].append(max((s.step_s - s.wait_s) for s in live) * 1e3)
            rec["wait_ms"].append(float(np.mean([s.wait_s for s in live])) * 1e3)
            tr = env.coordinator.traffic
            rec["bytes"].append(tr.between_shards)
            rec["calls_bytes"].append(tr.actions + tr.replies)
    out = {k: float(np.median(v)) for k, v in rec.items() if v}
    if shards is not None:
        out["coord_ms"] = out["step_ms"] - out["max_call_ms"]
    close(env)
    return out


def stage_table(n: int, steps: int, ray: Any) -> str:
    """Where a shard's step goes: each stage of a 2-shard rollout against half of the same stage in one process
    (``shard_stages``)."""
    import tempfile

    import shard_stages as ss

    ray.cloudpickle.register_pickle_by_value(ss)  # the shards build the timed policy from this module's code
    acts = actions(n, "full")
    env = build(n, None, api="rollout")
    env.rollout(Cycle(acts, env.scenario.act_parts()), 2, seed=0)  # compiles, as the shards' warm-up below
    stamps: list[float] = []

    def clock(env: Any, taken: int, view: Any) -> bool:
        stamps.append(time.perf_counter())
        return False

    ss.install(ss.all_targets(1))
    try:
        env.rollout(Cycle(acts, env.scenario.act_parts()), steps, seed=0, on_step=clock)
        one = ss.per_step_ms(dict(ss._RECORD), 1)
    finally:
        ss.uninstall()
        close(env)
    step_one = float(np.mean(np.diff(stamps[2:]))) * 1e3
    with tempfile.TemporaryDirectory() as folder:
        env = build(n, 2, "ray", "rollout")
        try:
            env.rollout(Cycle(acts, env.scenario.act_parts()), 2, seed=0)
            env.rollout(ss.TimedCycle(Cycle(acts, env.scenario.act_parts()), folder), steps, seed=0)
            wait = _shard_times(env)["wait_ms"]
        finally:
            close(env)
        shards = [ss.per_step_ms(r, 1) for r in ss.read_shards(folder)]
    rows = ss.table_rows(one, step_one, shards, wait)
    return markdown_table(["stage", "one process ms", "half of it", "each shard ms", "slowest shard - half"], rows)


def same_result(a: Any, b: Any) -> bool:
    """Whether two rollouts ended with the same returns, final positions and events."""
    return bool(
        np.array_equal(a.returns, b.returns)
        and np.array_equal(a.final_pos, b.final_pos)
        and a.events == b.events
        and a.steps == b.steps
    )


def speed_table(sizes: list[int], steps: int, ray: Any) -> tuple[str, dict[tuple[int, str, str], dict[str, Any]]]:
    """Table a and its measurements by (agents, API, system)."""
    res: dict[tuple[int, str, str], dict[str, Any]] = {}
    for n in sizes:
        for api, run in (("rollout", run_rollout), ("step API", run_steps)):
            res[n, api, "one process"] = run(n, None, "full", steps)
            if ray is not None:
                res[n, api, "2 shards (Ray)"] = run(n, 2, "full", steps)
    rows = []
    for (n, api, system), r in res.items():
        base = res[n, api, "one process"]
        sharded = system != "one process"
        same = "-"
        if api == "rollout" and sharded:
            same = "yes" if same_result(base["result"], r["result"]) else "NO"
        rows.append(
            [
                fmt_num(n),
                api,
                system,
                fmt_num(r["step_ms"]),
                fmt_num(1e3 / r["step_ms"]),
                f"{base['step_ms'] / r['step_ms']:.2f}",
                fmt_num(r["busy_ms"]) if sharded else "-",
                fmt_num(r["wait_ms"]) if sharded else "-",
                f"{100 * r['coord_ms'] / r.get('call_wall_ms', r['step_ms']):.1f} %" if sharded else "-",
                _bytes(r["bytes"]) if sharded else "-",
                _bytes(r["calls_bytes"]) if sharded else "-",
                same,
            ]
        )
    table = markdown_table(
        [
            "agents",
            "API",
            "system",
            "ms/step",
            "env-steps/s",
            "speed-up",
            "slowest shard busy ms",
            "exchange ms",
            "coordinator share",
            "bytes/step between shards",
            "bytes/step coordinator calls",
            "same results",
        ],
        rows,
    )
    return table, res


FIXED_MS_PER_SLOT = 45.0 / 100_000
"""A shard's work that does not shrink with its share of the agents (kernels over its full-length slot arrays),
per slot of the world: ~45 ms at 100,000 slots in a shard's profile."""
LINK_BYTES_S = 1.25e9
"""A 10 Gb/s link."""
PAPER_N, PAPER_K = 1_000_000, 16


def paper_table(
    res: dict[tuple[int, str, str], dict[str, Any]],
    n_ref: int,
    floor: dict[str, float],
    by_k: dict[int, dict[str, float]],
    n_small: int,
) -> str:
    """Table f: 1,000,000 agents on 16 machines from this run's measurements (see ``main`` for the assumptions)."""
    one = res[n_ref, "rollout", "one process"]
    two = res[n_ref, "rollout", "2 shards (Ray)"]
    n, k = PAPER_N, PAPER_K
    one_ms = one["step_ms"] * n / n_ref  # one process linear in N (measured: a little worse than linear)
    per_agent = (two["busy_ms"] - FIXED_MS_PER_SLOT * n_ref) / (n_ref / 2)  # ms per own agent of a shard
    own = per_agent * n / k * 1.08  # + 8 % ghosts at 16 strips of a 1,000,000-agent map
    wire = "TCP connection per shard (today)"
    barriers = floor[wire]  # the barriers' latency a step, measured with no simulation (2 shards, loopback)
    hub_cpu_per_byte = floor[wire + " cpu"] / two["bytes"]  # the exchange's CPU per byte it routes
    kk = max(by_k)
    # bytes a step through the exchange at K shards: the phases at strip edges grow with the edge (sqrt(N)), the
    # bus, the far senders' positions and the group sums with N
    b = by_k[kk]
    edge = sum(b[f] for f in ("halo", "handover", "offline"))
    hub_bytes = edge * np.sqrt(n / n_small) + (b["total"] - edge) * n / n_small
    coord = two["coord_ms"] * k / 2  # the coordinator's calls grow with the number of shards
    rows = []
    for label, fixed, peer in (
        ("full-length slot arrays, one exchange (today)", FIXED_MS_PER_SLOT * n, False),
        ("compact shard worlds, one exchange", 0.0, False),
        ("compact shard worlds, shards exchange directly", 0.0, True),
    ):
        busy = own + fixed
        # one exchange routes every byte on one CPU and one link; shards exchanging directly split both K ways
        route = hub_bytes * hub_cpu_per_byte / (k if peer else 1)
        link = hub_bytes / LINK_BYTES_S * 1e3 / (k if peer else 1)
        step = busy + barriers + route + link + coord
        rows.append(
            [
                label,
                fmt_num(one_ms),
                fmt_num(busy),
                fmt_num(barriers),
                _bytes(hub_bytes / (k if peer else 1)),
                fmt_num(route),
                fmt_num(link),
                fmt_num(coord),
                fmt_num(step),
                f"{one_ms / step:.1f}x",
            ]
        )
    return markdown_table(
        [
            "shards hold, exchange",
            "one process ms",
            "shard busy ms",
            "barriers ms",
            "bytes / step on the busiest link",
            "routing ms",
            "link ms",
            "coordinator ms",
            "step ms",
            "vs one process",
        ],
        rows,
    )


def record_posts(n: int, steps: int) -> tuple[Any, dict[int, list[tuple[str, Any]]]]:
    """Every post of a 2-shard rollout of ``steps`` steps after a 3-step warm-up (local backend): per shard, the
    phases and payloads in order; with the exchange's routing (``Bridge``)."""
    env = build(n, 2, "local", api="rollout")
    policy = Cycle(actions(n, "full"), env.scenario.act_parts())
    env.rollout(policy, 3, seed=0)
    posts: dict[int, list[tuple[str, Any]]] = {0: [], 1: []}
    backend = env.coordinator.backend
    for k, shard in backend.shards.items():
        inner = shard._swap

        def swap(key: Any, i: int, payload: Any, inner: Any = inner, k: int = k) -> Any:
            posts[k].append((key[1], payload))
            return inner(key, i, payload)

        shard._swap = swap
    env.rollout(policy, steps, seed=1)
    bridge = backend.exchange.bridge
    close(env)
    return bridge, posts


class _NullShard:
    """A Ray actor that only posts recorded payloads at the exchange (no simulation): the exchange's floor."""

    def __init__(self, k: int, posts: list[tuple[str, Any]], wire: Any, exchange: Any) -> None:
        from agentsim_env.distributed.wire import WireClient

        self.k, self.posts, self.exchange = k, posts, exchange
        self.client = WireClient(*wire, k, 120.0) if wire is not None else None

    def run(self, per_step: int, steps: int, tick0: int) -> float:
        """Post ``steps`` steps of recorded payloads (cycled); this process's CPU seconds."""
        import ray

        c0 = time.process_time()
        for s in range(steps):
            for i in range(per_step):
                phase, payload = self.posts[(s * per_step + i) % len(self.posts)]
                key = (tick0 + s, phase)
                if self.client is not None:
                    self.client.swap(key, self.k, payload)
                else:
                    ray.get(self.exchange.swap.remote(key, self.k, payload))
        return time.process_time() - c0


def exchange_floor(ray: Any, n: int, steps: int) -> tuple[str, dict[str, float]]:
    """Table d: the exchange alone, replaying a 2-shard rollout's posts with no simulation, over the wire (the data
    path of today) and over one Ray actor call per barrier (the earlier one)."""
    import secrets

    from agentsim_env.distributed.exchange import ExchangeActor

    bridge, posts = record_posts(n, steps)
    per_step = len(posts[0]) // steps

    class TimedExchange(ExchangeActor):
        async def cpu(self) -> float:
            return time.process_time()

    rows, out = [], {}
    for label, use_wire in (
        ("TCP connection per shard (today)", True),
        ("Ray actor call per barrier", False),
    ):
        ex = ray.remote(num_cpus=0)(TimedExchange).remote(bridge, 2, 120.0)
        ray.get(ex.set_slot_owner.remote(bridge.slot_owner))
        token = secrets.token_bytes(32)
        wire = ("127.0.0.1", ray.get(ex.serve.remote("127.0.0.1", token)), token) if use_wire else None
        actors = [ray.remote(num_cpus=0)(_NullShard).remote(k, posts[k], wire, ex) for k in (0, 1)]
        ray.get([a.run.remote(per_step, steps, 0) for a in actors])  # warm-up
        c0 = ray.get(ex.cpu.remote())
        t0 = time.perf_counter()
        cpu = ray.get([a.run.remote(per_step, steps, 10_000) for a in actors])
        wall = (time.perf_counter() - t0) / steps * 1e3
        ex_cpu = (ray.get(ex.cpu.remote()) - c0) / steps * 1e3
        out[label] = wall
        out[label + " cpu"] = ex_cpu
        rows.append([label, str(per_step), fmt_num(wall), fmt_num(ex_cpu), fmt_num(max(cpu) / steps * 1e3)])
        for a in (*actors, ex):
            ray.kill(a)
    table = markdown_table(
        [
            "data path",
            "barriers / step",
            "wall ms / step",
            "exchange CPU ms / step",
            "a shard's CPU ms / step",
        ],
        rows,
    )
    return table, out


def scaling_table(n: int, shard_counts: list[int], steps: int) -> str:
    """Table e: one process vs K shards on this machine's local Ray cluster, through ``env.rollout`` (wall ms per
    step without the reset, whether the results equal one process's). For machines with more cores than this one:
    each shard is a process, so K shards need K cores (plus one for the driver and the exchange)."""
    base = run_rollout(n, None, "full", steps)
    rows = [
        [
            fmt_num(n),
            "one process",
            fmt_num(base["step_ms"]),
            fmt_num(1e3 / base["step_ms"]),
            "1.00",
            "-",
            "-",
            "-",
        ]
    ]
    for k in shard_counts:
        r = run_rollout(n, k, "full", steps)
        rows.append(
            [
                fmt_num(n),
                f"{k} shards (Ray)",
                fmt_num(r["step_ms"]),
                fmt_num(1e3 / r["step_ms"]),
                f"{base['step_ms'] / r['step_ms']:.2f}",
                fmt_num(r["busy_ms"]),
                fmt_num(r["wait_ms"]),
                "yes" if same_result(base["result"], r["result"]) else "NO",
            ]
        )
        print(f"  {k} shards: {r['step_ms']:.0f} ms/step", file=sys.stderr, flush=True)
    return markdown_table(
        [
            "agents",
            "system",
            "ms/step",
            "env-steps/s",
            "speed-up",
            "slowest shard busy ms",
            "exchange ms",
            "same results",
        ],
        rows,
    )


def border_bytes(sizes: list[int], steps: int, shards: int = 2, traffic: str = "full") -> list[dict[str, float]]:
    """Table c's rows: bytes per step (mean over ``steps`` steps after one warm-up step), local backend.

    Returns:
        One dict per size: ``n``, ``side`` (map side, m), ``halo_m``, ``halo``, ``handover``, ``total`` (bytes
        per step), ``ghosts`` (halo bytes / 32) and ``expected`` (agents within a halo of an edge, on either
        side, at uniform density: ``2 * halo * n / side`` per edge).
    """
    out = []
    for n in sizes:
        env = build(n, shards, "local")
        acts = actions(n, traffic)
        env.step(acts[0])
        got: dict[str, list[int]] = {"halo": [], "handover": [], "total": []}
        for i in range(1, steps + 1):
            env.step(acts[i % bc.CYCLE])
            tr = env.coordinator.traffic
            got["halo"].append(tr.halo)
            got["handover"].append(tr.handover)
            got["total"].append(tr.between_shards)
        side, halo = float(env.scenario.config.side), float(env.coordinator.strips.halo)
        close(env)
        row: dict[str, float] = {"n": n, "side": side, "halo_m": halo}
        row.update({k: float(np.mean(v)) for k, v in got.items()})
        row["ghosts"] = row["halo"] / GHOST_BYTES
        row["expected"] = (shards - 1) * 2.0 * halo * n / side
        out.append(row)
    return out


def bytes_by_shards(n: int, shard_counts: list[int], steps: int) -> dict[int, dict[str, float]]:
    """Bytes per step through the exchange by phase (posted and routed back, mean over ``steps`` step-API steps
    after a warm-up step), local backend, for each shard count: what grows with K at a fixed N."""
    out: dict[int, dict[str, float]] = {}
    for k in shard_counts:
        env = build(n, k, "local")
        acts = actions(n, "full")
        env.step(acts[0])
        got: dict[str, list[float]] = {}
        for i in range(1, steps + 1):
            env.step(acts[i % bc.CYCLE])
            tr = env.coordinator.traffic
            for f in ("halo", "handover", "offline", "bus", "positions", "groups"):
                got.setdefault(f, []).append(getattr(tr, f))
            got.setdefault("total", []).append(tr.between_shards)
        close(env)
        out[k] = {f: float(np.mean(v)) for f, v in got.items()}
    return out


def hub_table(by_k: dict[int, dict[str, float]], n: int) -> str:
    """The exchange's bytes per step by phase and shard count (posted plus routed back)."""
    rows = [
        [
            str(k),
            *(_bytes(b[f]) for f in ("halo", "handover", "offline", "bus", "positions", "groups", "total")),
            _bytes(b["total"] / n),
        ]
        for k, b in by_k.items()
    ]
    return markdown_table(
        ["shards", "halo", "handover", "offline", "bus", "positions", "groups", "total", "total / agent"],
        rows,
    )


def border_table(rows: list[dict[str, float]]) -> str:
    """Table c, with halo bytes per agent and per sqrt(agent) (flat when the halo grows as sqrt(N))."""
    body = [
        [
            fmt_num(r["n"]),
            fmt_num(r["side"]),
            fmt_num(r["ghosts"]),
            fmt_num(r["expected"]),
            _bytes(r["halo"]),
            fmt_num(r["halo"] / r["n"]),
            fmt_num(r["halo"] / np.sqrt(r["n"])),
            _bytes(r["handover"]),
            _bytes(r["total"]),
        ]
        for r in rows
    ]
    return markdown_table(
        [
            "agents",
            "map side m",
            "ghosts",
            "expected ghosts",
            "halo bytes",
            "halo bytes / agent",
            "halo bytes / sqrt(agents)",
            "handover bytes",
            "total bytes",
        ],
        body,
    )


def main(argv: list[str] | None = None) -> int:
    """Print the tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes and few steps (smoke test)")
    p.add_argument(
        "--scaling",
        type=int,
        metavar="N",
        default=None,
        help="only table e: N agents, one process vs --shards K (a machine with many cores)",
    )
    p.add_argument("--shards", type=str, default="2,4,8", help="shard counts of --scaling, comma separated")
    p.add_argument("--steps", type=int, default=None, help="steps of each measured rollout")
    p.add_argument(
        "--stages",
        type=int,
        metavar="N",
        default=None,
        help="only the stage table: N agents, each stage of a 2-shard rollout against half of one process's",
    )
    args = p.parse_args(argv)
    q = args.quick
    if args.stages is not None:
        print(f"# Where a shard's step goes\n\nMachine: {machine_description()}\n")
        ray = start_ray()
        if ray is None:
            print("Ray is not installed: pip install 'agentsim-env[ray]'")
            return 1
        try:
            print(stage_table(args.stages, args.steps or 12, ray))
        finally:
            ray.shutdown()
        return 0
    if args.scaling is not None:
        ks = [int(x) for x in args.shards.split(",") if x.strip()]
        print(f"# One world over K shards on one machine\n\nMachine: {machine_description()}\n")
        ray = start_ray()
        if ray is None:
            print("Ray is not installed: pip install 'agentsim-env[ray]'")
            return 1
        try:
            print(scaling_table(args.scaling, ks, args.steps or 6))
        finally:
            ray.shutdown()
        return 0
    sizes, steps = ([10_000], 4) if q else ([100_000, 200_000], 12)
    border = [2000, 10_000] if q else [10_000, 40_000, 100_000]
    print(f"# One world over shards that step themselves\n\nMachine: {machine_description()}\n")
    ray = start_ray()
    if ray is None:
        print("Ray is not installed: the Ray rows are skipped (pip install 'agentsim-env[ray]').\n")
    try:
        print(
            f"## Speed-up over one process (full traffic; rollout: per step of a {steps}-step rollout, its reset "
            f"left out; step API: median of {steps} steps)\n"
        )
        table, res = speed_table(sizes, steps, ray)
        print(table)
        if ray is not None:
            print(
                f"\n## The exchange alone: {sizes[0]:,} agents, 2 shards, the posts of a rollout replayed with no "
                f"simulation\n"
            )
            floor_table, floor = exchange_floor(ray, sizes[0], steps)
            print(floor_table)
            one = res[sizes[0], "rollout", "one process"]["step_ms"]
            wall = floor["TCP connection per shard (today)"]
            print(
                f"\nThe floor bounds the rollout's speed-up over 2 shards on this machine: with no other cost than "
                f"the exchange, a step takes half of one process's ({one:.0f} / 2 ms) plus the exchange's wall time "
                f"({wall:.1f} ms): at most {one / (one / 2 + wall):.2f}x (at most "
                f"{one / (one / 2 + floor['Ray actor call per barrier']):.2f}x over Ray actor calls)."
            )
            n_small = 5_000 if q else 20_000
            ks = [2, 4] if q else [2, 4, 8, 16]
            print(
                f"\n## Bytes through the exchange vs shards ({n_small:,} agents, local backend, full traffic, step "
                f"API, mean of 3 steps; posted plus routed back)\n"
            )
            by_k = bytes_by_shards(n_small, ks, 3)
            print(hub_table(by_k, n_small))
            print(
                "\nThe bus's bytes grow with the agents, not with the strip edge: a quarter of the messages go to "
                "a named agent anywhere on the map and a quarter to a group whose members live anywhere (a GROUP "
                "message goes to every shard), so with K shards (K - 1) / K of the named ones cross and every "
                "GROUP message is sent K times."
            )
            print(f"\n## On paper: {PAPER_N:,} agents on {PAPER_K} machines\n")
            print(paper_table(res, sizes[0], floor, by_k, n_small))
            one = (
                res[sizes[-1], "rollout", "one process"]["step_ms"] / res[sizes[0], "rollout", "one process"]["step_ms"]
            )
            print(
                f"\nAssumptions: one shard per machine; its busy time = a part per own agent (measured above at "
                f"{sizes[0]:,} agents over 2 shards, minus the fixed part) x ({PAPER_N:,} / {PAPER_K} agents + 8 % "
                f"ghosts) + a fixed part per slot of the world ({FIXED_MS_PER_SLOT * 1e6:.0f} ns a slot, from a "
                f"shard's profile; 0 with shard worlds sized to their agents); the barriers' latency as measured "
                f"above with no simulation; the bytes through the exchange at {max(ks)} shards (table above), "
                f"those of the edge phases (halo, hand-overs, offline) times sqrt({PAPER_N:,} / {n_small:,}), the "
                f"others (bus, positions, groups) times {PAPER_N:,} / {n_small:,}, routed at the CPU cost per byte "
                f"measured above and sent over "
                f"10 Gb/s links (one exchange: every byte on its one CPU and link; shards exchanging directly: "
                f"each carries 1 / {PAPER_K} of them); the coordinator's share linear in the number of shards; "
                f"one process linear in N, the choice that favours one process (measured here: worse than linear, "
                f"{one:.2f}x "
                f"for {sizes[-1] / sizes[0]:.0f}x the agents)."
            )
        print(
            f"\n## Bytes per step vs agents near the strip edge (2 shards, local backend, full traffic, step "
            f"API, mean of {2 if q else 3} steps)\n"
        )
        rows = border_bytes(border, 2 if q else 3)
        print(border_table(rows))
        print(
            f"\nGhosts = halo bytes / {GHOST_BYTES}. Expected ghosts = 2 x halo ({rows[0]['halo_m']:.0f} m) x "
            f"agents / map side: the agents within a halo of the strip edge at uniform density. The map side "
            f"grows as sqrt(agents) (fixed area per agent), so the halo grows as sqrt(agents)."
        )
    finally:
        if ray is not None and ray.is_initialized():
            ray.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
