"""The overlay of a shard's comms stack: ``PartFloods`` behind the interface the comms stack uses.

A shard's ``CommsStack`` keeps its single-process code; only its ``overlay`` is this object: floods start on the
origin's shard (stage 1), a hop walks the links from the own frontier entries and the ghost frontier entries
the neighbours sent in this step's exchange (``ghost_frontier``, set by the shard before stage 7) into own
agents only, and statistics are the shard's share (``distributed.floods.combine_stats`` adds them up).
"""

from __future__ import annotations

import numpy as np

from agentsim_env.comms.overlay import Deliveries, Overlay, OverlayStats
from agentsim_env.distributed.floods import FloodEntries, PartFloods


class ShardOverlay:
    """Overlay floods of one shard (see the module docstring).

    Args:
        like: The single-process overlay it replaces (its ranges are kept).
        own: ``(S,)`` bool, the shard's own slots (the shard's mask, read at every hop).
    """

    def __init__(self, like: Overlay, own: np.ndarray) -> None:
        self.ranges = like
        self.own = own
        self.payload_dim = int(like._payload.shape[1])
        self.part = PartFloods(like.n_slots, self.payload_dim)
        self.ghost_frontier = FloodEntries.empty(self.payload_dim)
        self.full_propagation = False
        self._last = OverlayStats()
        self._totals = OverlayStats()

    # ------------------------------------------------------------------ ranges (the single-process object's)
    @property
    def n_slots(self) -> int:
        """Number of slots S."""
        return int(self.ranges.n_slots)

    @property
    def link_range(self) -> np.ndarray:
        """Per-slot transmission range ``(S,)`` (do not write)."""
        return self.ranges.link_range

    @property
    def comm_range(self) -> np.ndarray:
        """Per-slot transmission range ``(S,)`` (a copy)."""
        return self.ranges.comm_range

    @property
    def max_range(self) -> float:
        """The largest per-slot transmission range."""
        return self.ranges.max_range

    def set_range(self, comm_range: float | np.ndarray) -> None:
        """As ``Overlay.set_range``."""
        self.ranges.set_range(comm_range)

    # ------------------------------------------------------------------ floods
    @property
    def frontier_size(self) -> int:
        """Own and ghost frontier entries: whether the next hop has anything to spread here."""
        return int(self.part.frontier_size) + len(self.ghost_frontier)

    @property
    def stats(self) -> OverlayStats:
        """This shard's counters of the latest hop (``finished`` is not known per shard: 0)."""
        return self._last

    @property
    def totals(self) -> OverlayStats:
        """This shard's running totals."""
        return self._totals

    def reset(self) -> None:
        """Drop every flood."""
        self.part.reset()
        self.ghost_frontier = FloodEntries.empty(self.payload_dim)

    def drop_slots(self, slots: np.ndarray) -> None:
        """Forget the reads and frontier entries of ``slots`` (a world reset)."""
        self.part.drop(np.asarray(slots, dtype=np.int64))

    def start(
        self, origin: np.ndarray, hop_limit: np.ndarray | int, payload: np.ndarray | None, step: int
    ) -> np.ndarray:
        """Floods started by own agents (stage 1); their keys ``(k, 3)``."""
        return self.part.start(origin, hop_limit, payload, step)

    def advance_graph(self, start: np.ndarray, end: np.ndarray, indices: np.ndarray) -> Deliveries:
        """One hop into the own agents, from the own and the ghost frontier (``ghost_frontier``, then cleared)."""
        d = self.part.hop((start, end, indices), self.own, self.ghost_frontier)
        self.ghost_frontier = FloodEntries.empty(self.payload_dim)
        st = self.part.stats
        self._last = OverlayStats(int(st.started), int(st.delivered), int(st.duplicates), 0)
        self._totals = self._totals + self._last
        # origin, created and payload looked up in the part's flood table when read (it replaces its columns
        # instead of writing them, so these rows stay as they are)
        return Deliveries.by_flood(d.receiver, np.full(len(d), -1, dtype=np.int64), d.hops, d.table[:3], d.rows)
