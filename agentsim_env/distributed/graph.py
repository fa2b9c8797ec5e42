"""The coordinator's range graph: the rows the shards computed, in the shape the comms stack reads.

On the coordinator the comms stack (bus, overlay, inboxes) runs over every slot, but the range graph is spatial
work: each shard computes it over its own agents and ghosts and sends back each own agent's nearest neighbour
and, for the agents on the overlay's frontier, their links. ``GatheredGraph`` stands in for
``comms.rangegraph.RangeGraph`` in ``CommsStack.graph``: it ignores the grid the stack passes and answers
``nearest()`` and ``links()`` from those rows. Only the frontier's rows are filled: a flood's next hop reads no
other (``comms.flooding.spread``; full propagation, which would, is refused with shards).
"""

from __future__ import annotations

from typing import Any

import numpy as np


class GatheredGraph:
    """Nearest neighbours and frontier links gathered from the shards (see the module docstring).

    Args:
        n_slots: Number of slots S.
        nearest_range: The comms config's "nearest" range (kept for the stack's reads).
    """

    def __init__(self, n_slots: int, nearest_range: float) -> None:
        self.n_slots = int(n_slots)
        self.nearest_range = float(nearest_range)
        self._near = np.full(self.n_slots, -1, dtype=np.int64)
        self._start = np.zeros(self.n_slots, dtype=np.int64)
        self._end = np.zeros(self.n_slots, dtype=np.int64)
        self._idx = np.zeros(0, dtype=np.int64)
        empty = np.zeros(0, dtype=np.int64)
        self._pairs: tuple[np.ndarray, ...] = (empty, empty, np.zeros(0))

    # -- what the shards send ---------------------------------------------------------------------------
    def clear(self) -> None:
        """Forget the previous step's rows (every slot: no nearest neighbour, no links)."""
        self._near.fill(-1)
        self._start.fill(0)
        self._end.fill(0)
        self._idx = np.zeros(0, dtype=np.int64)

    def put(self, slots: np.ndarray, nearest: np.ndarray | None, front: Any, count: Any, links: Any) -> None:
        """One shard's rows: the nearest neighbour of ``slots``; the links of its frontier slots ``front``.

        Args:
            slots: The shard's own slots.
            nearest: Their nearest neighbour (or -1), or ``None`` without comms.
            front: Its frontier slots (or ``None``).
            count: Links per frontier slot.
            links: The linked slots, row after row.
        """
        if nearest is not None:
            self._near[slots] = nearest
        if front is not None and len(front):
            base = self._idx.shape[0]
            ends = base + np.cumsum(count)
            self._start[front] = ends - count
            self._end[front] = ends
            self._idx = np.concatenate([self._idx, np.asarray(links, dtype=np.int64)])

    # -- what the comms stack reads ---------------------------------------------------------------------
    @property
    def pairs(self) -> tuple[np.ndarray, ...]:
        """No pairs are kept on the coordinator (empty)."""
        return self._pairs

    def set_grid(self, *args: Any, **kwargs: Any) -> None:
        """The stack passes the coordinator's grid here; the shards' rows stand for it (ignored)."""
        del args, kwargs

    def set_pairs(self, *args: Any, **kwargs: Any) -> None:
        """Pairs set from code have no meaning on the coordinator (ignored)."""
        del args, kwargs

    def nearest(self) -> np.ndarray:
        """``(S,)`` int64: each slot's nearest neighbour within the "nearest" range, or -1."""
        return self._near

    def links(self, link_range: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(start, end, indices)`` of the frontier slots' links (the other rows are empty)."""
        del link_range
        return self._start, self._end, self._idx
