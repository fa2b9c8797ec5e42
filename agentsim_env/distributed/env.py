"""The distributed env: the same PettingZoo ``ParallelEnv`` (and array front end) over K shards.

``make(name, shards=K, ray_address=None, **config)`` builds the scenario's env whose steps run over K shard
processes (Ray actors; ``backend="local"`` keeps them in this process): the API, spaces, agent ids, infos and
results are those of ``agentsim_env.make``, so training code does not change. ``env.rollout(policy, steps)`` runs
the policy inside the shards (only counts come back). ``env.world`` is the coordinator's mirror (positions, scene,
groups; kept current while the step API or a hook needs it), so ``render``, ``state()``, the recorder and the web
viewer work as on one process; ``send_message`` and ``assign_group`` run on the agent's shard (inboxes and
heartbeats live there). ``env.shards`` lists each shard's address, last answer and step time; ``env.add_objects``
adds static objects at run time (every shard has them before the next step).
"""

from __future__ import annotations

import dataclasses
import os
import time
from typing import Any

import numpy as np

from agentsim_env.core.validation import check_choice, check_float, check_int
from agentsim_env.distributed.bridge import Bridge
from agentsim_env.distributed.coordinator import Coordinator, ShardInfo
from agentsim_env.distributed.partition import Strips, halo_width
from agentsim_env.distributed.shard import Shard
from agentsim_env.env.buffers import Recycled
from agentsim_env.env.parallel_env import ENV_KEYS, AgentSimParallelEnv
from agentsim_env.env.rollout import RolloutResult, StepView, build_policy, check_seed, check_steps
from agentsim_env.env.vector import BatchedEnv
from agentsim_env.scenarios.base import Scenario
from agentsim_env.scenarios.registry import make_scenario, scenario_class, usable_scenarios

BACKENDS = ("ray", "local")
DEFAULT_TIMEOUT_S = 5.0
"""Seconds a shard may take to answer one call before it is declared offline."""


def check_shardable(scenario: Scenario, shards: int) -> None:
    """Refuse, with the option to change, a scenario or config that cannot run over shards.

    Raises:
        ValueError: Naming the scenario (and the shardable ones), ``physics`` or ``comms.overlay_full``.
    """
    c = scenario.config
    if not scenario.shardable:
        ok = [n for n in usable_scenarios() if scenario_class(n).shardable]
        raise ValueError(
            f"scenario {scenario.name!r} cannot run over shards (shards={shards}); the scenarios that "
            f"can are {ok}; use shards=None for one process"
        )
    if getattr(c, "physics", "kinematic") == "pymunk":
        raise ValueError(
            f"physics='pymunk' cannot run over shards (shards={shards}): its contact solver needs every "
            f"body in one space; use physics='kinematic', or shards=None"
        )
    comms = getattr(c, "comms", None)
    if comms is not None and comms.overlay_full:
        raise ValueError(
            f"comms.overlay_full=True cannot run over shards (shards={shards}): a flood would cross "
            f"every shard within one step; use overlay_full=False, or shards=None"
        )


def check_options(shards: Any, backend: Any, ray_address: Any, timeout_s: Any) -> None:
    """Validate the distribution options before anything is built.

    Raises:
        ValueError: Naming ``shards``, ``backend``, ``timeout_s`` or ``ray_address`` and what is allowed.
    """
    check_int("shards", shards, 1, 1024)
    check_choice("backend", backend, BACKENDS)
    check_float("timeout_s", timeout_s, 0.0, 3600.0, lo_open=True)
    if ray_address is not None:
        if backend != "ray":
            raise ValueError(f"ray_address is for backend='ray', got backend={backend!r}")
        from agentsim_env.distributed.ray_backend import check_address

        check_address(ray_address)


def build_coordinator(
    scenario: Scenario, world: Any, shards: int, backend: str, ray_address: str | None, timeout_s: float
) -> Coordinator:
    """Start the shards of ``world`` (the mirror of a front end); the options were checked (``check_options``)."""
    strips = Strips.build(world.config.bounds, int(shards), halo_width(world))
    name, config = scenario.name, _config_fields(scenario)

    def copy() -> Strips:  # the coordinator, the exchange and every shard each keep their own
        return Strips(strips.edges.copy(), strips.halo, strips.owner.copy())

    bridge = Bridge(copy(), world.state.n_slots)
    if backend == "local":
        from agentsim_env.distributed.backends import LocalShards

        be: Any = LocalShards(lambda k, swap: Shard(k, name, config, copy(), swap), int(shards), bridge)
    else:
        from agentsim_env.distributed.ray_backend import RayShards

        be = RayShards(name, config, copy(), int(shards), ray_address, bridge)
    return Coordinator(scenario, world, strips, be, timeout_s)


