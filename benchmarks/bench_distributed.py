"""One world over shards: step time, the coordinator's share, and the bytes that cross between processes.

``navigation`` with the full-stack comms config of ``bench_comms`` (collisions off, so the population stays
constant), stepped through the array front end with one world: ``BatchedEnv`` (one process) next to
``DistributedBatchedEnv`` (K shards as Ray actors on a local cluster, or in this process with
``backend="local"``). Two kinds of traffic: "full" (every agent sends one message every step, a quarter of them
overlay floods with hop limit 2, as in ``bench_comms``) and "silent" (comms on, nobody sends: channel "none").

Three tables:

a. 100,000 agents, one world: median wall time per step, env-steps/s, the speed-up of 2 Ray shards over one
   process (same traffic), the shards' compute time (their heartbeats' ``step_s``), the rest ("coordinator +
   transfer": step time minus the slowest shard's compute: the coordinator's serial stages, serialisation,
   Ray's calls) and the bytes per step. Each system is built, stepped (1 warm-up step, then the timed steps)
   and closed before the next (a 100k world exists three times with 2 shards: the mirror and one per shard).
b. The coordinator's overhead at small sizes (silent traffic): one process, 1 shard in this process, 1 shard
   on Ray, 2 shards on Ray; wall ms per step, interleaved rounds (``common.measure_interleaved``; wall time,
   since a Ray shard's work is not in this process's CPU time).
c. Bytes per step against the number of agents near the strip edge (2 shards, ``backend="local"``: the bytes do
   not depend on the backend): the halo (ghosts) grows with the map side, i.e. with sqrt(N) at fixed density,
   not with N.

Timing is wall time (the shards run in other processes); on a shared machine the numbers move with its load.
Ray is started once for the whole run (a local cluster on 127.0.0.1) and stopped at the end; without Ray the
Ray rows are skipped.

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
from common import fmt_num, machine_description, markdown_table, measure_interleaved  # noqa: E402, I001

import numpy as np  # noqa: E402  (after common: it pins the thread pools before numpy loads)

import bench_comms as bc  # noqa: E402

SHARD_TIMEOUT_S = (
    120.0  # per call: a loaded shared machine must not declare a slow shard offline mid-benchmark
)
GHOST_BYTES = 32  # a ghost: its int64 slot id and its 3 float64 coordinates
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
        ray.init(num_cpus=max(os.cpu_count() or 1, 2), include_dashboard=False, _node_ip_address="127.0.0.1",
                 logging_level="ERROR", log_to_driver=False)  # fmt: skip
    return ray


def build(n: int, shards: int | None, backend: str = "ray") -> Any:
    """One process (``shards=None``) or ``shards`` shards on ``backend``; reset with seed 0."""
    if shards is None:
        from agentsim_env.env.vector import BatchedEnv

        env = BatchedEnv("navigation", 1, **config(n))
    else:
        from agentsim_env.distributed import DistributedBatchedEnv

        env = DistributedBatchedEnv(
            "navigation", shards, backend=backend, timeout_s=SHARD_TIMEOUT_S, **config(n)
        )
    env.reset(seed=0)
    return env


def close(env: Any) -> None:
    """Stop the shards (if any) and free the worlds before the next system is built."""
    if hasattr(env, "coordinator"):
        env.close()
    del env
    gc.collect()


def run_blocks(env: Any, acts: list[np.ndarray], warmup: int, steps: int) -> dict[str, float]:
    """Step ``env`` ``warmup`` times untimed, then ``steps`` times timed; medians over the timed steps.

    Returns:
        ``step_ms``; for a sharded env also ``shard_ms`` (mean over shards of their compute), ``max_shard_ms``,
        ``coord_ms`` (step minus the slowest shard), ``bytes`` (total) and ``border_bytes`` (halo + handover).
    """
    for i in range(warmup):
        env.step(acts[i % bc.CYCLE])
    rec: dict[str, list[float]] = {k: [] for k in ("step_ms", "shard_ms", "max_shard_ms", "coord_ms", "bytes",
                                                   "border_bytes")}  # fmt: skip
    co = getattr(env, "coordinator", None)
    for i in range(warmup, warmup + steps):
        t0 = time.perf_counter()
        env.step(acts[i % bc.CYCLE])
        ms = (time.perf_counter() - t0) * 1e3
        rec["step_ms"].append(ms)
        if co is not None:
            comp = [s.step_s * 1e3 for s in env.shards if s.alive]
            rec["shard_ms"].append(float(np.mean(comp)))
            rec["max_shard_ms"].append(max(comp))
            rec["coord_ms"].append(ms - max(comp))
            rec["bytes"].append(co.traffic.total)
            rec["border_bytes"].append(co.traffic.halo + co.traffic.handover)
    return {k: float(np.median(v)) for k, v in rec.items() if v}


def one_world_table(n: int, warmup: int, steps: int, ray: Any) -> tuple[str, str]:
    """Table a and the note under it (why the speed-up target is met or not)."""
    systems: list[tuple[str, int | None]] = [("one process", None)]
    if ray is not None:
        systems.append(("2 shards (Ray)", 2))
    res: dict[tuple[str, str], dict[str, float]] = {}
    for traffic in TRAFFIC:
        acts = actions(n, traffic)
        for label, shards in systems:
            env = build(n, shards)
            res[traffic, label] = run_blocks(env, acts, warmup, steps)
            close(env)
    rows = []
    for traffic in TRAFFIC:
        base = res[traffic, "one process"]["step_ms"]
        for label, shards in systems:
            r = res[traffic, label]
            sharded = shards is not None
            rows.append([traffic, label, fmt_num(r["step_ms"]), fmt_num(1e3 / r["step_ms"]),
                         f"{base / r['step_ms']:.2f}",
                         fmt_num(r["shard_ms"]) if sharded else "-", fmt_num(r["coord_ms"]) if sharded else "-",
                         _bytes(r["bytes"]) if sharded else "-",
                         _bytes(r["border_bytes"]) if sharded else "-"])  # fmt: skip
    table = markdown_table(["traffic", "system", "step ms", "env-steps/s", "speed-up", "shard compute ms",
                            "coordinator + transfer ms", "bytes/step", "halo + handover bytes/step"], rows)  # fmt: skip
    if ray is None:
        return table, "Ray is not installed: the 2-shard rows are skipped (pip install 'agentsim-env[ray]')."
    notes = []
    for traffic in TRAFFIC:
        one, two = res[traffic, "one process"], res[traffic, "2 shards (Ray)"]
        speed = one["step_ms"] / two["step_ms"]
        need = one["step_ms"] / 1.6
        co, slow = two["coord_ms"], two["max_shard_ms"]
        why = (
            f"the coordinator's serial share alone (bus, overlay, inboxes, observations of all {n:,} agents, "
            f"plus the transfers) is {co:.0f} ms of the {two['step_ms']:.0f} ms step"
        )
        if co >= need:
            why += f", over the {need:.0f} ms that 1.6x allows, whatever the shards do"
        else:
            why += (
                f"; with the slowest shard's {slow:.0f} ms on top it does not fit in the {need:.0f} ms that 1.6x "
                f"allows"
            )
        why += f"; with this serial share no number of shards beats {one['step_ms'] / max(co, 1e-9):.2f}x"
        if speed >= 1.6:
            why = f"the slowest shard computes {slow:.0f} ms and the coordinator + transfers take {co:.0f} ms"
        notes.append(
            f"{traffic} traffic: {speed:.2f}x vs one process ({one['step_ms']:.0f} ms), target 1.6x "
            f"{'met' if speed >= 1.6 else 'not met'}: {why} (the shards compute {two['shard_ms']:.0f} ms each on "
            f"average)."
        )
    cores = os.cpu_count() or 1
    if cores < 3:
        notes.append(f"This machine has {cores} logical CPUs for the coordinator and 2 shards (and anything else "
                     f"running): the shards do not always get a core each.")  # fmt: skip
    return table, "\n".join(f"Note: {x}" for x in notes)


def overhead_table(sizes: list[int], rounds: int, block_s: float, ray: Any) -> str:
    """Table b: wall ms per step of one process and of 1-2 shards, silent traffic, interleaved rounds."""
    rows = []
    for n in sizes:
        acts = actions(n, "silent")
        systems: dict[str, tuple[int | None, str]] = {
            "one process": (None, "ray"),
            "1 shard, local": (1, "local"),
        }
        if ray is not None:
            systems.update({"1 shard, Ray": (1, "ray"), "2 shards, Ray": (2, "ray")})
        envs = {name: build(n, k, be) for name, (k, be) in systems.items()}
        cases = {name: bc._cycling(env, acts, n) for name, env in envs.items()}
        try:
            stats = measure_interleaved(cases, rounds=rounds, block_s=block_s, warmup=2, max_block_steps=500)
        finally:
            for env in envs.values():
                close(env)
        base = stats["one process"].wall_step_s * 1e3
        for name in systems:
            ms = stats[name].wall_step_s * 1e3
            rows.append([fmt_num(n), name, fmt_num(ms), "-" if name == "one process" else fmt_num(ms - base),
                         f"{ms / base:.2f}"])  # fmt: skip
    return markdown_table(["agents", "system", "ms/step", "overhead ms/step", "vs one process"], rows)


def border_bytes(
    sizes: list[int], steps: int, shards: int = 2, traffic: str = "full"
) -> list[dict[str, float]]:
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
            got["total"].append(tr.total)
        side, halo = float(env.scenario.config.side), float(env.coordinator.strips.halo)
        close(env)
        row: dict[str, float] = {"n": n, "side": side, "halo_m": halo}
        row.update({k: float(np.mean(v)) for k, v in got.items()})
        row["ghosts"] = row["halo"] / GHOST_BYTES
        row["expected"] = (shards - 1) * 2.0 * halo * n / side
        out.append(row)
    return out


def border_table(rows: list[dict[str, float]]) -> str:
    """Table c, with halo bytes per agent and per sqrt(agent) (flat when the halo grows as sqrt(N))."""
    body = [[fmt_num(r["n"]), fmt_num(r["side"]), fmt_num(r["ghosts"]), fmt_num(r["expected"]), _bytes(r["halo"]),
             fmt_num(r["halo"] / r["n"]), fmt_num(r["halo"] / np.sqrt(r["n"])), _bytes(r["handover"]),
             _bytes(r["total"])] for r in rows]  # fmt: skip
    return markdown_table(["agents", "map side m", "ghosts", "expected ghosts", "halo bytes", "halo bytes / agent",
                           "halo bytes / sqrt(agents)", "handover bytes", "total bytes"], body)  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    """Print the three tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes and few steps (smoke test)")
    args = p.parse_args(argv)
    q = args.quick
    n_big, steps = (10_000, 4) if q else (100_000, 8)
    small = [100, 1000] if q else [100, 1000, 10_000]
    border = [2000, 10_000] if q else [10_000, 40_000, 100_000]
    print(f"# One world over shards\n\nMachine: {machine_description()}\n")
    ray = start_ray()
    if ray is None:
        print("Ray is not installed: the Ray rows are skipped (pip install 'agentsim-env[ray]').\n")
    try:
        print(f"## {n_big:,} agents, one world (1 warm-up step, median of {steps} timed steps, wall time)\n")
        table, note = one_world_table(n_big, 1, steps, ray)
        print(table)
        print(f"\n{note}\n")
        print(
            "## Coordinator overhead at small sizes (silent traffic: comms on, nobody sends; wall ms per step)\n"
        )
        print(overhead_table(small, rounds=2 if q else 5, block_s=0.05 if q else 0.3, ray=ray))
        print(f"\n## Bytes per step vs agents near the strip edge (2 shards, local backend, full traffic, "
              f"mean of {2 if q else 3} steps)\n")  # fmt: skip
        rows = border_bytes(border, 2 if q else 3)
        print(border_table(rows))
        print(f"\nGhosts = halo bytes / {GHOST_BYTES} (each ghost is sent as an int64 slot id and 3 float64 "
              f"coordinates). Expected ghosts = 2 x halo ({rows[0]['halo_m']:.0f} m) x agents / map side: the agents "
              f"within a halo of the one strip edge at uniform density. The map side grows as sqrt(agents) (fixed "
              f"area per agent), so the halo grows as sqrt(agents): halo bytes per agent fall, halo bytes per "
              f"sqrt(agent) stay flat.")  # fmt: skip
    finally:
        if ray is not None and ray.is_initialized():
            ray.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
