"""What the coordinator does during a step of shards that step themselves: it only routes.

Each shard runs the step pipeline for its own agents (``distributed.worker``). At a few points of the step it
needs something from the others; it posts what it has and waits for what is routed to it (an **exchange**):

========== ============================================================ ====================================
phase      each shard posts                                             each shard gets
========== ============================================================ ====================================
``motion`` its agents near a strip edge (slot, position) after motion,  its ghosts (the agents of other
           and the agents that crossed into another shard's strip       shards within its halo) and the
           (their whole per-slot rows)                                  agents handed over to it
``offline``its agents near an edge that went offline this step          every such slot (its ghosts among
           (collisions, heartbeat timeouts)                             them leave its world)
``groups`` the scenario's per-group partial sums over its own agents    the sums over every shard
========== ============================================================ ====================================

The routing is a pure function of the posts (:meth:`Bridge.route`), run where the posts meet: in this process
for the local backend (``distributed.exchange.LocalExchange``), in a small Ray actor for Ray shards. Its cost
grows with the agents near strip edges, the hand-overs and the number of groups, not with the number of agents.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.distributed.partition import Strips

Packed = dict[str, Any]
"""Names to numpy arrays (and a few scalars): what crosses between shards and the coordinator."""

_EMPTY = np.zeros(0, dtype=np.int64)


def concat_rows(parts: list[Packed]) -> Packed | None:
    """Packed rows of several senders as one (the keys of the first; ``None`` when there is nothing)."""
    got = [p for p in parts if p is not None and p["slots"].size]
    if not got:
        return None
    return {key: np.concatenate([p[key] for p in got]) for key in got[0]}


def take_rows(rows: Packed, sel: np.ndarray) -> Packed:
    """The rows of ``rows`` selected by the boolean mask or index array ``sel``."""
    return {key: v[sel] for key, v in rows.items()}


class Bridge:
    """The coordinator's routing between shards (see the module docstring).

    Args:
        strips: The partition (its ``owner`` changes when a shard goes offline).
    """

    def __init__(self, strips: Strips) -> None:
        self.strips = strips

    def set_owner(self, owner: np.ndarray) -> None:
        """The shard owning each strip from now on."""
        self.strips.owner = np.asarray(owner, dtype=np.int64).copy()

    def route(self, phase: str, posts: dict[int, Packed]) -> dict[int, Packed]:
        """What each shard that posted gets back in ``phase``.

        Raises:
            ValueError: For an unknown phase.
        """
        if phase == "motion":
            return self._motion(posts)
        if phase == "offline":
            slots = np.concatenate([p["slots"] for p in posts.values()]) if posts else _EMPTY
            out = {"slots": np.unique(slots)}
            return dict.fromkeys(posts, out)
        if phase == "groups":
            return dict.fromkeys(posts, _sum_partials(list(posts.values())))
        raise ValueError(f"unknown exchange phase {phase!r}")

    def _motion(self, posts: dict[int, Packed]) -> dict[int, Packed]:
        strips = self.strips
        edge = concat_rows([p["edge"] for p in posts.values()])
        leave = concat_rows([p["leave"] for p in posts.values()])
        out: dict[int, Packed] = {}
        dest = strips.owner_of(leave["x"]) if leave is not None else _EMPTY
        for k in posts:
            if edge is not None:
                g = strips.ghosts(edge["x"], np.arange(edge["slots"].size), k)
                ghosts = take_rows(edge, g)
            else:
                ghosts = {"slots": _EMPTY, "x": np.zeros(0), "pos": np.zeros((0, 3))}
            arrivals = take_rows(leave, dest == k) if leave is not None else None
            out[k] = {"ghosts": ghosts, "arrivals": arrivals}
        return out


def _sum_partials(parts: list[Packed]) -> Packed:
    """Element-wise sums of the shards' partial arrays (integers: exact in any order)."""
    got = [p for p in parts if p]
    if not got:
        return {}
    return {key: np.sum([p[key] for p in got], axis=0) for key in got[0]}
