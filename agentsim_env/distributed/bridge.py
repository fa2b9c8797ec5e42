"""What the coordinator does during a step of shards that step themselves: it only routes.

Each shard runs the step pipeline for its own agents (``distributed.shard``). At a few points of the step it
needs something from the others; it posts what it has and waits for what is routed to it (an **exchange**):

========== ============================================================ ====================================
phase      each shard posts                                             each shard gets
========== ============================================================ ====================================
``motion`` its agents near a strip edge (slot, position) after motion,  its ghosts (the agents of other
           and the agents that crossed into another shard's strip       shards within its halo) and the
           (their whole per-slot rows)                                  agents handed over to it
``offline``its agents near an edge that went offline this step          every such slot (its ghosts among
           (collisions, heartbeat timeouts), and the overlay frontier   them leave its world), and the
           entries its agents near an edge hold                         frontier entries of its ghosts
``bus``    the due bus messages whose receivers are not its own (all    the rows for its own receivers
           GROUP rows)                                                  (routed by the owner of each slot)
``groups`` the scenario's per-group partial sums over its own agents,  the sums over every shard; the own
           and the senders in its inboxes it cannot see (beyond its    slots others asked for
           halo)
``want``   the senders of ``groups`` when the scenario has no group     the own slots others asked for
           sums (or the observations are built again in the step)
``have``   the positions of the slots it was asked for                  every answer (it keeps its own)
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


def nbytes(obj: Any) -> int:
    """Bytes of the numpy arrays inside ``obj`` (dicts, lists, tuples, dataclasses; other values count 8)."""
    if isinstance(obj, np.ndarray):
        return int(obj.nbytes)
    if isinstance(obj, dict):
        return sum(nbytes(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(nbytes(v) for v in obj)
    fields = getattr(obj, "__dataclass_fields__", None)
    if fields is not None:
        return sum(nbytes(getattr(obj, f)) for f in fields)
    return 8


class Bridge:
    """The coordinator's routing between shards (see the module docstring).

    Args:
        strips: The partition (its ``owner`` changes when a shard goes offline).
    """

    def __init__(self, strips: Strips, n_slots: int = 0) -> None:
        self.strips = strips
        self.slot_owner = np.full(int(n_slots), -1, dtype=np.int64)
        self.bytes: dict[str, int] = {}
        """Bytes posted and routed back since the last ``take_bytes``, by phase (``halo`` and ``handover`` for
        the motion phase)."""
        """``(S,)`` the shard owning each slot (set at reset, updated by every hand-over)."""

    def set_slot_owner(self, owner: np.ndarray) -> None:
        """The shard owning each slot (at the start of an episode)."""
        self.slot_owner = np.asarray(owner, dtype=np.int64).copy()

    def set_owner(self, owner: np.ndarray) -> None:
        """The shard owning each strip from now on."""
        self.strips.owner = np.asarray(owner, dtype=np.int64).copy()

    def take_bytes(self) -> dict[str, int]:
        """The byte counts by phase since the previous call (then zeroed)."""
        out, self.bytes = self.bytes, {}
        return out

    def route(self, phase: str, posts: dict[int, Packed]) -> dict[int, Packed]:
        """What each shard that posted gets back in ``phase`` (its bytes counted in ``bytes``)."""
        out = self._route(phase, posts)
        if phase == "groups":  # the sums, and the far senders asked for with them (counted as ``want``)
            self._count("groups", nbytes([p["partials"] for p in posts.values()]))
            self._count("groups", nbytes([o["sums"] for o in out.values()]))
            self._count("want", nbytes([p["want"] for p in posts.values()]))
            self._count("want", nbytes([o["serve"] for o in out.values()]))
        elif phase == "motion":
            for p in posts.values():
                self._count("halo", nbytes(p["edge"]))
                self._count("handover", nbytes(p["leave"]) + nbytes(p.get("leave_floods")))
            for o in out.values():
                self._count("halo", nbytes(o["ghosts"]))
                self._count("handover", nbytes(o["arrivals"]) + nbytes(o.get("floods")))
        else:
            self._count(phase, nbytes(list(posts.values())) + nbytes(list(out.values())))
        return out

    def _count(self, phase: str, n: int) -> None:
        self.bytes[phase] = self.bytes.get(phase, 0) + int(n)

    def _route(self, phase: str, posts: dict[int, Packed]) -> dict[int, Packed]:
        """The routing itself (see ``route``).

        Raises:
            ValueError: For an unknown phase.
        """
        if phase == "motion":
            return self._motion(posts)
        if phase == "offline":
            return self._offline(posts)
        if phase == "bus":
            return self._bus(posts)
        if phase == "want":  # each shard gets the slots of its own whose positions others asked for
            return {k: {"slots": v} for k, v in self._serve({k: p["slots"] for k, p in posts.items()}).items()}
        if phase == "have":  # every answer to every shard (each keeps what it asked for)
            got = concat_rows([{"slots": p["slots"], "pos": p["pos"]} for p in posts.values()])
            got = got or {"slots": _EMPTY, "pos": np.zeros((0, 3))}
            return dict.fromkeys(posts, got)
        if phase == "groups":  # the sums over every shard, and the ``want`` routing of the same step
            from agentsim_env.scenarios.rewards import combine_partials

            sums = combine_partials([p["partials"] for p in posts.values()])
            serve = self._serve({k: p["want"] for k, p in posts.items()})
            return {k: {"sums": sums, "serve": serve[k]} for k in posts}
        raise ValueError(f"unknown exchange phase {phase!r}")

    def _serve(self, want: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
        """For each shard, the slots of its own whose positions the others asked for (``want``: each shard's ask)."""
        asked = np.unique(np.concatenate(list(want.values()))) if want else _EMPTY
        owner = self.slot_owner[asked] if self.slot_owner.size else np.full(asked.size, -1)
        return {k: asked[owner == k] for k in want}

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
            floods = [p["leave_floods"] for p in posts.values() if p.get("leave_floods") is not None]
            if floods and leave is not None:
                out[k]["floods"] = _entries_for(floods, leave["slots"][dest == k])
        if leave is not None and self.slot_owner.size:
            self.slot_owner[leave["slots"]] = dest
        return out

    def _offline(self, posts: dict[int, Packed]) -> dict[int, Packed]:
        slots = np.concatenate([p["slots"] for p in posts.values()]) if posts else _EMPTY
        gone = np.unique(slots)
        fronts = [(p["front"], p["front_x"]) for p in posts.values() if p.get("front") is not None]
        out: dict[int, Packed] = {}
        for k in posts:
            out[k] = {"slots": gone}
            if fronts:
                got = []
                for entries, x in fronts:
                    sel = self.strips.ghosts(x, np.arange(x.size), k)
                    if sel.size:
                        got.append(_take_entries(entries, sel))
                out[k]["front"] = got
        return out

    def _bus(self, posts: dict[int, Packed]) -> dict[int, Packed]:
        from agentsim_env.comms.split import route

        parts: dict[int, list[Any]] = {k: [] for k in posts}
        n = max(posts) + 1 if posts else 0
        for src, p in posts.items():
            rows = p["rows"]
            if rows is None or not len(rows):
                continue
            for k, got in route(rows, self.slot_owner, max(n, self.strips.n_strips)).items():
                if k != src and k in parts and len(got):
                    parts[k].append(got)
        return {k: {"rows": got} for k, got in parts.items()}


def _take_entries(entries: Any, sel: np.ndarray) -> Any:
    """The flood entries (``distributed.floods.FloodEntries``) at positions ``sel``."""
    return type(entries)(*(getattr(entries, f)[sel] for f in entries.__dataclass_fields__))


def _entries_for(parts: list[Any], slots: np.ndarray) -> list[Any]:
    """The handed-over flood entries whose slot is among ``slots``."""
    out = []
    for e in parts:
        sel = np.flatnonzero(np.isin(e.slot, slots))
        if sel.size:
            out.append(_take_entries(e, sel))
    return out
