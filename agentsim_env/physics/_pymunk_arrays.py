"""Array side of the pymunk backend: input checks, numba row copies to and from pymunk's batch layout, and
the contact result type.

Nothing here touches pymunk; ``pymunk_backend`` (the only pymunk importer) calls these helpers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from ..core.scene import CYLINDER, SPHERE


# Row copies between the caller's arrays and the batch layout (x, y, vx, vy per body). One pass per side: numpy
# needs three masked copies, and the (S, 2) strided ones are slow (about 10 us for 1,000 rows).
@njit(cache=True)
def _pack(pos: np.ndarray, vel: np.ndarray, online: np.ndarray, x_offset: np.ndarray, body: np.ndarray) -> None:
    for i in range(online.shape[0]):
        if online[i]:  # offline rows keep their parking spot (and may hold NaN in pos)
            body[i, 0] = pos[i, 0] + x_offset[i]
            body[i, 1] = pos[i, 1]
            body[i, 2] = vel[i, 0]
            body[i, 3] = vel[i, 1]


@njit(cache=True)
def _unpack(
    body: np.ndarray, online: np.ndarray, x_offset: np.ndarray, out_xy: np.ndarray, out_vel: np.ndarray
) -> None:
    for i in range(online.shape[0]):
        if online[i]:
            out_xy[i, 0] = body[i, 0] - x_offset[i]
            out_xy[i, 1] = body[i, 1]
            out_vel[i, 0] = body[i, 2]
            out_vel[i, 1] = body[i, 3]


@njit(cache=True)
def _bad_online_row(pos: np.ndarray, vel: np.ndarray, online: np.ndarray, half_band: float) -> int:
    """0 if every online row is valid, 1 if one is not finite, 2 if one's x is out of its band."""
    for i in range(online.shape[0]):
        if online[i] and not (
            np.isfinite(pos[i, 0])
            and np.isfinite(pos[i, 1])
            and np.isfinite(pos[i, 2])
            and np.isfinite(vel[i, 0])
            and np.isfinite(vel[i, 1])
        ):
            return 1
    for i in range(online.shape[0]):
        if online[i] and abs(pos[i, 0]) >= half_band:
            return 2
    return 0


def _float_array(name: str, a: Any, shape: tuple[int, ...], finite: bool = True) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if finite and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


def _int_array(name: str, a: Any, shape: tuple[int, ...], low: int, high: int) -> np.ndarray:
    arr = np.asarray(a)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        raise ValueError(f"{name} must be an integer array, got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if arr.size and (arr.min() < low or arr.max() >= high):
        raise ValueError(f"{name} values must be in [{low}, {high}), got range [{arr.min()}, {arr.max()}]")
    return arr


def _check_obstacles(
    kind: Any, centre: Any, half: Any, world: Any, n_worlds: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    k = np.asarray(kind)
    if k.ndim != 1:
        raise ValueError(f"obj_kind must have shape (O,), got {k.shape}")
    n = k.shape[0]
    kind_arr = _int_array("obj_kind", k, (n,), 0, 3).astype(np.int8)
    centre_arr = _float_array("obj_centre", centre, (n, 3))
    half_arr = _float_array("obj_half", half, (n, 3))
    world_arr = _int_array("obj_world", world, (n,), 0, n_worlds).astype(np.int32)
    # Only the columns each kind uses must be positive (cylinder: radius, half-height; sphere: radius).
    used = np.ones((n, 3), dtype=bool)
    used[kind_arr == CYLINDER, 1] = False
    used[kind_arr == SPHERE, 1:] = False
    if np.any(used & (half_arr <= 0.0)):
        raise ValueError(
            "obj_half must be positive in the columns its kind uses (box: x, y, z; "
            "cylinder: radius [0], half-height [2]; sphere: radius [0])"
        )
    return kind_arr, centre_arr, half_arr, world_arr


def _check_backend_args(
    radius: Any, n_worlds: Any, substeps: Any, world_spacing: Any, collision_slop: Any, correction: Any
) -> np.ndarray:
    """Check the backend's scalar arguments and radii (see ``PymunkPlanarBackend``); return radius as float64.

    Raises:
        ValueError: If an argument is outside its allowed range (the message names it).
    """
    r = np.asarray(radius, dtype=np.float64)
    if r.ndim != 1 or r.shape[0] == 0:
        raise ValueError(f"radius must have shape (S,) with S >= 1, got {r.shape}")
    if not np.all(np.isfinite(r) & (r > 0.0)):
        raise ValueError("radius must be finite and positive")
    if isinstance(n_worlds, bool) or not isinstance(n_worlds, (int, np.integer)) or n_worlds < 1:
        raise ValueError(f"n_worlds must be an integer >= 1, got {n_worlds!r}")
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ValueError(f"substeps must be an integer >= 1, got {substeps!r}")
    if not (np.isfinite(world_spacing) and world_spacing > 0.0):
        raise ValueError(f"world_spacing must be finite and positive, got {world_spacing!r}")
    if not (np.isfinite(collision_slop) and collision_slop >= 0.0):
        raise ValueError(f"collision_slop must be finite and >= 0, got {collision_slop!r}")
    if not (0.0 < correction < 1.0):
        raise ValueError(f"correction must be in (0, 1), got {correction!r}")
    return r


def _check_step_inputs(
    pos: Any, desired_vel: Any, online: Any, dt: Any, n: int, half_band: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check ``PymunkPlanarBackend.step``'s inputs for ``n`` slots; return ``(pos, vel, online)`` as arrays.

    Raises:
        ValueError: If an input has the wrong shape or type, or an online row is not finite or out of its band.
    """
    pos = _float_array("pos", pos, (n, 3), finite=False)
    vel = _float_array("desired_vel", desired_vel, (n, 3), finite=False)
    on = np.asarray(online)
    if on.shape != (n,) or on.dtype != np.bool_:
        raise ValueError(f"online must be a bool array of shape ({n},), got {on.dtype} {on.shape}")
    if not (np.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be finite and positive, got {dt!r}")
    bad = _bad_online_row(pos, vel, on, half_band)
    if bad == 1:
        raise ValueError("pos and desired_vel must be finite for online slots")
    if bad == 2:
        raise ValueError(f"pos x of online slots must stay within +-{half_band} m (world_spacing / 2)")
    return pos, vel, on


@dataclass(frozen=True, slots=True)
class PhysicsContacts:
    """Contacts that began during one step, one row per unordered pair.

    Attributes:
        agent: Slot of the agent ``(C,) int64`` (the lower slot for agent-agent pairs).
        other_agent: Slot of the other agent, or -1 for an agent-obstacle contact ``(C,) int64``.
        obj: Obstacle index, or -1 for an agent-agent contact ``(C,) int64``.
    """

    agent: np.ndarray
    other_agent: np.ndarray
    obj: np.ndarray

    def __len__(self) -> int:
        return int(self.agent.shape[0])


def _frozen_empty() -> np.ndarray:
    a = np.zeros(0, dtype=np.int64)
    a.flags.writeable = False
    return a


# Most steps begin no contact: they all return this (read-only) instance instead of three new arrays.
_NO_CONTACTS = PhysicsContacts(_frozen_empty(), _frozen_empty(), _frozen_empty())
