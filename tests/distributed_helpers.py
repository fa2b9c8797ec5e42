"""Shared by the distributed tests: run a single-process env and a sharded one side by side and compare."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

import agentsim_env
from agentsim_env.distributed import make as make_sharded


@dataclass
class Trace:
    """What one run produced, step by step (agents that were live, in order)."""

    obs: list[dict[str, Any]] = field(default_factory=list)
    rewards: list[dict[str, float]] = field(default_factory=list)
    terms: list[dict[str, bool]] = field(default_factory=list)
    truncs: list[dict[str, bool]] = field(default_factory=list)
    infos: list[dict[str, Any]] = field(default_factory=list)
    pos: list[np.ndarray] = field(default_factory=list)
    bus: list[set[tuple[int, ...]]] = field(default_factory=list)
    overlay: list[set[tuple[int, ...]]] = field(default_factory=list)
    handovers: int = 0
    cross_collisions: int = 0
    collisions: int = 0


def random_actions(env: Any, rng: np.random.Generator) -> dict[str, Any]:
    """Uniform actions in [-1, 1] for every live agent (every action part)."""
    return {
        a: {k: rng.uniform(-1.0, 1.0, sp.shape).astype(np.float32) for k, sp in env.action_space(a).spaces.items()}
        for a in env.agents
    }


def live_steps(env: Any, steps: int, rng: np.random.Generator) -> list[tuple]:
    """Up to ``steps`` steps with random actions, fewer if the episode ends; the step results."""
    out = []
    for _ in range(steps):
        if not env.agents:
            break
        out.append(env.step(random_actions(env, rng)))
    return out


def run(env: Any, steps: int, seed: int = 3, hook: Any = None) -> Trace:
    """Reset with ``seed`` and step with seeded random actions; ``hook(env, t)`` runs before step ``t``."""
    tr = Trace()
    co = getattr(env, "coordinator", None)
    if co is not None and hasattr(co, "gather_events"):
        co.gather_events = True  # the message deliveries of every step, as one process reports them
    env.reset(seed=seed)
    rng = np.random.default_rng(seed + 1)
    for t in range(steps):
        if hook is not None:
            hook(env, t)
        obs, rew, term, trunc, info = env.step(random_actions(env, rng))
        tr.obs.append(obs)
        tr.rewards.append(rew)
        tr.terms.append(term)
        tr.truncs.append(trunc)
        tr.infos.append(info)
        tr.pos.append(env.world.state.pos.copy())
        ev = env.world.last_events
        tr.collisions += len(ev.collisions)
        if ev.comms is not None:
            d = ev.comms.bus.delivered
            tr.bus.append(set(zip(d.sender.tolist(), d.receiver.tolist(), d.kind.tolist(), d.created.tolist())))
            ov = ev.comms.overlay
            tr.overlay.append(set(zip(ov.receiver.tolist(), ov.origin.tolist(), ov.created.tolist(), ov.hops.tolist())))
        co = getattr(env, "coordinator", None)
        if co is not None:
            tr.handovers += int(co.traffic.handover > 0)
            col = ev.collisions
            both = col.other_agent >= 0
            if both.any():
                strip = co.strips.strip_of(env.world.state.pos[:, 0])
                tr.cross_collisions += int((strip[col.agent[both]] != strip[col.other_agent[both]]).sum())
        if not env.agents:
            break
    return tr


def first_difference(a: Trace, b: Trace) -> str | None:
    """The first step and field where two traces differ, or ``None`` when they are identical."""
    if len(a.obs) != len(b.obs):
        return f"lengths {len(a.obs)} != {len(b.obs)}"
    for t in range(len(a.obs)):
        if list(a.obs[t]) != list(b.obs[t]):
            return f"step {t}: live agents differ"
        for ag, parts in a.obs[t].items():
            for k, v in parts.items():
                if not np.array_equal(v, b.obs[t][ag][k]):
                    return f"step {t}: observation {k!r} of {ag}"
        for name in ("rewards", "terms", "truncs", "infos"):
            if getattr(a, name)[t] != getattr(b, name)[t]:
                return f"step {t}: {name}"
        if not np.array_equal(a.pos[t], b.pos[t]):
            return f"step {t}: positions"
        if a.bus and a.bus[t] != b.bus[t]:
            return f"step {t}: bus deliveries"
        if a.overlay and a.overlay[t] != b.overlay[t]:
            return f"step {t}: overlay deliveries"
    return None


def compare(name: str, shards: int, steps: int, backend: str = "local", **config: Any) -> tuple[Trace, Trace]:
    """Run ``name`` in one process and over ``shards``; assert identical traces; return both."""
    ref = run(agentsim_env.make(name, **config), steps)
    env = make_sharded(name, shards=shards, backend=backend, **config)
    try:
        got = run(env, steps)
    finally:
        env.close()
    diff = first_difference(ref, got)
    assert diff is None, f"{name} over {shards} shards differs from one process at {diff}"
    return ref, got
