"""What the sharded-world benchmarks share: the scenario config and the action cycle, starting Ray, building and
closing one process or a sharded env, the shards' per-step times.

``navigation`` with the full-stack comms config of ``bench_comms`` (collisions off, so the population stays
constant); the actions come from a fixed cycle of ``bench_comms`` action arrays, played by a row policy
(``Cycle``): the same actions in every system, so the results can be compared. Objects of the benchmark modules
travel to Ray's workers by value (``ship_by_value``): the benchmarks folder is not on the workers' path.
"""

from __future__ import annotations

import gc
import os
import sys
from typing import Any

import bench_comms as bc  # first: through common, it pins the thread pools before numpy loads
import numpy as np

SHARD_TIMEOUT_S = 120.0  # per call: a loaded shared machine must not declare a slow shard offline mid-benchmark


def fmt_bytes(x: float) -> str:
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
    ship_by_value(sys.modules[__name__])
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


def shard_times(env: Any) -> dict[str, float]:
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


def ship_by_value(*modules: Any) -> None:
    """Let Ray send the objects of ``modules`` (benchmark modules, not importable on the workers) by value."""
    from agentsim_env.distributed.ray_backend import import_ray

    for module in modules:
        import_ray().cloudpickle.register_pickle_by_value(module)
