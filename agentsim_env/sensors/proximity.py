"""Laser-scanner-like proximity sensor: vectorised ray casting with a per-slot range.

Every online slot casts ``K = n_azimuth * len(elevations_deg)`` rays from its centre. Rays are ordered
ring-major: ray ``k = ring * n_azimuth + a`` has azimuth ``a * 360 / n_azimuth`` degrees counter-clockwise
from the slot's heading and elevation ``elevations_deg[ring]`` (negative looks down). A ray reports the
nearest of: another online agent of the same world (a sphere of its radius), a static object of the same
world (axis-aligned box, vertical cylinder with caps, sphere) and the ground plane ``z = 0``.

Conventions: distances are normalised by the slot's range (``1.0`` = nothing within range; a hit exactly at
the range counts); a ray whose origin lies inside a shape (or below the ground) reads ``0`` on that shape;
exact ties go to the lower ``(hit_kind, hit_id)``. Offline slots scan nothing and are invisible.

The grid kernel (:class:`ProximitySensor`) and the brute-force numpy reference of the tests
(``tests/reference/proximity.py``) share these conventions exactly; the ray-shape tests live in
:mod:`raycast`. The kernel finds agents through the step's agent grid (``spatial.build_grid``
over the online slots, built from the same positions) and objects through the object grid
(``spatial.build_object_grid`` with ``scene.footprint_radius()``); both are keyed by world. Per
candidate it rejects by bounding sphere vs range, then tests only the azimuths whose horizontal
projection can cross the candidate's bounding disc, so the cost per agent stays flat as N grows.

The sensor declares its observation part, ``lidar (K, 2)`` in [0, 1] (:attr:`ProximitySensor.part_name`,
:attr:`ProximitySensor.part`), and writes it: per ray the normalised distance and the hit code / 3 (0 none,
1/3 agent, 2/3 object, 1 ground). A scenario places the part among its own (it sits between ``self`` and
``task``), either as an array (:func:`lidar_observation`, the sensor's ``observe``) or written into flat
observation rows by its own numba kernel (:func:`write_lidar_row`); both give the same bits.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import Annotated

import numba as nb
import numpy as np
from pydantic import Field

from agentsim_env.core.config_model import Flag, Int, Real, config
from agentsim_env.core.pipeline import Part, StepContext
from agentsim_env.core.spatial import Grid, cell_of
from agentsim_env.core.threads import RowThreads
from agentsim_env.sensors.raycast import (
    _BOX,
    _CYL,
    _EPS,
    _SPH,
    HIT_AGENT,
    HIT_GROUND,
    HIT_NONE,
    HIT_OBJECT,
    _candidate,
)


@config()
class ProximityConfig:
    """Ray layout and what the sensor detects.

    Attributes:
        n_azimuth: Rays per elevation ring, evenly spaced over 360 degrees; ray 0 points along the heading.
        elevations_deg: Elevation of each ring in degrees, within [-90, 90] (negative looks down).
        detect_agents: Whether other agents are seen.
        detect_objects: Whether static objects are seen.
        detect_ground: Whether the ground plane is seen (also needs the scene's ground flag).
    """

    n_azimuth: Annotated[Int, Field(ge=1, le=4096)] = 32
    elevations_deg: Annotated[tuple[Annotated[Real, Field(ge=-90.0, le=90.0)], ...], Field(min_length=1)] = (0.0,)
    detect_agents: Flag = True
    detect_objects: Flag = True
    detect_ground: Flag = True

    @property
    def n_rays(self) -> int:
        """Rays per slot ``K = n_azimuth * len(elevations_deg)``."""
        return int(self.n_azimuth) * len(self.elevations_deg)

    def ray_directions(self) -> np.ndarray:
        """Unit ray directions ``(K, 3)`` in the body yaw frame (x along the heading, z up), ring-major."""
        az = 2.0 * np.pi * np.arange(self.n_azimuth) / self.n_azimuth
        el = np.deg2rad(np.asarray(self.elevations_deg))
        ce, se = np.cos(el)[:, None], np.sin(el)[:, None]
        d = np.stack(np.broadcast_arrays(ce * np.cos(az), ce * np.sin(az), se * np.ones_like(az)), axis=-1)
        return np.ascontiguousarray(d.reshape(-1, 3))


@dataclass(slots=True)
class ScanResult:
    """One scan of every slot (buffers reused from scan to scan: copy what you keep).

    Attributes:
        distance: ``(S, K) float32`` hit distance / slot range in [0, 1]; 1.0 = nothing within range.
        hit_kind: ``(S, K) int8``: ``HIT_NONE``, ``HIT_AGENT``, ``HIT_OBJECT`` or ``HIT_GROUND``.
        hit_id: ``(S, K) int32``: slot of the agent hit, object index, or -1 (ground, nothing).
    """

    distance: np.ndarray
    hit_kind: np.ndarray
    hit_id: np.ndarray

    @classmethod
    def empty(cls, n_slots: int, n_rays: int) -> ScanResult:
        """Allocate buffers for ``n_slots`` slots of ``n_rays`` rays (filled as 'nothing seen')."""
        return cls(
            np.ones((n_slots, n_rays), dtype=np.float32),
            np.zeros((n_slots, n_rays), dtype=np.int8),
            np.full((n_slots, n_rays), -1, dtype=np.int32),
        )


@nb.njit(cache=True, error_model="numpy", nogil=True)
def _scan_prep(pos, radius, online, a_items, use_agents, o_kind, o_half):  # type: ignore[no-untyped-def]
    # What every row range shares: the largest online radius, the objects' horizontal and 3D bounding radii
    # (for cheap rejection) and the agents' data gathered in grid order, so a cell range is one sequential
    # read (radius -1 marks offline).
    rmax = 0.0
    for j in range(pos.shape[0]):
        if online[j] and radius[j] > rmax:
            rmax = radius[j]
    n_o = o_kind.shape[0]
    o_rb = np.empty((n_o, 2))
    for o in range(n_o):
        hx, hy, hz = o_half[o, 0], o_half[o, 1], o_half[o, 2]
        if o_kind[o] == _BOX:
            o_rb[o, 0], o_rb[o, 1] = np.sqrt(hx * hx + hy * hy), np.sqrt(hx * hx + hy * hy + hz * hz)
        elif o_kind[o] == _CYL:
            o_rb[o, 0], o_rb[o, 1] = hx, np.sqrt(hx * hx + hz * hz)
        else:
            o_rb[o, 0], o_rb[o, 1] = hx, hx
    n_grid = a_items.shape[0] if use_agents else 0
    packed = np.empty((n_grid, 4))
    for q in range(n_grid):
        j = a_items[q]
        packed[q, 0], packed[q, 1], packed[q, 2] = pos[j, 0], pos[j, 1], pos[j, 2]
        packed[q, 3] = radius[j] if online[j] else -1.0
    return rmax, o_rb, packed


# Kernels compile with error_model="numpy": every division in them is guarded or by a validated positive
# value, and dropping the per-division zero check of the default model made the scan ~20 % faster.
@nb.njit(cache=True, error_model="numpy", nogil=True)
def _scan_kernel(
    lo, hi, pos, heading, srange, online, world, a_grid, scene, o_grid, dirs, n_az, flags, prep, stamp, out, blank
):  # type: ignore[no-untyped-def]
    # Scans slots lo..hi-1 (rows are independent, so ranges may run on different threads, each with its own
    # ``stamp``). a_grid / o_grid = (cell_start, items, origin_x, origin_y, cell, nx, ny); scene = (kind,
    # centre, half, world); flags = (agents, objects, ground); prep = _scan_prep's result; out = (distance,
    # hit_kind, hit_id). Grid cells are per world, so whatever a cell lists belongs to the scanning slot's world.
    # blank[i]: row i of out holds "nothing seen" already (an offline slot's row is written only when it is not).
    a_start, a_items, a_ox, a_oy, a_cell, a_nx, a_ny = a_grid
    o_start, o_items, o_ox, o_oy, o_cell, o_nx, o_ny = o_grid
    o_kind, o_centre, o_half, _ = scene  # object worlds are implied by the grid's per-world cells
    use_agents, use_objects, use_ground = flags
    rmax, o_rb, packed = prep
    out_d, out_k, out_id = out
    n_k = dirs.shape[0]
    bt = np.empty(n_k)
    bk = np.empty(n_k, dtype=np.int8)
    bi = np.empty(n_k, dtype=np.int64)
    for o in range(o_kind.shape[0]):
        stamp[o] = -1
    # Slot order: visiting slots in grid order measured slower at 100,000 agents (scattered output rows).
    for i in range(lo, hi):
        if not online[i]:
            if not blank[i]:
                out_d[i, :] = 1.0
                out_k[i, :] = HIT_NONE
                out_id[i, :] = -1
                blank[i] = True
            continue
        blank[i] = False
        rng = srange[i]
        x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
        cs = (np.cos(heading[i]), np.sin(heading[i]))
        for k0 in range(0, n_k, n_az):
            # The ground is the solid half-space z <= 0; its distance depends only on the ring's elevation.
            tg = np.inf
            if use_ground:
                if z < 0.0:
                    tg = 0.0
                elif dirs[k0, 2] < -_EPS:
                    tg = z / -dirs[k0, 2]
            ground = tg <= rng
            for k in range(k0, k0 + n_az):
                bt[k] = tg if ground else rng
                bk[k] = HIT_GROUND if ground else HIT_NONE
                bi[k] = -1
        w = world[i]
        if use_agents:
            # Agents are binned by centre, so the cells must reach range + the largest radius.
            reach = rng + rmax
            x0, y0 = cell_of(x - reach, y - reach, a_ox, a_oy, a_cell, a_nx, a_ny)
            x1, y1 = cell_of(x + reach, y + reach, a_ox, a_oy, a_cell, a_nx, a_ny)
            for ca in range(x0, x1 + 1):
                base = (w * a_nx + ca) * a_ny
                # Rows of one column are consecutive cells, hence one contiguous run of items.
                for q in range(a_start[base + y0], a_start[base + y1 + 1]):
                    r = packed[q, 3]
                    j = a_items[q]
                    if r < 0.0 or j == i:
                        continue
                    h = (r, r, r)
                    px, py, pz = x - packed[q, 0], y - packed[q, 1], z - packed[q, 2]
                    _candidate(px, py, pz, _SPH, h, r, r, HIT_AGENT, j, rng, cs, dirs, n_az, bt, bk, bi)
        if use_objects:
            # Objects are registered in every cell their footprint touches, so the range alone suffices.
            x0, y0 = cell_of(x - rng, y - rng, o_ox, o_oy, o_cell, o_nx, o_ny)
            x1, y1 = cell_of(x + rng, y + rng, o_ox, o_oy, o_cell, o_nx, o_ny)
            for ca in range(x0, x1 + 1):
                base = (w * o_nx + ca) * o_ny
                for q in range(o_start[base + y0], o_start[base + y1 + 1]):
                    o = o_items[q]
                    if stamp[o] == i:  # objects span cells: visit each once per slot
                        continue
                    stamp[o] = i
                    h = (o_half[o, 0], o_half[o, 1], o_half[o, 2])
                    px, py, pz = x - o_centre[o, 0], y - o_centre[o, 1], z - o_centre[o, 2]
                    _candidate(
                        px,
                        py,
                        pz,
                        o_kind[o],
                        h,
                        o_rb[o, 0],
                        o_rb[o, 1],
                        HIT_OBJECT,
                        o,
                        rng,
                        cs,
                        dirs,
                        n_az,
                        bt,
                        bk,
                        bi,
                    )
        inv = 1.0 / rng
        for k in range(n_k):
            out_d[i, k] = min(bt[k] * inv, 1.0)
            out_k[i, k] = bk[k]
            out_id[i, k] = bi[k]


# ------------------------------------------------------------------------------------- observation part
LIDAR_PART = "lidar"
"""Name of the proximity sensor's observation part."""
LIDAR_BOUNDS = (0.0, 1.0)
"""Bounds of every value of the ``lidar`` part."""


def lidar_observation(scan: ScanResult) -> np.ndarray:
    """The ``lidar`` part of every slot: ``(S, K, 2)`` float32, normalised distance and hit code / 3 per ray.

    Args:
        scan: A scan of every slot.

    Returns:
        A fresh array (the values :func:`write_lidar_row` writes into flat rows).
    """
    out = np.empty((*scan.distance.shape, 2), dtype=np.float32)
    out[..., 0] = scan.distance
    out[..., 1] = scan.hit_kind / 3.0  # in float64, then rounded to float32 as the row writer does
    return out


@nb.njit(cache=True, error_model="numpy", inline="always")
def write_lidar_row(distance, hit_kind, s, out, r, col):  # type: ignore[no-untyped-def]
    """Slot ``s``'s ``lidar`` part into ``out[r, col : col + 2K]``, distance and hit code / 3 interleaved.

    For numba kernels that write whole flat observation rows (inlined into them): the values of
    :func:`lidar_observation` row ``s`` flattened, bit for bit.

    Args:
        distance: ``(S, K)`` float32 scan distances (``ScanResult.distance``).
        hit_kind: ``(S, K)`` int8 hit codes (``ScanResult.hit_kind``).
        s: Slot read.
        out: ``(R, D)`` float32 rows written.
        r: Row written.
        col: First column of the part in the row.
    """
    for k in range(distance.shape[1]):
        out[r, col + 2 * k] = distance[s, k]
        out[r, col + 2 * k + 1] = hit_kind[s, k] / 3.0


# ----------------------------------------------------------------------------------------------- sensor
def _arr(a, dtype):  # type: ignore[no-untyped-def]
    # The per-step case (already a C-contiguous array of the right dtype) costs no numpy call at all.
    if type(a) is np.ndarray and a.dtype == dtype and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=dtype)


