"""Where a shard's step goes: the stages of one process and of a shard, timed by the same wrappers.

``bench_distributed.py --stages`` prints ``stage_table``. Each stage is a method (or a few) of the pipeline,
wrapped with a timer in the process that runs it: in this process for one process, inside each shard process for
the shards (the policy object that plays the action cycle installs the wrappers when the shard resets it, and
writes its shard's timings to a folder this process reads after the rollout). The table sets each stage of a
shard against half of the same stage in one process: what a perfect split over 2 shards would cost.
"""

from __future__ import annotations

import functools
import importlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from common import markdown_table
from distributed_setup import Cycle, actions, build, close, shard_times, ship_by_value

#: (row label, methods timed in one process, methods timed in a shard); "module:Class.method".
STAGES: list[tuple[str, list[str], list[str]]] = [
    (
        "1. actions, sends",
        [
            "agentsim_env.scenarios.navigation:NavigationScenario.apply_actions",
            "agentsim_env.comms.stack:CommsStack.send_actions",
        ],
        [
            "agentsim_env.scenarios.navigation:NavigationScenario.apply_actions",
            "agentsim_env.comms.stack:CommsStack.send_actions",
        ],
    ),
    ("2-4. motion", ["agentsim_env.sim.world:World.run_motion"], ["agentsim_env.sim.world:World.run_motion"]),
    ("exchange: hand-overs, ghosts", [], ["agentsim_env.distributed.shard:Shard.after_motion"]),
    (
        "5. grid, collisions",
        ["agentsim_env.sim.world:World.run_collisions"],
        ["agentsim_env.sim.world:World.run_collisions"],
    ),
    ("6. groups", ["agentsim_env.sim.world:World.run_groups"], ["agentsim_env.sim.world:World.run_groups"]),
    ("exchange: offline, ghost frontier", [], ["agentsim_env.distributed.shard:Shard.after_offline"]),
    (
        "7. range graph",
        ["agentsim_env.comms.stack:CommsStack.update_graph"],
        ["agentsim_env.comms.stack:CommsStack.update_graph"],
    ),
    (
        "7. bus deliveries (shard: with its exchange)",
        ["agentsim_env.comms.bus:MessageBus.deliver"],
        ["agentsim_env.distributed.shard:Shard.deliver"],
    ),
    (
        "7. overlay hop",
        ["agentsim_env.comms.overlay:Overlay.advance_graph"],
        ["agentsim_env.distributed.shard_overlay:ShardOverlay.advance_graph"],
    ),
    (
        "7. inbox pushes",
        ["agentsim_env.comms.inbox:Inbox.push_batches"],
        ["agentsim_env.comms.inbox:Inbox.push_batches"],
    ),
    ("8. sensors", ["agentsim_env.sim.world:World.run_sensors"], ["agentsim_env.sim.world:World.run_sensors"]),
    (
        "9. scoring (shard: with the group sums' exchange)",
        [
            "agentsim_env.scenarios.navigation:NavigationScenario.score",
            "agentsim_env.scenarios.navigation:NavigationScenario.group_partials",
        ],
        [
            "agentsim_env.scenarios.navigation:NavigationScenario.score",
            "agentsim_env.scenarios.navigation:NavigationScenario.group_partials",
            "agentsim_env.distributed.shard:Shard.combine",
        ],
    ),
    (
        "observations (shard: with the far senders' exchange)",
        ["agentsim_env.env.parallel_env:AgentSimParallelEnv._flat_obs"],
        [
            "agentsim_env.distributed.shard_rollout:ShardRollout._observe",
            "agentsim_env.distributed.shard:Shard._sender_positions",
        ],
    ),
]
STEP_ONE = "agentsim_env.env.parallel_env:AgentSimParallelEnv._step_core"
STEP_SHARD = "agentsim_env.distributed.shard:Shard.act"

_RECORD: dict[str, list[float]] = {}
_ORIGINAL: dict[str, tuple[Any, str, Any]] = {}


def _resolve(target: str) -> tuple[Any, str]:
    mod, qual = target.split(":")
    owner: Any = importlib.import_module(mod)
    *path, name = qual.split(".")
    for p in path:
        owner = getattr(owner, p)
    return owner, name


def _timed(target: str, fn: Any) -> Any:
    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            _RECORD.setdefault(target, []).append(time.perf_counter() - t)

    return wrapper


def install(targets: list[str]) -> None:
    """Wrap each ``module:Class.method`` with a timer (once per process)."""
    for target in targets:
        if target in _ORIGINAL:
            continue
        owner, name = _resolve(target)
        fn = getattr(owner, name)
        _ORIGINAL[target] = (owner, name, fn)
        setattr(owner, name, _timed(target, fn))


def uninstall() -> None:
    """Put the original methods back and forget the timings."""
    for owner, name, fn in _ORIGINAL.values():
        setattr(owner, name, fn)
    _ORIGINAL.clear()
    _RECORD.clear()


def all_targets(which: int) -> list[str]:
    """Every method of the table for one process (``which=1``) or a shard (``which=2``), with the step's."""
    out = [t for row in STAGES for t in row[which]]
    return [*out, STEP_ONE if which == 1 else STEP_SHARD]


