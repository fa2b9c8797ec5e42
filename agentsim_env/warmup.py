"""``agentsim warmup``: compile and cache, ahead of time, every simulation kernel a shipped command reaches.

numba compiles a ``cache=True`` kernel once per signature, the types of its arguments: dtype, number of
dimensions, layout (C-contiguous or any, ``'A'``, as for a column slice or a stride-0 broadcast) and whether
the array is read-only. A command that calls a kernel with a signature the warm-up never produced compiles it
there and then. So the warm-up does not call kernels one by one: it drives, on small configs, the same code
paths the commands drive, which hands every kernel the argument types those paths hand it:

- every scenario with every scripted baseline (``agentsim run``, ``agentsim evaluate``'s strategies, the
  baselines ``agentsim train`` compares against) and with random actions (messages, falling payloads);
- the variants that reach other kernels or other signatures: navigation with comms and with pymunk physics
  (when pymunk is installed), relay long enough for relayed messages;
- ``BatchedEnv``, the vector env ``agentsim train`` learns on, for every scenario;
- the distributed front end over in-process shards (``agentsim run --shards``), for the scenarios that shard,
  also with arguments and replies passed as Ray passes them (read-only arrays).

The kernels of those paths are the same at any size, so small worlds and short episodes suffice; the whole
warm-up then takes about as long as compiling takes.
"""

from __future__ import annotations

import pickle
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

#: Small configs per scenario for the warm-up (the kernels' argument types do not depend on the sizes).
WARMUP_CONFIG: dict[str, dict[str, Any]] = {
    "navigation": {"n_agents": 2},
    "rendezvous": {"n_agents": 2},
    "uav_release": {"zones": "tiny", "n_uavs": 2},
}
#: Steps of each short episode.
WARMUP_STEPS = 5
#: Worlds of the warm-up's ``BatchedEnv``.
WARMUP_WORLDS = 2


@dataclass(frozen=True)
class Variant:
    """One extra run of a scenario's default baseline: config keys over its warm-up config.

    Attributes:
        config: Scenario config keys over ``WARMUP_CONFIG`` (``max_steps`` included).
        needs: A module that must import for the variant to run (an optional extra); skipped when it does not.
    """

    config: dict[str, Any] = field(default_factory=dict)
    needs: str | None = None


#: Extra runs of the default baseline that reach kernels, or kernel signatures, the short episodes do not.
VARIANTS: dict[str, list[Variant]] = {
    "navigation": [
        Variant({"comms": {}}),
        Variant({"physics": "pymunk", "collisions": False}, needs="pymunk"),
    ],
    # direct, flooded and relayed messages (forwarded once the scout has seen its target), for inbox_pair_forms
    "relay": [
        Variant({"max_steps": 60}),
        Variant({"max_steps": 30, "comms": {"loss": 0.1}}),
    ],  # lossy: keyed draws
}
#: Scenarios that run over shards (``agentsim run --shards``), with config keys over the warm-up config: relay
#: long enough for floods to cross from one shard to the other.
SHARDED: dict[str, dict[str, Any]] = {"navigation": {}, "relay": {"max_steps": 60}}


def _config(name: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    return {**WARMUP_CONFIG.get(name, {}), "max_steps": WARMUP_STEPS, **(extra or {})}


def _random_episode(env: Any) -> None:
    """Step ``env`` with seeded random actions until the episode ends."""
    env.reset(seed=0)
    for a in env.agents:
        env.action_space(a).seed(0)
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})


def _play(name: str, env: Any, every: bool) -> None:
    """One episode of ``env`` per scripted baseline of ``name`` (only the default one unless ``every``), then a
    random one; closes ``env``."""
    from agentsim_env.policies.registry import BASELINES, make_policy
    from agentsim_env.policies.rollout import run_episode

    try:
        for policy in list(BASELINES.get(name, {}))[: None if every else 1]:
            run_episode(env, make_policy(name, env, policy), 0)
            # the array path of agentsim run (over shards: the policy inside them), without and with an observer
            env.rollout(policy, env.scenario.max_steps, seed=0)
            env.rollout(policy, env.scenario.max_steps, seed=0, on_step=lambda *args: None)
        _random_episode(env)
    finally:
        env.close()


def _baselines(name: str, config: dict[str, Any], every: bool = True) -> None:
    """One episode per scripted baseline of ``name`` (only the default one unless ``every``), then a random one."""
    import agentsim_env

    _play(name, agentsim_env.make(name, **config), every)


def _batched(name: str, config: dict[str, Any] | None = None, num_threads: int = 1) -> None:
    """A few steps of ``BatchedEnv`` (training's vector env) with random actions, past an episode's end."""
    from agentsim_env.env.vector import BatchedEnv

    batch = BatchedEnv(name, WARMUP_WORLDS, num_threads=num_threads, **(config or _config(name)))
    rng = np.random.default_rng(0)
    batch.reset(seed=0)
    for _ in range(WARMUP_STEPS + 1):  # one step past max_steps: the worlds reset automatically
        batch.step(rng.uniform(-1.0, 1.0, (batch.n_worlds, batch.n_agents, batch.act_dim)))


