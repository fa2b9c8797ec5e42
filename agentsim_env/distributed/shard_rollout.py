"""A rollout inside a shard: the policy acts for the shard's own agents on their observation rows.

``env.rollout(policy, steps, seed)`` over shards (``distributed.coordinator``): each shard builds the policy from
picklable inputs (a baseline name, a trained model folder; ``env.rollout.build_policy``; a policy object is
sent as it is) and, every step, acts for its own live agents on the observation rows it built at the end of the
previous step, then runs the step (``Shard.run``). Observations never leave the shard. What an agent
accumulates (its return, its info sums, whether it is live) is a per-slot array of the shard that travels with
the agent when it is handed over, so each agent's sums are added in the same order as in one process.
Each step answers only counts (live agents, events); ``finish`` answers the per-agent rows once.
"""

from __future__ import annotations

import copy
import os
from typing import Any

import numpy as np

from agentsim_env.distributed.bridge import Packed
from agentsim_env.env.rollout import EVENT_KEYS, ArrayPolicy, build_policy, count_events, scatter_part_checked


def obs_layout(scenario: Any) -> list[tuple[str, slice, tuple[int, ...]]]:
    """Each observation part's columns and shape in the flat layout (the front end's order)."""
    out, start = [], 0
    for key, part in scenario.obs_parts().items():
        out.append((key, slice(start, start + part.size), tuple(part.shape)))
        start += part.size
    return out


class ShardRollout:
    """The rollout state of one shard (see the module docstring).

    Args:
        worker: The ``distributed.shard.Shard``.
        policy: A baseline name, a trained model folder, or a policy object.
        seed: The rollout's seed (given to ``policy.reset``).
    """

    def __init__(self, worker: Any, policy: Any, seed: int | None) -> None:
        self.worker = worker
        sc = worker.scenario
        if isinstance(policy, (str, os.PathLike)):
            self.policy: ArrayPolicy = build_policy(sc.name, worker.config, policy)
        else:  # an object: this shard's own copy (writable arrays, state apart from the other shards')
            own = copy.deepcopy(policy)
            self.policy = own if isinstance(own, ArrayPolicy) else build_policy(sc.name, worker.config, own)
        self.policy.reset(seed)
        s = worker.world.state.n_slots
        self.layout = obs_layout(sc)
        self.act_parts = sc.act_parts()
        self.info_keys = sc.info_keys()
        self.live = worker.own & worker.world.state.online
        self.returns = np.zeros(s, dtype=np.float64)
        self.sums = {k: np.zeros(s, dtype=np.float64) for k in self.info_keys}
        self.ended_here = np.zeros(s, dtype=bool)
        worker.carry.update({"live": self.live, "returns": self.returns, "ended_here": self.ended_here})
        worker.carry.update({f"sum.{k}": v for k, v in self.sums.items()})
        self.slots = np.flatnonzero(self.live & worker.own)
        self.parts = self._observe(self.slots)

    def _observe(self, slots: np.ndarray) -> dict[str, np.ndarray]:
        """The observation parts of ``slots`` in the layout's shapes and float32 (the values the flat rows hold),
        not flattened: the policy gets parts."""
        got = self.worker.scenario.observation_rows(self.worker.world, slots)
        return {k: got[k].astype(np.float32, copy=False).reshape(slots.size, *shape) for k, _, shape in self.layout}

    def act(self, control: Packed) -> Packed:
        """One step: the policy's actions for the own live agents, the step, the sums; counts back."""
        w = self.worker
        st = w.world.state
        s = st.n_slots
        slots = np.flatnonzero(self.live & w.own)
        n = slots.size
        if np.array_equal(slots, self.slots):
            obs = self.parts
        else:
            at = np.searchsorted(self.slots, slots)
            obs = {k: v[at] for k, v in self.parts.items()}
        if n:
            acts = self.policy.act_rows(obs, slots, int(control["taken"]))
        else:  # no own agent acts this step: the shard still steps (its neighbours meet it at the exchange)
            acts = {name: np.zeros((0, *p.shape), np.float32) for name, p in self.act_parts.items()}
        parts = {name: scatter_part_checked(name, acts, p, slots, s) for name, p in self.act_parts.items()}
        res, terminated = w.run(slots, parts, control)
        acting = w.acting
        over = bool(control["over"])
        gone = acting & (terminated | over)
        # by index: a boolean mask over every slot with the own half set at random costs ~6x more a pass
        done = np.flatnonzero(acting)
        self.returns[done] += np.asarray(res.rewards, dtype=np.float64)[done]
        for k in self.info_keys:
            a = np.asarray(res.info[k])
            if a.dtype != bool:
                self.sums[k][done] += a[done]
        self.live &= ~gone
        self.ended_here |= acting & terminated
        w.own[acting & terminated] = False  # they stay where they stopped (``ended_here``)
        w._sender_positions()
        self.slots = np.flatnonzero(self.live & w.own)
        self.parts = self._observe(self.slots)
        counts = count_events(w.world.last_events)
        out: Packed = {
            "live": int((self.live & w.own).sum()),
            "events": [counts[k] for k in EVENT_KEYS],
            "ended": np.flatnonzero(acting & terminated),
            "arrived": w.arrived,
        }
        if control.get("gather"):  # an observer of the steps: the acting agents' rows (no observations)
            out["acted"], out["still"] = done, self.live[done]
            out["info"] = {k: np.asarray(v)[done] for k, v in res.info.items()}
            out["pos"] = st.pos[done]
        return out

    def finish(self) -> Packed:
        """The per-agent rows: every slot this shard holds or saw end (returns, info sums, positions, live)."""
        w = self.worker
        slots = np.flatnonzero(w.own | self.ended_here)
        out: Packed = {
            "slots": slots,
            "returns": self.returns[slots],
            "pos": w.world.state.pos[slots],
            "live": np.flatnonzero(self.live & w.own),
        }
        out["sums"] = {k: v[slots] for k, v in self.sums.items()}
        out["own"] = np.flatnonzero(w.own)
        out["obs"] = self.worker.flat_layout(self.parts, self.slots.size)  # of ``live``: step() can go on from here
        for key in ("live", "returns", "ended_here", *(f"sum.{k}" for k in self.info_keys)):
            w.carry.pop(key, None)
        return out