def _ids(a):  # type: ignore[no-untyped-def]
    # World ids: any signed integer array is used as is (the kernel specialises on it), saving a copy.
    if type(a) is np.ndarray and a.dtype.kind == "i" and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=np.int64)


@nb.njit(cache=True, error_model="numpy")
def _summary(srange, radius, online, world, kind, obj_world):  # type: ignore[no-untyped-def]
    # Every value check of _check_inputs in one pass: (range ok, radius ok, online world id range,
    # kind codes ok, object world id range).
    ok_range, ok_radius = True, True
    lo, hi, first = 0, 0, True
    for s in range(online.shape[0]):
        if not online[s]:
            continue
        r = srange[s]
        if not (r > 0.0 and r < np.inf):
            ok_range = False
        q = radius[s]
        if not (q >= 0.0 and q < np.inf):
            ok_radius = False
        w = np.int64(world[s])
        if first:
            lo, hi, first = w, w, False
        else:
            lo, hi = min(lo, w), max(hi, w)
    ok_kind = True
    olo, ohi = lo, hi
    for o in range(kind.shape[0]):
        if kind[o] < _BOX or kind[o] > _SPH:
            ok_kind = False
        w = np.int64(obj_world[o])
        olo, ohi = min(olo, w), max(ohi, w)
    return ok_range, ok_radius, lo, hi, ok_kind, olo, ohi