def _threaded(name: str, config: dict[str, Any]) -> None:
    """``_batched`` over 4 threads with ranges of one slot or more, so the kernels that only big worlds split (the
    range graph's and the overlay's joins, the delivery look-ups, the sends' rows, the bus's fan-out and filters,
    and from 4 ranges the inbox push's per-range count) compile here too."""
    from agentsim_env.core import threads

    saved = threads.MIN_ROWS
    threads.MIN_ROWS = 1
    try:
        _batched(name, config, num_threads=4)
    finally:
        threads.MIN_ROWS = saved


def _through_store(obj: Any) -> Any:
    """``obj`` as a Ray actor receives it (or the driver, a reply): pickled with out-of-band buffers (protocol 5)
    and read back from immutable copies of them, so its arrays come back read-only, as from Ray's object store."""
    buffers: list[pickle.PickleBuffer] = []
    data = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    return pickle.loads(data, buffers=[b.raw().tobytes() for b in buffers])


class _StoreTransport:
    """In-process shards whose arguments and replies travel as through Ray (``_through_store``).

    Ray hands a shard its arguments, and the coordinator its replies, as read-only arrays: kernels called
    with them compile read-only signatures the plain in-process backend never makes.
    """

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.n_shards = inner.n_shards
        self.address = inner.address

    def call(
        self, method: str, calls: dict[int, tuple[Any, ...]], timeout_s: float, on_reply: Any = None
    ) -> dict[int, Any]:
        """Run ``method`` on the shards with their arguments and replies passed through ``_through_store``."""
        from agentsim_env.distributed.backends import Failure

        del on_reply  # as the in-process shards: the replies come all at once
        sent = {k: _through_store(args) for k, args in calls.items()}
        replies = self.inner.call(method, sent, timeout_s)
        return {k: r if isinstance(r, Failure) else _through_store(r) for k, r in replies.items()}

    def __getattr__(self, name: str) -> Any:  # restart, kill, close: as the in-process shards do them
        return getattr(self.inner, name)


def _sharded(name: str) -> None:
    """The default baseline and random actions over two in-process shards (the shard code Ray runs in its
    workers), once as they are and once with Ray's read-only transport."""
    from agentsim_env.distributed.env import make as make_distributed
    from agentsim_env.distributed.row_kernels import warm

    warm()  # the driver's row copies of Ray shards sharing memory with it (the local shards below do not)
    for store in (False, True):
        env = make_distributed(name, shards=2, backend="local", **_config(name, SHARDED[name]))
        if store:
            env.coordinator.backend = _StoreTransport(env.coordinator.backend)
            for shard in env.coordinator.backend.inner.shards.values():  # and the exchange between shards
                shard._swap = _stored_swap(shard._swap)
        _play(name, env, every=False)


def _stored_swap(swap: Callable[..., Any]) -> Callable[..., Any]:
    """A shard's exchange whose posts and parts arrive read-only (``_through_store``), as the exchange actor gets
    the posts of Ray shards: the routing's kernels compile for read-only arrays too."""

    def stored(key: Any, k: int, payload: Any) -> Any:
        return _through_store(swap(key, k, _through_store(payload)))

    return stored


def _importable(module: str | None) -> bool:
    if module is None:
        return True
    import importlib.util

    return importlib.util.find_spec(module) is not None


def scenario_steps(name: str) -> list[tuple[str, Callable[[], None]]]:
    """The warm-up's runs of scenario ``name``, each a label and a function that runs it."""
    steps: list[tuple[str, Callable[[], None]]] = [("baselines", lambda: _baselines(name, _config(name)))]
    for i, v in enumerate(VARIANTS.get(name, [])):
        if _importable(v.needs):
            steps.append((f"variant {i}", partial(_baselines, name, _config(name, v.config), every=False)))
    steps.append(("batched", lambda: _batched(name)))
    for i, v in enumerate(VARIANTS.get(name, [])):
        if "comms" in v.config:
            steps.append((f"threads, variant {i}", partial(_threaded, name, _config(name, v.config))))
    if name in SHARDED:
        steps.append(("sharded", lambda: _sharded(name)))
    return steps


def warm_up(report: Callable[[str, float], None] | None = None) -> float:
    """Run every warm-up step of every registered scenario, which compiles and caches the kernels they reach.

    Args:
        report: Called with each scenario's name and its seconds once that scenario is done.

    Returns:
        The total seconds.
    """
    from agentsim_env.scenarios.registry import usable_scenarios

    start = time.perf_counter()
    for name in usable_scenarios():  # a plug-in that does not load is left out (with a warning)
        t0 = time.perf_counter()
        for _, run in scenario_steps(name):
            run()
        if report is not None:
            report(name, time.perf_counter() - t0)
    return time.perf_counter() - start


__all__ = [
    "SHARDED",
    "VARIANTS",
    "WARMUP_CONFIG",
    "WARMUP_STEPS",
    "WARMUP_WORLDS",
    "Variant",
    "scenario_steps",
    "warm_up",
]
