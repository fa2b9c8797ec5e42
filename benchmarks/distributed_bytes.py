"""The bytes of the sharded world and what they imply: the exchange's floor (a rollout's posts replayed with no
simulation), bytes per step against the agents near a strip edge and against the number of shards, and the
1,000,000-agent estimate built from them (``bench_distributed.py`` prints these tables)."""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from common import fmt_num, markdown_table
from distributed_setup import Cycle, actions, build, close, fmt_bytes, ship_by_value

GHOST_BYTES = 80  # a ghost: its int64 slot id, x and 3 float64 coordinates, posted by its shard and routed on

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
    coord_line: tuple[float, float],
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
    coord = coord_line[0] + coord_line[1] * k  # measured against the number of shards on a small world
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
                fmt_bytes(hub_bytes / (k if peer else 1)),
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

    ship_by_value(sys.modules[__name__])  # the null shards' class
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
            env.step(acts[i % len(acts)])
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
            env.step(acts[i % len(acts)])
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
            *(fmt_bytes(b[f]) for f in ("halo", "handover", "offline", "bus", "positions", "groups", "total")),
            fmt_bytes(b["total"] / n),
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
            fmt_bytes(r["halo"]),
            fmt_num(r["halo"] / r["n"]),
            fmt_num(r["halo"] / np.sqrt(r["n"])),
            fmt_bytes(r["handover"]),
            fmt_bytes(r["total"]),
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
