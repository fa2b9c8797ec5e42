"""Motion-primitive state: a struct of arrays over agent slots.

Every slot runs exactly one primitive at a time, identified by ``kind``. The meaning of the
``params`` columns depends on the kind:

========== ======================================================================================
kind       ``params`` columns
========== ======================================================================================
VELOCITY   0-2 target velocity (m/s)
LINEAR     0-2 start position p0 (m), 3-5 velocity = unit direction * speed (m/s), 6 duration (s)
CIRCULAR   0-1 centre xy (m), 2 radius (m), 3 omega (rad/s, + is counter-clockwise),
           4 altitude (m), 5 start phase (rad)
PARABOLIC  0-2 start position p0 (m), 3-5 initial velocity v0 (m/s), 6 gravity g (m/s^2)
PATH       0 speed (m/s), 1 arrival radius (m); waypoints in ``waypoints`` / ``n_waypoints``
HOLD       none (hover in place, velocity zero)
========== ======================================================================================

Unused columns are zero. ``t`` is the time since the primitive was set, advanced by the
integrator for online slots only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

VELOCITY = 0
LINEAR = 1
CIRCULAR = 2
PARABOLIC = 3
PATH = 4
HOLD = 5

KIND_NAMES: tuple[str, ...] = ("velocity", "linear", "circular", "parabolic", "path", "hold")
N_PARAMS = 10


@dataclass(slots=True)
class MotionState:
    """Motion-primitive parameters for ``S`` slots (struct of arrays).

    Attributes:
        kind: ``(S,) int8`` primitive per slot (``VELOCITY`` .. ``HOLD``).
        params: ``(S, 10) float64`` per-kind parameters (see the module docstring).
        t: ``(S,) float64`` seconds since the primitive was set.
        waypoints: ``(S, W, 3) float64`` path waypoints (rows ``>= n_waypoints`` unused).
        n_waypoints: ``(S,) int32`` number of valid waypoints (0 unless ``kind == PATH``).
        wp_index: ``(S,) int32`` index of the waypoint being approached.
        loop: ``(S,) bool`` whether a path wraps to its first waypoint at the end.
        done: ``(S,) bool`` the primitive finished (linear duration elapsed, path end reached
            without loop, parabola landed); the slot then hovers.
    """

    kind: np.ndarray
    params: np.ndarray
    t: np.ndarray
    waypoints: np.ndarray
    n_waypoints: np.ndarray
    wp_index: np.ndarray
    loop: np.ndarray
    done: np.ndarray

    @classmethod
    def create(cls, n_slots: int, max_waypoints: int = 16) -> MotionState:
        """Allocate a state with every slot in ``HOLD``.

        Args:
            n_slots: number of slots ``S`` (>= 0).
            max_waypoints: path capacity ``W`` per slot (>= 1).

        Returns:
            A fresh ``MotionState``.

        Raises:
            ValueError: if ``n_slots < 0`` or ``max_waypoints < 1``.
        """
        if int(n_slots) != n_slots or n_slots < 0:
            raise ValueError(f"n_slots must be an integer >= 0, got {n_slots!r}")
        if int(max_waypoints) != max_waypoints or max_waypoints < 1:
            raise ValueError(f"max_waypoints must be an integer >= 1, got {max_waypoints!r}")
        n, w = int(n_slots), int(max_waypoints)
        return cls(
            kind=np.full(n, HOLD, dtype=np.int8),
            params=np.zeros((n, N_PARAMS), dtype=np.float64),
            t=np.zeros(n, dtype=np.float64),
            waypoints=np.zeros((n, w, 3), dtype=np.float64),
            n_waypoints=np.zeros(n, dtype=np.int32),
            wp_index=np.zeros(n, dtype=np.int32),
            loop=np.zeros(n, dtype=np.bool_),
            done=np.zeros(n, dtype=np.bool_),
        )

    @property
    def n_slots(self) -> int:
        """Number of slots ``S``."""
        return int(self.kind.shape[0])

    @property
    def max_waypoints(self) -> int:
        """Path capacity ``W`` per slot."""
        return int(self.waypoints.shape[1])

    def reset(self, slots: np.ndarray | list[int] | int) -> None:
        """Put ``slots`` back in ``HOLD`` with cleared parameters and flags.

        Args:
            slots: slot indices (int array, list or scalar).
        """
        idx = check_slots(self, slots)
        self.kind[idx] = HOLD
        self.params[idx] = 0.0
        self.t[idx] = 0.0
        self.n_waypoints[idx] = 0
        self.wp_index[idx] = 0
        self.loop[idx] = False
        self.done[idx] = False

    def copy(self) -> MotionState:
        """Return a deep copy (no array is shared with ``self``)."""
        return MotionState(
            kind=self.kind.copy(),
            params=self.params.copy(),
            t=self.t.copy(),
            waypoints=self.waypoints.copy(),
            n_waypoints=self.n_waypoints.copy(),
            wp_index=self.wp_index.copy(),
            loop=self.loop.copy(),
            done=self.done.copy(),
        )


def check_slots(ms: MotionState, slots: np.ndarray | list[int] | int) -> np.ndarray:
    """Validate slot indices and return them as a 1-D ``int64`` array.

    Args:
        ms: the motion state the slots index into.
        slots: integer indices in ``[0, S)``; a scalar is treated as one slot.

    Returns:
        ``(k,) int64`` indices.

    Raises:
        ValueError: if ``slots`` is not integer, not 1-D, or out of range.
    """
    idx = np.asarray(slots)
    if idx.ndim == 0:
        idx = idx.reshape(1)
    if idx.ndim != 1:
        raise ValueError(f"slots must be a 1-D integer array, got shape {idx.shape}")
    if idx.size == 0:
        return idx.astype(np.int64)
    if not np.issubdtype(idx.dtype, np.integer):
        raise ValueError(f"slots must be integers in [0, {ms.n_slots}), got dtype {idx.dtype}")
    if idx.min() < 0 or idx.max() >= ms.n_slots:
        raise ValueError(f"slots must be in [0, {ms.n_slots}), got min {idx.min()} max {idx.max()}")
    return idx.astype(np.int64, copy=False)
