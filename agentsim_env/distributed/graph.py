"""The coordinator's range graph: the nearest neighbours the shards found, in the shape the comms stack reads.

On the coordinator the comms stack (bus, overlay table, inboxes) runs over every slot, but the range graph is
spatial work: each shard computes it over its own agents and ghosts and sends back each own agent's nearest
neighbour (for the next step's "nearest" sends). ``GatheredGraph`` stands in for ``comms.rangegraph.RangeGraph``
in ``CommsStack.graph``: it ignores the grid the stack passes, answers ``nearest()`` from those rows, and has no
links (the shards walk them for the overlay: ``distributed.flooding``).
"""

from __future__ import annotations

from typing import Any

import numpy as np


class GatheredGraph:
    """The nearest neighbours gathered from the shards, read by the comms stack (see the module docstring).

    Args:
        n_slots: Number of slots S.
        nearest_range: The comms config's "nearest" range (kept for the stack's reads).
    """

    def __init__(self, n_slots: int, nearest_range: float) -> None:
        self.n_slots = int(n_slots)
        self.nearest_range = float(nearest_range)
        self._near = np.full(self.n_slots, -1, dtype=np.int64)
        self._none = (np.zeros(self.n_slots, dtype=np.int64), np.zeros(self.n_slots, dtype=np.int64),
                      np.zeros(0, dtype=np.int64))  # fmt: skip
        empty = np.zeros(0, dtype=np.int64)
        self._pairs: tuple[np.ndarray, ...] = (empty, empty, np.zeros(0))

    # -- what the shards send ---------------------------------------------------------------------------
    def clear(self) -> None:
        """Forget the previous step's rows (every slot: no nearest neighbour)."""
        self._near.fill(-1)

    def put(self, slots: np.ndarray, nearest: np.ndarray) -> None:
        """One shard's rows: the nearest neighbour (or -1) of each of its own ``slots``."""
        self._near[slots] = nearest

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
        """No links: the shards walk them (``distributed.flooding``); the sharded overlay ignores these."""
        del link_range
        return self._none