class DistributedParallelEnv(AgentSimParallelEnv):
    """``AgentSimParallelEnv`` whose steps run over shards (see the module docstring).

    Args:
        scenario: The scenario (validated config).
        shards: Number of shards K (>= 1).
        backend: ``"ray"`` (shard actors on a Ray cluster) or ``"local"`` (shards in this process).
        ray_address: A Ray cluster's address (``"host:port"``, ``"ray://host:port"`` or ``"auto"``); ``None``
            starts a local cluster on 127.0.0.1.
        timeout_s: Deadline of every call to a shard; a shard that misses it is declared offline.
        **env_kw: ``render_mode``, ``obs_format``, ``action_format``, ``check_finite``, ``num_threads`` (the
            coordinator's stages, observations included; each shard runs one thread).
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        shards: int,
        backend: str = "ray",
        ray_address: str | None = None,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        **env_kw: Any,
    ) -> None:
        check_options(shards, backend, ray_address, timeout_s)
        check_shardable(scenario, shards)
        super().__init__(scenario, **env_kw)
        self.coordinator = build_coordinator(scenario, self.world, shards, backend, ray_address, timeout_s)
        self.metadata["shards"] = int(shards)

    @property
    def shards(self) -> list[ShardInfo]:
        """Each shard's index, address, liveness, last answer, last step and step time."""
        return self.coordinator.shards

    def add_objects(self, kind: Any, centre: Any, half: Any) -> None:
        """Add static objects at run time, as ``core.scene.Scene.add`` takes them (``"box"``, ``"cylinder"`` or
        ``"sphere"``, centres ``(n, 3)``, half-extents ``(n, 3)``): every shard has them before the next step."""
        self.coordinator.add_objects(kind, centre, half)

    def _reset_core(self, seed: np.random.SeedSequence) -> None:
        self.coordinator.reset(seed)

    def _step_core(self, parts: dict[str, np.ndarray], acting: np.ndarray) -> tuple[Any, np.ndarray]:
        return self.coordinator.step(parts, acting)

    def _flat_obs(self, rows: np.ndarray, result: Any = None) -> np.ndarray:
        obs = self.coordinator.obs  # built on the shards, gathered by the step
        assert obs is not None
        out = self._obs_out.get()
        np.copyto(out, obs)
        return out

    def send_message(self, sender: str, payload: Any, *, to: str | None = None, group: int | None = None) -> bool:
        """``AgentSimParallelEnv.send_message``: checked here, sent on the sender's shard (its bus, its bandwidth)."""
        with self._guard.hold("send_message"):
            s, target, to_group, pay = self._message(sender, payload, to, group)
            return bool(self.coordinator.call_owner(s, "send", s, target, pay, to_group)["accepted"])

    def assign_group(self, agent: str, group: int) -> None:
        """``AgentSimParallelEnv.assign_group``: on the agent's shard (its heartbeats), and in the mirror."""
        super().assign_group(agent, group)  # checks, and the mirror's group array for render() and state()
        slot = self._index[agent]
        self.coordinator.call_owner(slot, "assign_group", slot, int(group))

    def rollout(self, policy: Any, steps: int, seed: int | None = None, *, on_step: Any = None) -> RolloutResult:
        """``AgentSimParallelEnv.rollout`` with the policy inside the shards (observations stay there).

        Each shard builds the policy (a baseline name or a trained model folder; a policy object is sent as it
        is) and acts for its own agents; a step answers only counts. The results equal one process's. With an
        ``on_step`` observer the shards also send the acting agents' positions and infos each step (what the
        observer reads: ``env.world``'s positions and the ``StepView``); with step hooks (a recorder, the viewer),
        a render mode or ``ended_agents="stay"`` the rollout runs through the step API (every agent's data).
        """
        co = self.coordinator
        if self.world.hooks or self.render_mode or self._stay:
            return super().rollout(policy, steps, seed, on_step=on_step)
        steps, pseed = check_steps(steps), check_seed(seed)
        if isinstance(policy, (str, os.PathLike)):  # a bad name is one error here, not a failure in every shard
            build_policy(self.scenario.name, _config_fields(self.scenario), policy)
        if seed is not None:
            self._seeds.reset(seed)
        self._guard.enter("rollout")
        try:
            t0 = time.perf_counter()
            watch = None
            if on_step is not None:  # the observer reads the masks, infos and env.world's positions of each step

                def watch(taken: int, acted: Any, live: Any, info: Any) -> bool:
                    if acted is None:  # right after the reset
                        return bool(on_step(self, 0, None))
                    return bool(on_step(self, taken, StepView(acted, live, info)))

            out = co.rollout(policy, steps, self._seeds.next(), pseed, 0, self.scenario.max_steps, watch)
            wall = time.perf_counter() - t0
            self._steps, self._started = out["steps"], True
            live = out["live"]
            self._set_agents([self.possible_agents[i] for i in live.tolist()], live)
        finally:
            self._guard.exit()
        n = len(self.possible_agents)
        return RolloutResult(
            steps=out["steps"],
            returns=out["returns"][:n].copy(),
            final_pos=out["final_pos"][:n].copy(),
            events=out["events"],
            info_sums={k: float(v.sum()) for k, v in out["sums"].items()},
            agent_steps=out["agent_steps"],
            wall_s=wall,
            steps_per_s=out["steps"] / wall if wall > 0 else 0.0,
        )

    def close(self) -> None:
        """Stop the shards (and the viewer or window, if any)."""
        self.coordinator.backend.close()
        super().close()


