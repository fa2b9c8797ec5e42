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
c. The coordinator's part of a rollout step against the number of shards (a small world: 1, 2, 4, 8 shards).
d. On paper: 1,000,000 agents on 16 machines, from the measurements above (assumptions printed).

Timing is wall time (the shards run in other processes); on a shared machine the numbers move with its load.
Ray is started once for the whole run and stopped at the end; without Ray the Ray rows are skipped.

Run: ``python benchmarks/bench_distributed.py [--quick]``. The parts: ``distributed_setup.py`` (config, action
cycle, Ray, building the envs), ``distributed_bytes.py`` (the exchange's floor, bytes, the estimate on paper),
``shard_stages.py`` (``--stages``); this file runs the systems and prints the tables.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import fmt_num, machine_description, markdown_table  # noqa: E402, I001

import numpy as np  # noqa: E402  (after common: it pins the thread pools before numpy loads)

from distributed_bytes import (  # noqa: E402
    FIXED_MS_PER_SLOT,
    GHOST_BYTES,
    PAPER_K,
    PAPER_N,
    border_bytes,
    border_table,
    bytes_by_shards,
    exchange_floor,
    hub_table,
    paper_table,
)
from distributed_setup import Cycle, actions, build, close, fmt_bytes, shard_times, start_ray  # noqa: E402
from shard_stages import stage_table  # noqa: E402


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
        out.update(shard_times(env))
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
        env.step(acts[i % len(acts)])
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
                fmt_bytes(r["bytes"]) if sharded else "-",
                fmt_bytes(r["calls_bytes"]) if sharded else "-",
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


def coordinator_cost(n: int, shard_counts: list[int], steps: int) -> tuple[str, tuple[float, float]]:
    """Table d: the coordinator's part of a rollout step against the number of shards, on a world small enough
    that the shards' own work does not matter (the median over steps of the step call's wall time outside the
    slowest shard's call, and the driver process's CPU time a step, its rollout's reset included), and the least
    squares line ``a + b K`` through the first column (what the estimate on paper takes)."""
    rows, ks, ms = [], [], []
    for k in shard_counts:
        env = build(n, k, api="rollout")
        policy = Cycle(actions(n, "full"), env.scenario.act_parts())
        env.rollout(policy, 2, seed=0)
        c0 = time.process_time()
        env.rollout(policy, steps, seed=0)
        cpu = (time.process_time() - c0) / steps * 1e3
        st = env.coordinator.profile["steps"][1:]
        outside = float(np.median([wall - max(call) for wall, call, _ in st])) * 1e3
        close(env)
        ks.append(k)
        ms.append(outside)
        rows.append([str(k), fmt_num(outside), fmt_num(cpu)])
    b, a = np.polyfit(ks, ms, 1) if len(ks) > 1 else (0.0, ms[0])
    table = markdown_table(["shards", "coordinator ms / step", "driver CPU ms / step"], rows)
    return table + f"\n\nLine through the first column: {a:.2f} + {b:.2f} ms a shard.", (float(a), float(b))


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
            n_coord, coord_ks = (2_000, [1, 2]) if q else (2_000, [1, 2, 4, 8])
            print(
                f"\n## The coordinator's part of a rollout step vs shards ({n_coord:,} agents, full traffic, "
                f"{steps}-step rollouts)\n"
            )
            coord_table, coord_line = coordinator_cost(n_coord, coord_ks, steps)
            print(coord_table)
            print(f"\n## On paper: {PAPER_N:,} agents on {PAPER_K} machines\n")
            print(paper_table(res, sizes[0], floor, by_k, n_small, coord_line))
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
                f"each carries 1 / {PAPER_K} of them); the coordinator's part on the line through the table above at "
                f"{PAPER_K} shards; "
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