def _check_inputs(pos, heading, sensor_range, radius, online, world, kind, centre, half, obj_world):  # type: ignore[no-untyped-def]
    # Returns the arrays in kernel form plus the id ranges (online slots; online slots and objects).
    pos = _arr(pos, np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ValueError(f"pos must have shape (S, 3), got {pos.shape}")
    s = pos.shape[0]
    out = [pos]
    for name, a, dt in (
        ("heading", heading, np.float64),
        ("sensor_range", sensor_range, np.float64),
        ("radius", radius, np.float64),
        ("online", online, np.bool_),
        ("world", world, None),
    ):
        a = _arr(a, dt) if dt is not None else _ids(a)
        if a.shape != (s,):
            raise ValueError(f"{name} must have shape ({s},), got {a.shape}")
        out.append(a)
    kind = _arr(kind, np.int8)
    o = kind.shape[0]
    centre = _arr(centre, np.float64).reshape(o, 3)
    half = _arr(half, np.float64).reshape(o, 3)
    obj_world = _ids(obj_world)
    if obj_world.shape != (o,):
        raise ValueError(f"obj_world must have shape ({o},), got {obj_world.shape}")
    return _check_values((*out, kind, centre, half, obj_world))


def _check_values(arrays):  # type: ignore[no-untyped-def]
    # The value checks of arrays already in kernel form (every call: values change from step to step).
    _, _, srange, radius, online, world, kind, _, _, obj_world = arrays
    ok_range, ok_radius, lo, hi, ok_kind, olo, ohi = _summary(srange, radius, online, world, kind, obj_world)
    if not ok_range:
        raise ValueError("sensor_range must be finite and > 0 for every online slot")
    if not ok_radius:
        raise ValueError("radius must be finite and >= 0 for every online slot")
    if not ok_kind:
        raise ValueError("kind codes must be in {0 (box), 1 (cylinder), 2 (sphere)}")
    return arrays, (lo, hi, olo, ohi)


_NO_GRID = (np.zeros(2, dtype=np.int64), np.zeros(0, dtype=np.int64), 0.0, 0.0, 1.0, 1, 1)


def _grid_args(grid: Grid | None, lo: int, hi: int, name: str) -> tuple:
    # The kernel indexes cells by world id, so every id it looks up must exist in the grid.
    if grid is None:
        return _NO_GRID
    sp = grid.spec
    if lo < 0 or hi >= sp.n_worlds:
        raise ValueError(f"world ids must be in [0, {name}.spec.n_worlds={sp.n_worlds}), got {lo}..{hi}")
    return (grid.cell_start, grid.items, sp.origin_x, sp.origin_y, sp.cell, sp.nx, sp.ny)


class ProximitySensor:
    """Grid-accelerated ray caster for every slot (one numba kernel over row ranges, 1 thread by default)."""

    name = "proximity"
    obs_part = None  # the scenario places the ``lidar`` part among its own parts (see the module docstring)
    part_name = LIDAR_PART
    """Name of the observation part the sensor declares (:attr:`part`)."""

    def __init__(self, config: ProximityConfig | None = None) -> None:
        """Precompute the ray directions.

        Args:
            config: Ray layout and detection flags (defaults to 32 horizontal rays).
        """
        self.config = config if config is not None else ProximityConfig()
        self.directions = self.config.ray_directions()
        self._out: ScanResult | None = None
        # per row of ``_out``: it holds "nothing seen" (an offline slot's row is rewritten only when it does not: a
        # shard's world has most slots offline, ~4 ms a scan at 100,000 agents over 2 shards)
        self._blank = np.zeros(0, dtype=np.bool_)
        self._stamps = [np.empty(0, dtype=np.int64)]
        self._given: tuple[object, ...] = ()  # the arrays of the last scan, and their kernel form
        self._arrays: tuple[np.ndarray, ...] = ()
        self.threads = RowThreads(1)
        """Threads for the scan (``World.set_num_threads`` sets them); results do not depend on the count."""

    @property
    def n_rays(self) -> int:
        """Rays per slot K."""
        return self.config.n_rays

    @property
    def part(self) -> Part:
        """The ``lidar`` observation part: ``(K, 2)`` in [0, 1]."""
        return Part((self.n_rays, 2), *LIDAR_BOUNDS)

    # ------------------------------------------------------------------ the Sensor protocol (stage 8)
    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """The scan is noise-free: nothing to reset."""
        del w, rng

    def step(self, ctx: StepContext) -> ScanResult:
        """Scan every online slot on the step's shared grid (into the sensor's reused buffers)."""
        st, sc = ctx.state, ctx.scene
        return self.scan(
            st.pos,
            st.heading,
            st.sensor_range,
            st.radius,
            st.online,
            st.world_id,
            ctx.grid,
            sc.kind,
            sc.centre,
            sc.half,
            sc.world,
            ctx.object_grid,
            sc.ground,
        )

    def observe(self, reading: ScanResult) -> np.ndarray:
        """The ``lidar`` part ``(S, K, 2)`` float32 of a scan (:func:`lidar_observation`)."""
        return lidar_observation(reading)

    def scan(
        self,
        pos: np.ndarray,
        heading: np.ndarray,
        sensor_range: np.ndarray,
        radius: np.ndarray,
        online: np.ndarray,
        world: np.ndarray,
        agent_grid: Grid | None,
        kind: np.ndarray,
        centre: np.ndarray,
        half: np.ndarray,
        obj_world: np.ndarray,
        object_grid: Grid | None,
        ground: bool,
        out: ScanResult | None = None,
    ) -> ScanResult:
        """Scan every online slot.

        Args:
            pos: Slot centres ``(S, 3)`` (ray origins).
            heading: Yaw ``(S,)`` in radians; ray 0 points along it.
            sensor_range: Range ``(S,)`` in metres (> 0 for online slots); may change every step.
            radius: Agent radii ``(S,)`` (agents are spheres).
            online: Which slots scan and can be seen ``(S,)``.
            world: World id per slot ``(S,)``.
            agent_grid: ``build_grid(spec, pos, world, online)`` of this step (every online slot indexed);
                ``None`` sees no agents.
            kind: Scene object kinds ``(O,)`` (``BOX``, ``CYLINDER``, ``SPHERE``).
            centre: Object centres ``(O, 3)``.
            half: Object half extents ``(O, 3)`` (scene convention).
            obj_world: Object world ids ``(O,)``.
            object_grid: ``build_object_grid(spec, centre, scene.footprint_radius(), obj_world)`` (footprints
                must be covered); ``None`` sees no objects.
            ground: Whether the plane ``z = 0`` is solid (the scene's flag).
            out: Buffers to fill; by default the sensor's own, reused by the next scan (there an offline slot's
                row is rewritten only when it does not hold "nothing seen" already: the sensor's own rows are
                not to be written by others).

        Returns:
            The filled :class:`ScanResult`.
        """
        given = (pos, heading, sensor_range, radius, online, world, kind, centre, half, obj_world)
        last = self._given
        if len(last) == len(given) and all(map(operator.is_, given, last)):  # the same arrays as last time
            arrays, (lo, hi, olo, ohi) = _check_values(self._arrays)
        else:  # converted and shape-checked once per set of arrays
            arrays, (lo, hi, olo, ohi) = _check_inputs(*given)
            # only arrays used in place (or through a reshaped view) can be reused: a converted copy would
            # miss later changes of the caller's array
            same = all(a is g or a.base is g for a, g in zip(arrays, given))
            self._given, self._arrays = (given, arrays) if same else ((), ())
        pos, heading, srange, radius, online, world, kind, centre, half, obj_world = arrays
        s, k = pos.shape[0], self.n_rays
        if out is None:
            if self._out is None or self._out.distance.shape != (s, k):
                self._out = ScanResult.empty(s, k)
                self._blank = np.ones(s, dtype=np.bool_)  # ``empty`` rows: "nothing seen"
            out, blank = self._out, self._blank
        elif (
            out.distance.shape != (s, k)
            or out.distance.dtype != np.float32
            or out.hit_kind.dtype != np.int8
            or out.hit_id.dtype != np.int32
            or out.hit_kind.shape != (s, k)
            or out.hit_id.shape != (s, k)
        ):
            raise ValueError(f"out must hold (S, K) = ({s}, {k}) arrays of float32 / int8 / int32")
        else:  # the caller's buffers: every offline row written
            blank = np.zeros(s, dtype=np.bool_)
        use_agents = self.config.detect_agents and agent_grid is not None
        use_objects = self.config.detect_objects and object_grid is not None and kind.shape[0] > 0
        threads = self.threads
        parts = 1 if threads.num_threads == 1 else len(threads.ranges(s))
        if len(self._stamps) < parts or self._stamps[0].shape[0] < kind.shape[0]:
            self._stamps = [np.empty(kind.shape[0], dtype=np.int64) for _ in range(max(parts, len(self._stamps)))]
        agent_args = _grid_args(agent_grid if use_agents else None, lo, hi, "agent_grid")
        if use_objects:
            lo, hi = olo, ohi
        object_args = _grid_args(object_grid if use_objects else None, lo, hi, "object_grid")
        flags = (use_agents, use_objects, bool(self.config.detect_ground and ground))
        scene = (kind, centre, half, obj_world)
        prep = _scan_prep(pos, radius, online, agent_args[1], use_agents, kind, half)
        bufs = (out.distance, out.hit_kind, out.hit_id)
        stamps, dirs, n_az = self._stamps, self.directions, self.config.n_azimuth
        threads.run(
            lambda lo, hi, part: _scan_kernel(
                lo,
                hi,
                pos,
                heading,
                srange,
                online,
                world,
                agent_args,
                scene,
                object_args,
                dirs,
                n_az,
                flags,
                prep,
                stamps[part],
                bufs,
                blank,
            ),
            s,
        )
        return out
