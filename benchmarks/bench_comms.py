"""Full-stack throughput with communication: 32-ray 3D scan + bus + overlay + groups, every agent sending.

``navigation`` with comms on (heartbeats every 10 steps, groups of 8 agents); every agent sends one message every step,
the channels mixed by agent index (group, nearest, named, overlay flood with hop limit 2). Collisions are off
so the population stays constant while timing. Measured through the dict API (ParallelEnv) and the array API
(BatchedEnv, B = 1), next to the same world without comms, interleaved. A second table splits the comms
time of the array API into the pipeline stages (one extra pass, with a timer around each stage). A third
table times ``MessageBus`` delivery alone for growing message counts: the cost per message should stay flat
(linear delivery).

The motion actions cycle through 32 prepared arrays whose second half is the negated first half: agents move
(up to full speed) but stay spread over the map, so every timed step sees the same uniform density. (A
constant action per agent drives the whole swarm onto the map's edges within a thousand steps, and the cost
of the scan and of the range graph then grows with every step timed.)

Run: ``python benchmarks/bench_comms.py [--quick]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Case, fmt_num, machine_description, markdown_table, measure_interleaved  # noqa: E402, I001

import numpy as np  # noqa: E402  (after common: it pins the thread pools before numpy loads)

CHANNEL_VALUES = np.array([-0.4, 0.0, 0.4, 0.8])  # bin centres of group, nearest, named, overlay
CYCLE = 32  # prepared action arrays per case (motion: 16 random draws, then the same negated)


def _config(n: int, comms: bool) -> dict:
    cfg = {"n_agents": n, "n_groups": max(1, n // 8), "collisions": False, "max_steps": 10**9}
    if comms:
        cfg["comms"] = {
            "payload_dim": 4,
            "inbox_size": 4,
            "overlay_range": 30.0,
            "max_hops": 2,
            "heartbeat_period": 10,
            "heartbeat_timeout": 20,
        }
    return cfg


def _actions(n: int, comms: bool, rng: np.random.Generator) -> list[np.ndarray]:
    """``CYCLE`` action arrays ``(n, 3 [+ 7])``: mean-zero motion, the same comm part in every one."""
    half = rng.uniform(-1, 1, (CYCLE // 2, n, 3))
    motion = np.concatenate([half, -half])
    if not comms:
        return list(motion)
    comm = np.zeros((n, 7))
    comm[:, 0] = CHANNEL_VALUES[np.arange(n) % 4]
    comm[:, 1] = rng.uniform(-1, 1, n)
    comm[:, 2] = 1.0  # hop limit = max_hops
    comm[:, 3:] = rng.uniform(-1, 1, (n, 4))
    return [np.concatenate([m, comm], axis=1) for m in motion]


def _make_dict_env(n: int, comms: bool):  # type: ignore[no-untyped-def]
    import agentsim_env

    env = agentsim_env.make("navigation", **_config(n, comms))
    env.reset(seed=0)
    acts = []
    for a in _actions(n, comms, np.random.default_rng(0)):
        a = a.astype(np.float32)
        acts.append(
            {
                ag: ({"motion": a[i, :3], "comm": a[i, 3:]} if comms else {"motion": a[i, :3]})
                for i, ag in enumerate(env.possible_agents)
            }
        )
    return env, acts


def _make_array_env(n: int, comms: bool, threads: int = 1):  # type: ignore[no-untyped-def]
    from agentsim_env.env.vector import BatchedEnv

    b = BatchedEnv("navigation", 1, num_threads=threads, **_config(n, comms))
    b.reset(seed=0)
    return b, [a[None] for a in _actions(n, comms, np.random.default_rng(0))]


def _cycling(env, acts, n: int) -> Case:  # type: ignore[no-untyped-def]
    k = [0]

    def step() -> int:
        env.step(acts[k[0] % CYCLE])
        k[0] += 1
        return n

    return Case(step)


def dict_case(n: int, comms: bool) -> Case:
    """The ParallelEnv with prepared action dicts (built once, untimed)."""
    return _cycling(*_make_dict_env(n, comms), n)


def array_case(n: int, comms: bool, threads: int = 1) -> Case:
    """The batched array API with one world (``threads``: its ``num_threads``)."""
    return _cycling(*_make_array_env(n, comms, threads), n)


# Stages of the comms path, each the listed methods (the first that exists: the names changed over time).
# "range graph" is the neighbour pairs / range graph of the step; "bus" the bus delivery; "overlay" one hop of
# every flood; "deliver, rest" the rest of stage 7 (inbox push of the overlay deliveries, events).
STAGES = {
    "send (1)": [("agentsim_env.comms.stack", "CommsStack", "send_actions")],
    "groups (6)": [
        ("agentsim_env.groups.controller", "GroupController", "step"),
        ("agentsim_env.comms.stack", "CommsStack", "tick_groups"),
    ],
    "range graph": [
        ("agentsim_env.sim.world", "World", "_comm_pairs"),
        ("agentsim_env.comms.stack", "CommsStack", "update_graph"),
    ],
    "bus": [("agentsim_env.comms.bus", "MessageBus", "deliver")],
    "overlay": [
        ("agentsim_env.comms.overlay", "Overlay", "advance_graph"),
        ("agentsim_env.comms.overlay", "Overlay", "advance"),
    ],
    "deliver (7)": [("agentsim_env.comms.stack", "CommsStack", "deliver")],
    "observe (9)": [
        ("agentsim_env.comms.stack", "CommsStack", "observe_flat"),  # the array API's flat rows
        ("agentsim_env.comms.stack", "CommsStack", "observe"),
    ],
}


def stage_breakdown(n: int, steps: int) -> dict[str, float]:
    """Milliseconds per step of each comms stage (array API, B = 1), and of the whole step."""
    import importlib

    env, acts = _make_array_env(n, True)
    spent: dict[str, float] = defaultdict(float)
    saved = []
    for label, options in STAGES.items():
        for mod, cls_name, meth in options:
            cls = getattr(importlib.import_module(mod), cls_name)
            if not hasattr(cls, meth):
                continue
            orig = getattr(cls, meth)

            def timed(*a, _orig=orig, _label=label, **k):  # type: ignore[no-untyped-def]
                t = time.perf_counter()
                try:
                    return _orig(*a, **k)
                finally:
                    spent[_label] += time.perf_counter() - t

            saved.append((cls, meth, orig))
            setattr(cls, meth, timed)
            if label != "range graph":
                break  # one method per stage (both range graph hooks are timed: only one runs)
    try:
        for i in range(2 * CYCLE):  # warm up (compilation, buffers)
            env.step(acts[i % CYCLE])
        spent.clear()
        t0 = time.perf_counter()
        for i in range(steps):
            env.step(acts[i % CYCLE])
        total = time.perf_counter() - t0
    finally:
        for cls, meth, orig in saved:
            setattr(cls, meth, orig)
    out = {k: spent[k] / steps * 1e3 for k in STAGES}
    # the range graph, bus and overlay run inside deliver when the world passes its grid / pairs to it
    inner = out["bus"] + out["overlay"] + (out["range graph"] if _graph_in_deliver() else 0.0)
    out["deliver, rest"] = out.pop("deliver (7)") - inner
    out["comms total"] = sum(v for k, v in out.items())
    out["step"] = total / steps * 1e3
    return out


def _graph_in_deliver() -> bool:
    from agentsim_env.sim.world import World

    return not hasattr(World, "_comm_pairs")


def delivery_table(counts: list[int], rounds: int) -> str:
    """``MessageBus.deliver`` time per message for growing message counts (AGENT unicasts, 10k slots)."""
    from agentsim_env.comms.bus import ChannelConfig, MessageBus
    from agentsim_env.comms.messages import AGENT

    s = 10_000
    pos = np.random.default_rng(0).uniform(0, 1000, (s, 3))
    online = np.ones(s, dtype=bool)
    group = np.zeros(s, dtype=np.int32)
    cases = {}
    for k in counts:
        bus = MessageBus(1, s, 4, ChannelConfig(loss=0.1), 4, np.random.default_rng(0), group=group)
        rng = np.random.default_rng(k)
        snd, rcv = rng.integers(0, s, k), rng.integers(0, s, k)
        pay = rng.uniform(-1, 1, (k, 4)).astype(np.float32)
        step_no = [0]

        def step(bus=bus, snd=snd, rcv=rcv, pay=pay, step_no=step_no, k=k) -> int:  # noqa: ANN001
            bus.send(AGENT, snd, rcv, pay, step_no[0])
            bus.deliver(step_no[0], pos, online, group)
            step_no[0] += 1
            return k

        cases[str(k)] = Case(step)
    stats = measure_interleaved(cases, rounds=rounds, block_s=0.05)
    base = stats[str(counts[0])].step_s / counts[0]
    rows = []
    for k in counts:
        per = stats[str(k)].step_s / k
        rows.append([fmt_num(k), fmt_num(stats[str(k)].step_s * 1e3), fmt_num(per * 1e9), f"{per / base:.2f}"])
    return markdown_table(["messages / step", "send + deliver ms", "ns / message", "vs smallest"], rows)


def main(argv: list[str] | None = None) -> int:
    """Print the three tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes and few rounds (smoke test)")
    args = p.parse_args(argv)
    sizes = [64, 256] if args.quick else [1000, 10_000]
    rounds = 2 if args.quick else 5
    print(f"# Full stack with communication\n\nMachine: {machine_description()}\n")
    rows = []
    targets = {1000: 500.0, 10_000: 30.0}
    for n in sizes:
        cases = {
            "dict+comms": dict_case(n, True),
            "array+comms": array_case(n, True),
            "array, no comms": array_case(n, False),
        }
        st = measure_interleaved(cases, rounds=rounds, block_s=0.3 if not args.quick else 0.05)
        eps = {k: 1.0 / v.step_s for k, v in st.items()}
        tgt = targets.get(n)
        ok = "-" if tgt is None else ("yes" if eps["dict+comms"] >= tgt else "no")
        rows.append(
            [
                f"1x{n}",
                fmt_num(eps["dict+comms"]),
                fmt_num(eps["array+comms"]),
                fmt_num(eps["array, no comms"]),
                f"{eps['array, no comms'] / eps['array+comms']:.2f}",
                "-" if tgt is None else fmt_num(tgt),
                ok,
            ]
        )
    print(
        markdown_table(
            [
                "size",
                "dict API env-steps/s",
                "array API env-steps/s",
                "array, no comms",
                "comms cost (x)",
                "target (dict)",
                "met",
            ],
            rows,
        )
    )
    print("\n# Where the comms time goes (array API, ms per step; stage numbers as in DESIGN section 4)\n")
    br = {n: stage_breakdown(n, 40 if args.quick else (400 if n <= 1000 else 60)) for n in sizes}
    keys = list(br[sizes[0]])
    print(
        markdown_table(["stage"] + [f"1x{n}" for n in sizes], [[k] + [fmt_num(br[n][k]) for n in sizes] for k in keys])
    )
    print("\n# Bus delivery cost per message\n")
    counts = [500, 1000, 2000] if args.quick else [1000, 2000, 4000, 8000, 16000]
    print(delivery_table(counts, rounds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
