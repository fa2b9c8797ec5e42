"""Whole episodes on arrays: ``env.rollout(policy, steps, seed)`` without per-agent dicts.

``AgentSimParallelEnv.rollout`` runs a policy for up to ``steps`` steps through the env's own array pipeline:
observation rows of the live agents go to the policy, its action rows are scattered into the per-part arrays
``step`` builds from dicts, and the world steps (``run_step``). It gives the results of stepping through
``step()`` with the same policy (returns, final positions, events), at a fraction of the cost: building dicts of
100,000 agents' observations and actions takes about 100 ms a step.

A policy acts on rows (:class:`ArrayPolicy`): ``act_rows(obs, slots, step)`` maps the observation parts of some
agents (one row each, in the order of ``slots``) to their action parts. Rows are independent: acting on a
subset of the slots gives exactly those rows of acting on all, so a process that holds only some agents (a
shard) gets the same actions. :func:`build_policy` makes one from picklable inputs (scenario name, config, a
baseline name or a trained model folder), as a shard process needs; the scripted baselines and trained models
act on rows natively, and any dict ``Policy`` is wrapped (:class:`DictRows`, the slow path).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from agentsim_env.env.batch_kernels import scatter_part

#: Reference of the policy builder (``"module:function"``): it lives in ``agentsim_env.policies``, a layer above
#: the env, so it is looked up by name when a policy is given by name.
POLICY_BUILDER = "agentsim_env.policies.arrays:build_policy"
#: The counters of :attr:`RolloutResult.events`.
EVENT_KEYS = ("collisions", "offline", "delivered", "dropped")


@dataclass(frozen=True)
class StepView:
    """One step of a rollout as arrays over slots, for an ``on_step`` observer (read it, do not keep it).

    Attributes:
        acted: ``(S,)`` bool, the slots that acted in the step (the agents ``step()`` would have given infos).
        live: ``(S,)`` bool, the slots still live after it (``env.agents`` in ``step()``'s bookkeeping).
        info: The scenario's info arrays ``(S,)`` of the step (``step()``'s per-agent infos, as arrays).
    """

    acted: np.ndarray
    live: np.ndarray
    info: dict[str, np.ndarray]


#: ``on_step(env, step, view)``: called after the reset (``step`` 0, ``view`` None) and after every step (``step``
#: counts from 1, ``view`` a :class:`StepView`); True after a step stops the rollout there.
RolloutCallback = Callable[[Any, int, StepView | None], bool | None]


@runtime_checkable
class ArrayPolicy(Protocol):
    """A policy acting on rows of observation arrays (module docstring).

    ``act_rows`` must keep rows independent: the row of an agent depends on its own observation row, its slot,
    ``step`` and the seed given to ``reset``, never on which other agents are in the call (a random policy
    draws keyed by (seed, step, slot), not from one stream).
    """

    def reset(self, seed: int | None = None) -> None:
        """Start an episode (``seed`` keys any randomness)."""
        ...

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """Action parts ``{part: (n, *shape)}`` of the agents ``slots`` from their observation parts.

        Args:
            obs: Observation parts ``{part: (n, *shape)}`` float32, row ``i`` being agent ``slots[i]``'s.
            slots: ``(n,)`` int64 agent indices in ``possible_agents`` order.
            step: Steps since the reset (0 for the first action).
        """
        ...


@dataclass(frozen=True)
class RolloutResult:
    """What a rollout did.

    Attributes:
        steps: Steps taken (up to the ``steps`` asked for; fewer when the episode ended first).
        returns: ``(N,)`` float64, every agent's sum of rewards, in ``possible_agents`` order.
        final_pos: ``(N, 3)`` float64, every agent's position at the end (where it stopped, for one that ended).
        events: Counts over the run: ``collisions`` (collision events), ``offline`` (agents taken offline by the
            world: collisions, heartbeat timeouts, lost shards), ``delivered`` (bus deliveries and overlay reads)
            and ``dropped`` (bus messages dropped).
        info_sums: Per numeric info key, the sum over agents and steps (what ``step()``'s infos would add up to).
        agent_steps: Sum over steps of the agents that acted.
        wall_s: Wall-clock seconds of the rollout (reset included).
        steps_per_s: ``steps / wall_s``.
    """

    steps: int
    returns: np.ndarray
    final_pos: np.ndarray
    events: dict[str, int]
    info_sums: dict[str, float] = field(default_factory=dict)
    agent_steps: int = 0
    wall_s: float = 0.0
    steps_per_s: float = 0.0

    @property
    def agent_steps_per_s(self) -> float:
        """Agent-steps per second (``agent_steps / wall_s``)."""
        return self.agent_steps / self.wall_s if self.wall_s > 0 else 0.0

    def summary(self) -> str:
        """A short Markdown table of the run."""
        lines = [
            "| metric | value |",
            "|---|---|",
            f"| steps | {self.steps} |",
            f"| mean return | {float(np.mean(self.returns)) if self.returns.size else 0.0:.3f} |",
        ]
        lines += [f"| {k} | {v} |" for k, v in self.events.items()]
        lines += [
            f"| env-steps/s | {self.steps_per_s:.1f} |",
            f"| agent-steps/s | {self.agent_steps_per_s:.0f} |",
        ]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def count_events(events: Any) -> dict[str, int]:
    """The :data:`EVENT_KEYS` counts of one step's ``StepEvents`` (``world.last_events``)."""
    offline = int(events.went_offline.size + events.timed_out.size + events.lost.size)
    delivered = dropped = 0
    comms = events.comms
    if comms is not None:
        if comms.bus is not None:
            delivered += int(comms.bus.delivered.msg.shape[0])
            dropped += int(comms.bus.dropped.msg.shape[0])
        if comms.overlay is not None:
            delivered += len(comms.overlay)
    return {
        "collisions": len(events.collisions),
        "offline": offline,
        "delivered": delivered,
        "dropped": dropped,
    }


class DictRows:
    """A dict ``Policy`` (``act(observations) -> actions``) acting on rows: the slow path.

    It builds one observation dict per given row and reads the actions back into arrays, which costs about
    a microsecond per agent and part each step; rows are independent only as far as the wrapped policy's are.

    Args:
        policy: The dict policy.
        agents: ``possible_agents`` (slot ``i`` is agent ``agents[i]``).
        act_parts: The env's action parts (``scenario.act_parts()``), to read flat actions back.
    """

    def __init__(self, policy: Any, agents: list[str], act_parts: Mapping[str, Any]) -> None:
        self.policy = policy
        self.agents = list(agents)
        self.parts = dict(act_parts)

    def reset(self, seed: int | None = None) -> None:
        """Reset the wrapped policy."""
        self.policy.reset(seed)

    def act_rows(self, obs: dict[str, np.ndarray], slots: np.ndarray, step: int) -> dict[str, np.ndarray]:
        """Dicts for the given rows, the wrapped policy's ``act``, its actions stacked per part."""
        names = [self.agents[int(s)] for s in slots]
        keys = list(obs)
        acts = self.policy.act({a: {k: obs[k][i] for k in keys} for i, a in enumerate(names)})
        out: dict[str, np.ndarray] = {}
        start = 0
        for name, p in self.parts.items():
            if names and not isinstance(acts[names[0]], Mapping):  # flat actions: the parts in layout order
                rows = [np.asarray(acts[a], dtype=np.float32).reshape(-1)[start : start + p.size] for a in names]
            else:
                rows = [np.asarray(acts[a][name], dtype=np.float32) for a in names]
            start += p.size
            out[name] = np.stack(rows).reshape(len(names), *p.shape) if names else np.zeros((0, *p.shape))
        return out


def build_policy(scenario: str, config: Mapping[str, Any], policy: Any, **kwargs: Any) -> ArrayPolicy:
    """An :class:`ArrayPolicy` of ``scenario`` from picklable inputs (``agentsim_env.policies.arrays``).

    Args:
        scenario: The scenario name.
        config: Its config (the env's scenario keys).
        policy: A registered baseline name (None: the scenario's default), a trained model folder or ``.zip``, a
            dict ``Policy`` (wrapped: the slow path) or an ``ArrayPolicy`` (returned as it is).
        **kwargs: Passed on (``env``: an env of that scenario to configure the policy from).

    Returns:
        The policy.
    """
    module, _, attr = POLICY_BUILDER.partition(":")
    builder = getattr(importlib.import_module(module), attr)
    return builder(scenario, config, policy, **kwargs)  # type: ignore[no-any-return]


def check_steps(steps: Any) -> int:
    """``steps`` as an int, or a ValueError naming it (an integer >= 1)."""
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1, got {steps!r}")
    return int(steps)


def check_seed(seed: Any) -> int | None:
    """``seed`` as an int or None, or a ValueError naming it (None or an integer >= 0)."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be None or an integer >= 0, got {seed!r}")
    return int(seed)


def _array_policy(env: Any, policy: Any) -> ArrayPolicy:
    """``policy`` as rows: an ArrayPolicy as it is, anything else through ``build_policy`` with ``env``."""
    if isinstance(policy, ArrayPolicy):
        return policy
    return build_policy(env.scenario.name, {}, policy, env=env)


def run_rollout(
    env: Any,
    policy: Any,
    steps: int,
    seed: int | None = None,
    *,
    on_step: RolloutCallback | None = None,
    through_step: bool = False,
) -> RolloutResult:
    """Reset ``env`` with ``seed`` and run ``policy`` for up to ``steps`` steps (module docstring).

    Args:
        env: An ``AgentSimParallelEnv`` (or a subclass that keeps its ``_step_core`` contract); with
            ``through_step``, also a wrapper of one (``agentsim_env.wrappers.ParallelEnvWrapper``).
        policy: An :class:`ArrayPolicy`, a baseline name, a trained model folder or a dict ``Policy``.
        steps: Steps to run, >= 1 (fewer when every agent ends first).
        seed: Reset seed (None: a fresh episode, as ``reset()`` starts one); also given to ``policy.reset``.
        on_step: Called with ``(env, 0, None)`` after the reset and ``(env, steps so far, StepView)`` after
            every step; True after a step ends the rollout there.
        through_step: Run through ``env.reset`` and ``env.step`` with dicts (same results, slow): for a front
            end that overrides them (a recording one), where only they do everything.

    Returns:
        The result; the env is left at the end of the rollout (``agents`` holds the agents still live, and
        ``step()`` can go on from there).

    Raises:
        ValueError: A bad ``policy`` (the registered names are listed), ``steps`` or ``seed``, or a policy that
            returned a NaN, inf or misshapen action part (named).
    """
    steps = check_steps(steps)
    seed = check_seed(seed)
    rows = _array_policy(env, policy)
    t0 = time.perf_counter()
    if through_step:
        return _dict_loop(env, rows, steps, seed, on_step, t0)
    env._guard.enter("rollout")
    try:
        return _array_loop(env, rows, steps, seed, on_step, t0)
    finally:
        env._guard.exit()


def _array_loop(
    env: Any, policy: ArrayPolicy, steps: int, seed: int | None, on_step: RolloutCallback | None, t0: float
) -> RolloutResult:
    """The rollout on arrays: the same stages and bookkeeping as ``reset`` and ``step``, without dicts."""
    flat = env._begin(seed)  # reset without its dicts
    policy.reset(seed)
    sc, world = env.scenario, env.world
    n_slots = world.state.n_slots
    act_parts = env._act_parts
    live = env._live_idx.copy()
    acting = env._acting.copy()
    # a dict policy may read env.agents (the uav_release strategies do): keep it current, as step() does
    track = isinstance(policy, DictRows)
    if on_step is not None:
        on_step(env, 0, None)
    returns = np.zeros(n_slots, dtype=np.float64)
    events = dict.fromkeys(EVENT_KEYS, 0)
    acc: dict[str, np.ndarray] = {}
    ended_t = np.zeros(n_slots, dtype=bool)
    ended_u = np.zeros(n_slots, dtype=bool)
    taken = agent_steps = 0
    while taken < steps and live.size:
        n = live.size
        rows = flat[live] if n != n_slots else flat
        obs = {k: rows[:, sl].reshape(n, *shape) for k, (sl, shape) in zip(env._obs_keys, env._obs_cols)}
        acts = policy.act_rows(obs, live, taken)
        parts = {name: scatter_part_checked(name, acts, p, live, n_slots) for name, p in act_parts.items()}
        res, terminated = env._step_core(parts, acting.copy())
        env._steps += 1
        taken += 1
        agent_steps += n
        over = env._steps >= sc.max_steps
        truncated = acting & ~terminated if over else np.zeros(n_slots, dtype=bool)
        flat = env._flat_obs(acting, res)
        # by index (``live`` holds the acting slots): cheaper than a mask once some agents ended
        returns[live] += np.asarray(res.rewards, dtype=np.float64)[live]
        for k, v in count_events(world.last_events).items():
            events[k] += v
        for k, arr in res.info.items():
            a = np.asarray(arr)
            if a.dtype != bool:  # per agent first, so any split of the agents adds them up the same way
                if k not in acc:
                    acc[k] = np.zeros(n_slots, dtype=np.float64)
                acc[k][live] += a[live]
        ended_t |= terminated
        ended_u |= truncated
        gone = terminated | truncated
        acted = acting.copy() if on_step is not None else acting
        if gone.any():
            acting &= ~gone
            live = live[acting[live]]
            if track:
                env._set_agents([env.possible_agents[i] for i in live.tolist()], live)
        if on_step is not None and on_step(env, taken, StepView(acted, acting.copy(), res.info)):
            break
    # leave the env where step() would have left it: the live agents, the flags of the ended ones
    names = env.possible_agents
    env._set_agents([names[i] for i in live.tolist()], live)
    if env._stay:
        env._terminated |= ended_t
        env._truncated |= ended_u
        if not live.size:
            env.agents = []
    sums = {k: float(v.sum()) for k, v in acc.items()}
    return _result(env, taken, returns, events, sums, agent_steps, t0)


def scatter_part_checked(name: str, acts: Mapping[str, Any], part: Any, live: np.ndarray, n_slots: int) -> np.ndarray:
    """One action part of the live rows over every slot, clipped to its bounds (``step``'s rule)."""
    if name not in acts:
        raise ValueError(f"the policy returned no action part {name!r} (parts: {sorted(acts)})")
    values = np.asarray(acts[name])
    if values.shape != (live.size, *part.shape):
        raise ValueError(
            f"the policy's action part {name!r} has shape {values.shape}, expected {(live.size, *part.shape)}"
        )
    out = scatter_part(values.reshape(live.size, part.size), live, n_slots, part.low, part.high)
    if out is None:
        raise ValueError(f"the policy's action part {name!r} holds NaN or inf")
    return out


def _dict_loop(
    env: Any, policy: ArrayPolicy, steps: int, seed: int | None, on_step: RolloutCallback | None, t0: float
) -> RolloutResult:
    """The rollout through ``reset`` and ``step`` (a front end that overrides them, e.g. a recording one).

    ``env`` may be a wrapper (``agentsim_env.wrappers``): its ``reset`` and ``step`` are called, and the layout
    and bookkeeping are read from the innermost env (``env.unwrapped``).
    """
    inner = env.unwrapped
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    index = inner._index
    returns = np.zeros(len(env.possible_agents), dtype=np.float64)
    events = dict.fromkeys(EVENT_KEYS, 0)
    acc: dict[str, np.ndarray] = {}
    taken = agent_steps = 0
    keys = inner._obs_keys
    n_slots = env.world.state.n_slots
    if on_step is not None:
        on_step(env, 0, None)
    while taken < steps and inner._live:
        live = list(inner._live)
        slots = np.array([index[a] for a in live], dtype=np.int64)
        parts = {
            k: np.stack([np.asarray(obs[a][k] if isinstance(obs[a], dict) else _part(inner, obs[a], k)) for a in live])
            for k in keys
        }
        acts = policy.act_rows(parts, slots, taken)
        act_keys = list(inner._act_parts)
        actions: dict[str, Any] = {a: {k: np.asarray(acts[k][i]) for k in act_keys} for i, a in enumerate(live)}
        if env.action_format == "flat":
            actions = {a: np.concatenate([v[k].reshape(-1) for k in act_keys]) for a, v in actions.items()}
        obs, rew, _, _, infos = env.step(actions)
        taken += 1
        agent_steps += len(live)
        for a, r in rew.items():
            returns[index[a]] += r
        for k, v in count_events(env.world.last_events).items():
            events[k] += v
        for a, info in infos.items():
            for k, v in info.items():
                if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_)):
                    if k not in acc:
                        acc[k] = np.zeros(len(env.possible_agents), dtype=np.float64)
                    acc[k][index[a]] += float(v)
        if on_step is not None and on_step(env, taken, _view(inner, slots, infos, n_slots)):
            break
    sums = {k: float(v.sum()) for k, v in acc.items()}
    return _result(env, taken, returns, events, sums, agent_steps, t0)