class DistributedBatchedEnv(BatchedEnv):
    """The array front end (``BatchedEnv`` of one world) over shards: ``(1, N, ...)`` arrays in and out.

    Args:
        name: A scenario that can run over shards.
        shards: Number of shards.
        backend: ``"ray"`` or ``"local"``.
        ray_address: A Ray cluster's address, or ``None`` for a local one.
        timeout_s: Deadline of every call to a shard.
        check_finite: As for ``BatchedEnv``.
        **config: Scenario config keys.
    """

    def __init__(
        self,
        name: str,
        shards: int = 2,
        *,
        backend: str = "ray",
        ray_address: str | None = None,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        check_finite: bool | None = None,
        **config: Any,
    ) -> None:
        check_options(shards, backend, ray_address, timeout_s)
        check_shardable(make_scenario(name, **config), shards)
        super().__init__(name, 1, check_finite=check_finite, **config)
        self.coordinator = build_coordinator(self.scenario, self.world, shards, backend, ray_address, timeout_s)
        self._obs_out = SharedOut(self.coordinator, Recycled((self.world.state.n_slots, self.obs_dim), np.float32))

    @property
    def shards(self) -> list[ShardInfo]:
        """Each shard's index, address, liveness, last answer, last step and step time."""
        return self.coordinator.shards

    def _reset_core(self, worlds: list[int], seeds: list[np.random.SeedSequence]) -> None:
        self.coordinator.reset(seeds[0])

    def _step_core(
        self, parts: dict[str, np.ndarray], acting: np.ndarray, out: np.ndarray | None = None
    ) -> tuple[Any, np.ndarray]:
        return self.coordinator.step(parts, acting, out)

    def _flat_obs(
        self, rows: np.ndarray | None = None, step: int = 0, result: Any = None, out: np.ndarray | None = None
    ) -> np.ndarray:
        obs = self.coordinator.obs  # built on the shards, gathered by the step
        assert obs is not None
        filled = None if out is None else self.coordinator.filled(out)
        if filled is not None:  # the step wrote the rows there (or into its copy)
            flat = filled
        elif out is None:
            flat = obs.copy()
        else:
            np.copyto(out, obs)
            flat = out
        return flat.reshape(self.n_worlds, self.n_agents, self.obs_dim)

    def close(self) -> None:
        """Stop the shards."""
        self.coordinator.backend.close()


class SharedOut:
    """The array front end's observation arrays over shards: one the shards beside the driver fill themselves
    (``Coordinator.obs_buffer``) when one is free, else the front end's own recycled array (``fallback``)."""

    def __init__(self, coordinator: Any, fallback: Recycled) -> None:
        self.coordinator = coordinator
        self.fallback = fallback

    def get(self) -> np.ndarray:
        """An ``(S, obs_dim)`` float32 array for the next step's observations (uninitialised)."""
        a = self.coordinator.obs_buffer()
        return self.fallback.get() if a is None else a


def _config_fields(scenario: Scenario) -> dict[str, Any]:
    """The scenario's config as keyword arguments that rebuild it (nested configs as their dataclasses)."""
    c = scenario.config
    return {f.name: getattr(c, f.name) for f in dataclasses.fields(c)}


def make(
    name: str,
    shards: int = 2,
    ray_address: str | None = None,
    *,
    backend: str = "ray",
    timeout_s: float = DEFAULT_TIMEOUT_S,
    **config: Any,
) -> DistributedParallelEnv:
    """The ParallelEnv of scenario ``name`` over ``shards`` shard processes.

    Args:
        name: A registered scenario that can run over shards (``navigation``, ``relay``).
        shards: Number of shards (strips of the map), >= 1.
        ray_address: A Ray cluster to join; ``None`` starts a local one bound to 127.0.0.1.
        backend: ``"ray"`` or ``"local"`` (every shard in this process: for debugging; no speed-up).
        timeout_s: Deadline of every call to a shard, in seconds.
        **config: Env keys (``render_mode``, ``obs_format``, ``action_format``, ``check_finite``) and the
            scenario's config fields, as for ``agentsim_env.make``.

    Raises:
        ValueError: For a bad option (named), a scenario or config that cannot run over shards, or strips
            narrower than the halo.
        ImportError: With the install hint, when ``backend="ray"`` and Ray is not installed.
    """
    env_kw = {k: config.pop(k) for k in ENV_KEYS if k in config}
    return DistributedParallelEnv(
        make_scenario(name, **config),
        shards=shards,
        backend=backend,
        ray_address=ray_address,
        timeout_s=timeout_s,
        **env_kw,
    )
