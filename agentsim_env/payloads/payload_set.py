"""Released objects (sensor nodes) as a struct of arrays: release, fall with drag and wind, landing.

Every object has a row in preallocated arrays (doubled when full). ``release`` appends rows and applies
the release errors of the landing-scatter model (domain reference 3.1); ``step`` advances every falling
object at once in a numba kernel with RK4 sub-steps (quadratic drag on the velocity relative to the
wind, gravity), finds the ground crossing on the cubic Hermite interpolant of the crossing sub-step
(exact for a drag-free parabola, fourth order with drag; a straight line between the sub-step ends
would not be), adds the bounce scatter and marks the object landed.

Release errors, applied to the *effective* release state (the commanded one is kept in ``nominal_pos``):
- GNSS: horizontal offset ``N(0, sigma_gnss^2 I)`` (the UAV is not where it believes it is).
- Timing jitter ``delta ~ N(0, sigma_timing^2)``: the UAV lets go ``delta`` late, when it is at
  ``pos + vel * delta``. The object still enters the simulation at the commanded time ``t``; shifting
  the whole fall by ``delta`` in time changes where, not materially when, it lands.
Gust drift comes from the wind model's per-object Ornstein-Uhlenbeck gusts (``ScatterConfig.gust_drift``),
and ``sigma_bounce`` adds ``N(0, sigma_bounce^2 I)`` to the landing point.

Times: ``release_t`` is the simulation time passed to ``release``; ``step(dt)`` advances from there, and
``land_t = release_t + fall time``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from agentsim_env.core.config_model import Flag, Real, config
from agentsim_env.payloads.ballistic import FallParams
from agentsim_env.payloads.kernels import PROFILE_CODES, fall_substeps
from agentsim_env.payloads.wind import RngLike, WindModel, normals

__all__ = ["PAYLOAD_FIELDS", "PayloadSet", "ScatterConfig"]

# name -> (dtype, trailing shape, fill value of a fresh row)
_SPEC: dict[str, tuple[type, tuple[int, ...], float | int | bool]] = {
    "id": (np.int64, (), -1),
    "owner": (np.int64, (), -1),
    "world": (np.int64, (), 0),
    "zone": (np.int64, (), -1),
    "target_xy": (np.float64, (2,), np.nan),
    "nominal_pos": (np.float64, (3,), np.nan),
    "release_pos": (np.float64, (3,), np.nan),
    "release_vel": (np.float64, (3,), np.nan),
    "release_t": (np.float64, (), np.nan),
    "pos": (np.float64, (3,), np.nan),
    "vel": (np.float64, (3,), np.nan),
    "gust": (np.float64, (2,), np.nan),
    "fall_time": (np.float64, (), 0.0),
    "falling": (np.bool_, (), False),
    "landed": (np.bool_, (), False),
    "land_xy": (np.float64, (2,), np.nan),
    "land_t": (np.float64, (), np.nan),
}

#: Names of the per-object arrays (``PayloadSet.as_dict`` keys).
PAYLOAD_FIELDS: tuple[str, ...] = tuple(_SPEC)


@config("scatter")
class ScatterConfig:
    """Release and landing errors (domain reference 3.1, landing-scatter model).

    Attributes:
        sigma_gnss: Horizontal GNSS position error of the UAV, metres (>= 0).
        sigma_timing: Release-timing jitter, seconds (>= 0).
        sigma_bounce: Bounce or roll on impact, metres (>= 0).
        gust_drift: Apply the wind model's per-object gusts while falling.
    """

    sigma_gnss: Annotated[Real, Field(ge=0.0)] = 0.0
    sigma_timing: Annotated[Real, Field(ge=0.0)] = 0.0
    sigma_bounce: Annotated[Real, Field(ge=0.0)] = 0.0
    gust_drift: Flag = True


@dataclass(eq=False)
class PayloadSet:
    """All released objects of one or more worlds, as a struct of arrays.

    Args:
        params: Physical parameters shared by every object.
        scatter: Release and landing errors.
        capacity: Initial number of rows (doubled when full).
        max_substep: Largest integration sub-step in seconds; ``step(dt)`` uses ``ceil(dt / max_substep)``
            equal sub-steps (RK4 at 0.05 s lands within a fraction of a millimetre of a 0.1 ms reference).
    """

    params: FallParams = field(default_factory=FallParams)
    scatter: ScatterConfig = field(default_factory=ScatterConfig)
    capacity: int = 256
    max_substep: float = 0.05
    _count: int = field(default=0, init=False, repr=False)
    _next_id: int = field(default=0, init=False, repr=False)
    _a: dict[str, np.ndarray] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        """Validate the configuration and allocate the arrays."""
        cap = self.capacity
        if isinstance(cap, bool) or not isinstance(cap, (int, np.integer)) or cap < 1:
            raise ValueError(f"capacity must be an integer >= 1, got {self.capacity!r}")
        if not (math.isfinite(self.max_substep) and self.max_substep > 0.0):
            raise ValueError(f"max_substep must be a finite number > 0, got {self.max_substep!r}")
        self._a = {name: self._alloc(name, int(self.capacity)) for name in _SPEC}

    @staticmethod
    def _alloc(name: str, n: int) -> np.ndarray:
        """A fresh array of ``n`` rows for field ``name``, filled with its default."""
        dtype, shape, fill = _SPEC[name]
        return np.full((n, *shape), fill, dtype=dtype)

    def _reserve(self, k: int) -> None:
        """Make room for ``k`` more rows, doubling the capacity as often as needed."""
        need = self._count + k
        if need <= self.capacity:
            return
        cap = self.capacity
        while cap < need:
            cap *= 2
        for name, old in self._a.items():
            new = self._alloc(name, cap)
            new[: self._count] = old[: self._count]
            self._a[name] = new
        self.capacity = cap

    # ------------------------------------------------------------------ lifecycle
    def reset(self) -> None:
        """Remove every object (capacity is kept; ids start again from 0)."""
        for name, arr in self._a.items():
            arr[: self._count] = _SPEC[name][2]
        self._count = 0
        self._next_id = 0

    def clear_world(self, world: int) -> None:
        """Remove the objects of one world (for a batched env that resets one world), keeping order.

        Args:
            world: World id whose objects are removed.
        """
        n = self._count
        keep = np.flatnonzero(self._a["world"][:n] != world)
        for name, arr in self._a.items():
            arr[: keep.size] = arr[keep]
            arr[keep.size : n] = _SPEC[name][2]
        self._count = int(keep.size)

    def release(
        self,
        owner: ArrayLike,
        world: ArrayLike,
        pos: ArrayLike,
        vel: ArrayLike,
        t: float,
        zone: ArrayLike = -1,
        target_xy: ArrayLike | None = None,
        rng: RngLike | None = None,
    ) -> NDArray[np.int64]:
        """Release ``k`` objects at time ``t`` from the given (commanded) states.

        Args:
            owner: Releasing agent slot, scalar or ``(k,)``.
            world: World id, scalar or ``(k,)``.
            pos: Commanded release positions ``(k, 3)`` (or ``(3,)``). An object at or below ``z = 0``
                lands at the next ``step``, where it is.
            vel: Release velocities (the UAV's) ``(k, 3)`` (or ``(3,)``).
            t: Simulation time of the release in seconds.
            zone: Zone id (``-1``: none), scalar or ``(k,)``.
            target_xy: Intended landing points ``(k, 2)`` or ``(2,)``; ``None`` stores NaN.
            rng: Random generator, or one per world; required when ``sigma_gnss`` or ``sigma_timing`` is > 0.

        Returns:
            The new objects' ids ``(k,)``.
        """
        p = np.array(pos, dtype=np.float64, ndmin=2)
        v = np.array(vel, dtype=np.float64, ndmin=2)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"pos must have shape (3,) or (k, 3), got {np.shape(pos)}")
        if v.shape != p.shape:
            raise ValueError(f"vel must have the same shape as pos {p.shape}, got {np.shape(vel)}")
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise ValueError("pos and vel must be finite")
        if not math.isfinite(t):
            raise ValueError(f"t must be finite, got {t!r}")
        k = int(p.shape[0])
        cols = {}
        for name, value in (("owner", owner), ("world", world), ("zone", zone)):
            try:
                cols[name] = np.broadcast_to(np.asarray(value, dtype=np.int64), (k,))
            except ValueError as exc:
                msg = f"{name} must be a scalar or have shape ({k},), got {np.shape(value)}"
                raise ValueError(msg) from exc
        if target_xy is None:
            tgt = np.full((k, 2), np.nan)
        else:
            try:
                tgt = np.broadcast_to(np.asarray(target_xy, dtype=np.float64), (k, 2))
            except ValueError as exc:
                msg = f"target_xy must have shape (2,) or ({k}, 2), got {np.shape(target_xy)}"
                raise ValueError(msg) from exc
        sc = self.scatter
        p_eff = p.copy()
        if sc.sigma_timing > 0.0 or sc.sigma_gnss > 0.0:
            if rng is None:
                raise ValueError("rng must be a np.random.Generator when sigma_gnss or sigma_timing > 0")
            w_of = cols["world"]
            if sc.sigma_timing > 0.0:
                p_eff += v * (normals(rng, (k,), w_of) * sc.sigma_timing)[:, None]
            if sc.sigma_gnss > 0.0:
                p_eff[:, :2] += normals(rng, (k, 2), w_of) * sc.sigma_gnss
        self._reserve(k)
        sl = slice(self._count, self._count + k)
        a = self._a
        ids = np.arange(self._next_id, self._next_id + k, dtype=np.int64)
        a["id"][sl] = ids
        for name, col in cols.items():
            a[name][sl] = col
        a["target_xy"][sl] = tgt
        a["nominal_pos"][sl] = p
        a["release_pos"][sl] = p_eff
        a["release_vel"][sl] = v
        a["release_t"][sl] = t
        a["pos"][sl] = p_eff
        a["vel"][sl] = v
        a["gust"][sl] = np.nan  # drawn from the stationary law at the first step, when the wind is known
        a["fall_time"][sl] = 0.0
        a["falling"][sl] = True
        a["landed"][sl] = False
        self._count += k
        self._next_id += k
        return ids.copy()

    def step(self, dt: float, wind: WindModel | None, rng: RngLike) -> NDArray[np.int64]:
        """Advance every falling object by ``dt`` seconds; land those that reach the ground.

        With a single-world ``WindModel`` every object feels that world's wind; otherwise an object
        feels the wind of its own ``world`` id. Gusts (when enabled and the wind's gust sigma is > 0)
        are drawn from the stationary law at an object's first step, advanced by the exact OU
        transition once per call and held over its sub-steps (``gust_tau`` >> ``dt``).

        Args:
            dt: Time step in seconds (> 0).
            wind: Wind model, or ``None`` for still air.
            rng: Random generator for gusts and bounce scatter, or one per world.

        Returns:
            Ids of the objects that landed during this step, ascending.
        """
        if not (math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be a finite number > 0, got {dt!r}")
        a = self._a
        act = np.flatnonzero(a["falling"][: self._count])
        if act.size == 0:
            return np.empty(0, dtype=np.int64)
        n = act.size
        m = max(1, math.ceil(dt / self.max_substep - 1e-9))
        p, v, tf = a["pos"][act], a["vel"][act], a["fall_time"][act]
        gusts = np.zeros((n, 2))
        if wind is None:
            mean_xy, code, z0, z_ref = np.zeros((n, 2)), PROFILE_CODES["uniform"], 1.0, 2.0
        else:
            w_of = None if wind.n_worlds == 1 else a["world"][act]
            if not isinstance(rng, np.random.Generator) and w_of is None:
                w_of = a["world"][act]
            mean_xy = wind.mean[wind.world_index(w_of, n)]
            cfg = wind.config
            code, z0, z_ref = PROFILE_CODES[cfg.profile], cfg.z0, cfg.z_ref
            if self.scatter.gust_drift and np.any(wind.gust_sigma > 0.0):
                gusts = a["gust"][act]
                fresh = np.isnan(gusts[:, 0])
                old = ~fresh
                if np.any(old):
                    gusts[old] = wind.advance_gusts(gusts[old], dt, rng, None if w_of is None else w_of[old])
                if np.any(fresh):
                    gusts[fresh] = wind.init_gusts(int(fresh.sum()), rng, None if w_of is None else w_of[fresh])
                a["gust"][act] = gusts
        landed = np.zeros(n, dtype=np.bool_)
        xy = np.empty((n, 2))
        k, g = self.params.drag_k, self.params.g
        fall_substeps(p, v, tf, mean_xy, gusts, k, g, dt / m, m, code, z0, z_ref, landed, xy)
        a["pos"][act], a["vel"][act], a["fall_time"][act] = p, v, tf
        if not np.any(landed):
            return np.empty(0, dtype=np.int64)
        idx = act[landed]  # ascending, as act is
        xy = xy[landed]
        if self.scatter.sigma_bounce > 0.0:
            xy = xy + normals(rng, xy.shape, a["world"][idx]) * self.scatter.sigma_bounce
        a["land_xy"][idx] = xy
        a["land_t"][idx] = a["release_t"][idx] + a["fall_time"][idx]
        a["pos"][idx, :2] = xy
        a["falling"][idx] = False
        a["landed"][idx] = True
        return a["id"][idx].copy()

    # ------------------------------------------------------------------ accessors (fresh arrays)
    @property
    def count(self) -> int:
        """Number of objects stored (falling and landed)."""
        return self._count

    @property
    def n_falling(self) -> int:
        """Number of objects in the air."""
        return int(np.count_nonzero(self._a["falling"][: self._count]))

    @property
    def n_landed(self) -> int:
        """Number of objects on the ground."""
        return int(np.count_nonzero(self._a["landed"][: self._count]))

    def get(self, name: str) -> np.ndarray:
        """A copy of one per-object array over the stored objects.

        Args:
            name: One of ``PAYLOAD_FIELDS``.

        Returns:
            ``(count, ...)`` array.
        """
        if name not in self._a:
            raise ValueError(f"name must be one of {PAYLOAD_FIELDS}, got {name!r}")
        return self._a[name][: self._count].copy()

    def as_dict(self) -> dict[str, np.ndarray]:
        """Copies of every per-object array (keys ``PAYLOAD_FIELDS``), e.g. for the recorder."""
        return {name: arr[: self._count].copy() for name, arr in self._a.items()}

    def _select(self, base: np.ndarray, world: int | None, zone: int | None, owner: int | None) -> np.ndarray:
        """Row indices where ``base`` holds and the optional filters match."""
        mask = base[: self._count].copy()
        for name, value in (("world", world), ("zone", zone), ("owner", owner)):
            if value is not None:
                mask &= self._a[name][: self._count] == value
        return np.flatnonzero(mask)

    def landed_xy(self, world: int | None = None, zone: int | None = None, owner: int | None = None) -> np.ndarray:
        """Landing points ``(m, 2)`` of the landed objects, in id order, optionally filtered.

        Args:
            world: Keep only this world's objects.
            zone: Keep only objects released for this zone.
            owner: Keep only objects released by this agent slot.

        Returns:
            ``(m, 2)`` array.
        """
        return self._a["land_xy"][self._select(self._a["landed"], world, zone, owner)]

    def landed_ids(self, world: int | None = None, zone: int | None = None, owner: int | None = None) -> np.ndarray:
        """Ids of the landed objects (same order and filters as ``landed_xy``)."""
        return self._a["id"][self._select(self._a["landed"], world, zone, owner)]

    def falling_ids(self, world: int | None = None) -> np.ndarray:
        """Ids of the objects in the air, optionally of one world."""
        return self._a["id"][self._select(self._a["falling"], world, None, None)]

    def falling_pos(self, world: int | None = None) -> np.ndarray:
        """Positions ``(m, 3)`` of the objects in the air (e.g. for rendering), optionally of one world."""
        return self._a["pos"][self._select(self._a["falling"], world, None, None)]

    def index_of(self, ids: ArrayLike) -> np.ndarray:
        """Row indices of the given ids (ids are stored in ascending order).

        Raises:
            ValueError: If an id is not stored.
        """
        ids_arr = np.asarray(ids, dtype=np.int64)
        stored = self._a["id"][: self._count]
        idx = np.searchsorted(stored, ids_arr)
        ok = (idx < self._count) & (stored[np.minimum(idx, max(self._count - 1, 0))] == ids_arr)
        if self._count == 0 or not np.all(ok):
            raise ValueError("ids must all be ids of stored objects")
        return idx