def _view(env: Any, slots: np.ndarray, infos: dict[str, dict[str, Any]], n_slots: int) -> StepView:
    """The :class:`StepView` of a step taken through ``step()`` (from its infos dicts)."""
    acted = np.zeros(n_slots, dtype=bool)
    acted[slots] = True
    live = np.zeros(n_slots, dtype=bool)
    live[env._live_idx] = True
    index = env._index
    info: dict[str, np.ndarray] = {}
    for a, values in infos.items():
        for k, v in values.items():
            if k not in info:
                info[k] = np.zeros(n_slots, dtype=np.asarray(v).dtype)
            info[k][index[a]] = v
    return StepView(acted, live, info)


def _part(env: Any, flat_row: np.ndarray, key: str) -> np.ndarray:
    """Observation part ``key`` of one flat observation row."""
    sl, shape = dict(zip(env._obs_keys, env._obs_cols))[key]
    return np.asarray(flat_row)[sl].reshape(shape)


def _result(
    env: Any,
    taken: int,
    returns: np.ndarray,
    events: dict[str, int],
    sums: dict[str, float],
    agent_steps: int,
    t0: float,
) -> RolloutResult:
    n = len(env.possible_agents)
    wall = time.perf_counter() - t0
    return RolloutResult(
        steps=taken,
        returns=returns[:n].copy(),
        final_pos=np.array(env.world.state.pos[:n], dtype=np.float64),
        events=events,
        info_sums=sums,
        agent_steps=agent_steps,
        wall_s=wall,
        steps_per_s=taken / wall if wall > 0 else 0.0,
    )