def per_step_ms(record: dict[str, list[float]], skip: int) -> dict[str, float]:
    """Mean ms per step of each method, its first ``skip`` steps left out (a method called n times a step adds
    its n calls)."""
    steps = max(len(record.get(STEP_ONE, record.get(STEP_SHARD, []))) - skip, 1)
    out = {}
    for target, times in record.items():
        per = len(times) / max(steps + skip, 1)  # calls per step
        kept = times[int(round(skip * per)) :]
        out[target] = 1e3 * float(np.sum(kept)) / steps
    return out


class TimedCycle:
    """A row policy that times the stages of the shard it runs in: ``reset`` installs the wrappers, every step
    writes the timings to ``folder``; ``inner`` (``bench_distributed.Cycle``) chooses the actions."""

    def __init__(self, inner: Any, folder: str) -> None:
        self.inner = inner
        self.folder = folder

    def reset(self, seed: int | None = None) -> None:
        """Install the shard's timers (this runs in the shard's process)."""
        install(all_targets(2))
        _RECORD.clear()
        self.inner.reset(seed)

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """The inner policy's rows; the timings so far to this shard's file."""
        if step:
            path = Path(self.folder) / f"shard-{os.getpid()}.json"
            tmp = path.with_suffix(".tmp")
            tmp.write_text(json.dumps(_RECORD))
            os.replace(tmp, path)
        return self.inner.act_rows(obs, slots, step)  # type: ignore[no-any-return]


def read_shards(folder: str) -> list[dict[str, list[float]]]:
    """The timings each shard process wrote."""
    return [json.loads(p.read_text()) for p in sorted(Path(folder).glob("shard-*.json"))]


def table_rows(
    one: dict[str, float], step_one: float, shards: list[dict[str, float]], wait_ms: float
) -> list[list[str]]:
    """Rows: stage, one process ms, half of it, each shard's ms, the slowest shard minus the half (``step_one``:
    one process's wall ms per step, policy and observations included). A stage whose methods never ran in a
    process (or that one process does not have) shows "-" there."""
    rows = []
    total_one = total_shard = 0.0
    for label, t_one, t_shard in STAGES:
        ran_one = any(t in one for t in t_one)
        a = sum(one.get(t, 0.0) for t in t_one)
        b = [sum(s.get(t, 0.0) for t in t_shard) for s in shards]
        worst = max(b) if b else 0.0
        total_one += a
        total_shard += worst
        cells = [f"{x:.1f}" if any(t in s for t in t_shard) else "-" for x, s in zip(b, shards, strict=True)]
        rows.append(
            [
                label,
                f"{a:.1f}" if ran_one else "-",
                f"{a / 2:.1f}" if ran_one else "-",
                " / ".join(cells),
                f"{worst - a / 2:+.1f}",
            ]
        )
    step_shard = max((s.get(STEP_SHARD, 0.0) for s in shards), default=0.0)
    rows.append(
        [
            "other (policy, bookkeeping)",
            f"{step_one - total_one:.1f}",
            f"{(step_one - total_one) / 2:.1f}",
            "",
            f"{(step_shard - total_shard) - (step_one - total_one) / 2:+.1f}",
        ]
    )
    rows.append(
        [
            "**step**",
            f"**{step_one:.1f}**",
            f"**{step_one / 2:.1f}**",
            " / ".join(f"**{s.get(STEP_SHARD, 0.0):.1f}**" for s in shards),
            f"**{step_shard - step_one / 2:+.1f}**",
        ]
    )
    rows.append(["of which at the exchange (waits, routing, transfers)", "-", "-", f"{wait_ms:.1f} (mean)", ""])
    return rows


def stage_table(n: int, steps: int, ray: Any) -> str:
    """Where a shard's step goes: each stage of a 2-shard rollout against half of the same stage in one process
    (``ray``: the running Ray module)."""
    ship_by_value(sys.modules[__name__])  # the shards build the timed policy from this module's code
    acts = actions(n, "full")
    env = build(n, None, api="rollout")
    env.rollout(Cycle(acts, env.scenario.act_parts()), 2, seed=0)  # compiles, as the shards' warm-up below
    stamps: list[float] = []

    def clock(env: Any, taken: int, view: Any) -> bool:
        stamps.append(time.perf_counter())
        return False

    install(all_targets(1))
    try:
        env.rollout(Cycle(acts, env.scenario.act_parts()), steps, seed=0, on_step=clock)
        one = per_step_ms(dict(_RECORD), 1)
    finally:
        uninstall()
        close(env)
    step_one = float(np.mean(np.diff(stamps[2:]))) * 1e3
    with tempfile.TemporaryDirectory() as folder:
        env = build(n, 2, "ray", "rollout")
        try:
            env.rollout(Cycle(acts, env.scenario.act_parts()), 2, seed=0)
            env.rollout(TimedCycle(Cycle(acts, env.scenario.act_parts()), folder), steps, seed=0)
            wait = shard_times(env)["wait_ms"]
        finally:
            close(env)
        shards = [per_step_ms(r, 1) for r in read_shards(folder)]
    rows = table_rows(one, step_one, shards, wait)
    return markdown_table(["stage", "one process ms", "half of it", "each shard ms", "slowest shard - half"], rows)
