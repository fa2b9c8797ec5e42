"""Full-stack throughput with communication: 32-ray 3D scan + bus + overlay + groups, every agent sending.

``navigation`` with comms on (heartbeats every 10 steps, groups of 8 agents); every agent sends one message every step,
the channels mixed by agent index (group, nearest, named, overlay flood with hop limit 2). Collisions are off
so the population stays constant while timing. Measured through the dict API (ParallelEnv) and the array API
(BatchedEnv, B = 1), next to the same world without comms, interleaved. A second table times ``MessageBus``
delivery alone for growing message counts: the cost per message should stay flat (linear delivery).

Run: ``python benchmarks/bench_comms.py [--quick]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import Case, fmt_num, machine_description, markdown_table, measure_interleaved  # noqa: E402, I001

import numpy as np  # noqa: E402  (after common: it pins the thread pools before numpy loads)

CHANNEL_VALUES = np.array([-0.4, 0.0, 0.4, 0.8])  # bin centres of group, nearest, named, overlay


def _config(n: int, comms: bool) -> dict:
    cfg = {"n_agents": n, "n_groups": max(1, n // 8), "collisions": False, "max_steps": 10**9}
    if comms:
        cfg["comms"] = {"payload_dim": 4, "inbox_size": 4, "overlay_range": 30.0, "max_hops": 2,
                        "heartbeat_period": 10, "heartbeat_timeout": 20}  # fmt: skip
    return cfg


def _actions(n: int, comms: bool, rng: np.random.Generator) -> np.ndarray:
    motion = rng.uniform(-1, 1, (n, 3))
    if not comms:
        return motion
    comm = np.zeros((n, 7))
    comm[:, 0] = CHANNEL_VALUES[np.arange(n) % 4]
    comm[:, 1] = rng.uniform(-1, 1, n)
    comm[:, 2] = 1.0  # hop limit = max_hops
    comm[:, 3:] = rng.uniform(-1, 1, (n, 4))
    return np.concatenate([motion, comm], axis=1)


def dict_case(n: int, comms: bool) -> Case:
    """The ParallelEnv with one prepared action dict reused every step."""
    import agentsim_env

    env = agentsim_env.make("navigation", **_config(n, comms))
    env.reset(seed=0)
    a = _actions(n, comms, np.random.default_rng(0)).astype(np.float32)
    acts = {ag: ({"motion": a[i, :3], "comm": a[i, 3:]} if comms else {"motion": a[i, :3]})
            for i, ag in enumerate(env.possible_agents)}  # fmt: skip

    def step() -> int:
        env.step(acts)
        return n

    return Case(step)


def array_case(n: int, comms: bool) -> Case:
    """The batched array API with one world."""
    from agentsim_env.env.vector import BatchedEnv

    b = BatchedEnv("navigation", 1, **_config(n, comms))
    b.reset(seed=0)
    a = _actions(n, comms, np.random.default_rng(0))[None]

    def step() -> int:
        b.step(a)
        return n

    return Case(step)


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
        rows.append(
            [fmt_num(k), fmt_num(stats[str(k)].step_s * 1e3), fmt_num(per * 1e9), f"{per / base:.2f}"]
        )
    return markdown_table(["messages / step", "send + deliver ms", "ns / message", "vs smallest"], rows)


def main(argv: list[str] | None = None) -> int:
    """Print both tables."""
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
        rows.append([f"1x{n}", fmt_num(eps["dict+comms"]), fmt_num(eps["array+comms"]), fmt_num(eps["array, no comms"]),
                     f"{eps['array, no comms'] / eps['array+comms']:.2f}", "-" if tgt is None else fmt_num(tgt), ok])  # fmt: skip
    print(markdown_table(["size", "dict API env-steps/s", "array API env-steps/s", "array, no comms",
                          "comms cost (x)", "target (dict)", "met"], rows))  # fmt: skip
    print("\n# Bus delivery cost per message\n")
    counts = [500, 1000, 2000] if args.quick else [1000, 2000, 4000, 8000, 16000]
    print(delivery_table(counts, rounds))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
