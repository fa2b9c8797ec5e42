"""Planar contact dynamics for agents and obstacle footprints (the project's only pymunk adapter).

Agents are dynamic circles (mass ``pi r^2``, infinite moment so they never spin) and obstacles are static
footprints: a box becomes an axis-aligned rectangle, a cylinder or a sphere a circle of its radius. Contacts
are resolved in the horizontal plane only; altitude decides which contacts count:

* agent-obstacle: only if the agent's sphere overlaps the obstacle's vertical extent
  (``z - r < top`` and ``z + r > bottom``), so an agent above an obstacle's top passes over it;
* agent-agent: only if ``|z_a - z_b| < r_a + r_b``.

All worlds share ONE ``pymunk.Space`` (one C call steps every world, where a space per world would need a
Python loop per world). World ``w`` is translated by ``w * world_spacing`` metres along x (default 1e5 m),
so worlds never interact as long as every online agent keeps ``|x| < world_spacing / 2``; ``step`` checks
this. The translation costs about ``1e-11 * w`` m of rounding on positions read back.

Motion is velocity controlled: each step sets every online body's position and velocity from the arrays,
runs ``substeps`` solver steps, and reads positions and velocities back. The solver removes the velocity
component into a wall (friction and elasticity are zero), so a pushed agent slides along it. There is no
continuous collision detection: an agent does not tunnel while ``speed * dt / substeps`` stays below its
radius plus the obstacle's half thickness. Offline agents are parked far away with a shape filter that
rejects every contact; they are reported unchanged and produce no contacts.

Arrays cross into pymunk with ``pymunk.batch`` (one call to set, one to get, no per-body Python, buffers
preallocated); the only per-contact Python is the altitude filter callback (pymunk calls it for each touching
pair and sub-step). :meth:`PymunkPlanarBackend.step` validates its input; the world calls
:meth:`PymunkPlanarBackend.step_unchecked`, which trusts it and writes in place (same arithmetic, same
results). Pickling and :meth:`PymunkPlanarBackend.reset` rebuild the space from arrays (see their docstrings
for what pymunk state that drops).
"""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.scene import BOX, SPHERE
from ._pymunk_arrays import (
    _NO_CONTACTS,
    PhysicsContacts,
    _check_backend_args,
    _check_obstacles,
    _check_step_inputs,
    _int_array,
    _pack,
    _unpack,
)
from ._pymunk_fastpath import cffi_shape_getter, shape_reader

if TYPE_CHECKING:
    import pymunk

__all__ = ["PhysicsContacts", "PymunkPlanarBackend"]

_AGENT_TYPE = 1
_OBSTACLE_TYPE = 2
# Parking area for offline bodies: far from any sensible scene so the broad phase never pairs them with
# online bodies (their shape filter would reject the pair anyway) and spread out so parked bodies do not
# pair with each other.
_PARK_Y = -1.0e9


def _import_pymunk() -> Any:
    """Import pymunk 7 lazily so that the package imports without it."""
    try:
        import pymunk
        import pymunk.batch  # noqa: F401  (submodule used through the package attribute)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            'the pymunk physics backend needs pymunk 7; install it with: pip install "pymunk>=7,<8"'
        ) from exc
    if int(str(pymunk.version).split(".")[0]) != 7:  # the batch and collision APIs changed in 7.0
        raise ImportError(f'pymunk {pymunk.version} found; install it with: pip install "pymunk>=7,<8"')
    return pymunk


@cache
def _cffi_shape_getter() -> tuple[Any, Any] | None:
    """``(ffi, lib)`` for the C fast path of the collision callbacks, or None (see ``_pymunk_fastpath``)."""
    return cffi_shape_getter(_import_pymunk())


class PymunkPlanarBackend:
    """Planar physics for all slots of all worlds in one pymunk space (see the module docstring).

    Args:
        radius: Agent radius per slot ``(S,)`` in m, positive.
        world_id: World of each slot ``(S,)``, integers in ``[0, n_worlds)``.
        n_worlds: Number of independent worlds, at least 1.
        obj_kind: Obstacle kind ``(O,)``: 0 box, 1 cylinder, 2 sphere.
        obj_centre: Obstacle centres ``(O, 3)`` in m.
        obj_half: Half extents ``(O, 3)``: box x, y, z; cylinder radius in [0], half-height in [2];
            sphere radius in [0].
        obj_world: World of each obstacle ``(O,)``.
        substeps: Solver steps per ``step`` call, at least 1.
        world_spacing: Translation between consecutive worlds along x, in m.
        collision_slop: Penetration the solver tolerates before pushing apart, in m (pymunk's default
            0.1 m is too coarse for metre-sized agents).
        correction: Fraction of the penetration beyond the slop removed per sub-step, in (0, 1). pymunk
            integrates positions before it solves contacts, so an agent commanded into a wall sinks
            ``speed * dt / substeps`` into it each step; pymunk's default (10 % per 1/60 s) leaves a
            standing overlap of ~0.1 m at 3 m/s, 0.5 leaves ~0.015 m and stays stable in dense crowds.
    """

    # All state is declared here; nothing is added on the fly.
    __slots__ = tuple(
        "_agent_shapes _args _bottom _correction _dt _fields _get_buf _key _obj_centre _obj_half _obj_kind"
        " _obj_of_shape _obj_world _online _online_key _pa _park _pb _pm _pos _r_list _radius _read_shapes"
        " _set_arr _set_buf _slot_of_shape _space _substep _top _touch_now _touch_prev _world_id"
        " _x_offset".split()
    )

    def __init__(
        self,
        radius: np.ndarray,
        world_id: np.ndarray,
        n_worlds: int,
        obj_kind: np.ndarray,
        obj_centre: np.ndarray,
        obj_half: np.ndarray,
        obj_world: np.ndarray,
        substeps: int = 4,
        *,
        world_spacing: float = 1.0e5,
        collision_slop: float = 0.005,
        correction: float = 0.5,
    ) -> None:
        r = _check_backend_args(radius, n_worlds, substeps, world_spacing, collision_slop, correction)
        n = r.shape[0]
        self._radius = r.copy()
        self._world_id = _int_array("world_id", world_id, (n,), 0, int(n_worlds))
        self._correction = float(correction)
        # Everything but the obstacles, which add_obstacles may extend; used to rebuild after unpickling.
        self._args: dict[str, Any] = {
            "radius": self._radius,
            "world_id": self._world_id,
            "n_worlds": int(n_worlds),
            "substeps": int(substeps),
            "world_spacing": float(world_spacing),
            "collision_slop": float(collision_slop),
            "correction": self._correction,
        }
        self._x_offset = self._world_id * float(world_spacing)
        # Parking spots 3 max radii apart keep parked bodies out of each other's bounding boxes; a square
        # grid, since pymunk's bounding-box tree degrades to quadratic insertion time on a sorted line.
        side = int(np.ceil(np.sqrt(n)))
        cell = 3.0 * r.max()
        slots = np.arange(n)
        self._park = np.stack([(slots % side) * cell, _PARK_Y - (slots // side) * cell], axis=1)
        self._r_list: list[float] = r.tolist()
        # The step's ``pos``, for the filter callbacks (``pos.item(slot, 2)``: a float without converting
        # the whole column, since most steps have few touching pairs or none).
        self._pos = np.zeros((n, 3))
        self._touch_now: set[tuple[int, int, int]] = set()
        self._touch_prev: set[tuple[int, int, int]] = set()
        self._online = np.zeros(n, dtype=bool)
        self._online_key = self._online.tobytes()
        self._dt = -1.0  # the dt the sub-step and collision bias were derived from (none yet)
        self._substep = 0.0

        pm = _import_pymunk()
        self._pm = pm
        space = pm.Space()
        space.gravity = (0.0, 0.0)
        space.damping = 1.0
        space.collision_slop = float(collision_slop)
        self._space = space
        _ = space.static_body  # created lazily; create it now so the batch arrays always have S + 1 rows
        bodies = []
        shapes = []
        for s in range(n):  # construction only; the step never loops over agents
            body = pm.Body(np.pi * r[s] ** 2, float("inf"))
            body.position = (float(self._park[s, 0]), float(self._park[s, 1]))
            shape = pm.Circle(body, float(r[s]))
            shape.collision_type = _AGENT_TYPE
            shape.filter = pm.ShapeFilter(categories=0, mask=0)  # starts offline: no contacts at all
            bodies.append(body)
            shapes.append(shape)
        space.add(*bodies)
        space.add(*shapes)
        self._agent_shapes = shapes
        # The callbacks map an arbiter's shapes to slots and obstacles through dicts keyed by self._key.
        self._read_shapes, self._pa, self._pb, self._key = shape_reader(_cffi_shape_getter())
        self._slot_of_shape = {self._key(shape): s for s, shape in enumerate(shapes)}
        self._obj_of_shape: dict[Any, int] = {}
        space.on_collision(_AGENT_TYPE, _AGENT_TYPE, pre_solve=self._pre_solve_agents)
        space.on_collision(_AGENT_TYPE, _OBSTACLE_TYPE, pre_solve=self._pre_solve_obstacle)

        # pymunk.batch walks the dynamic bodies in insertion order, then the static body the obstacles hang
        # on; check it once so slot s is row s of the batch arrays.
        self._get_buf = pm.batch.Buffer()
        pm.batch.get_space_bodies(space, pm.batch.BodyFields.BODY_ID, self._get_buf)
        ids = np.frombuffer(self._get_buf.int_buf(), dtype=np.uintp)
        if ids.shape[0] != n + 1 or ids[:n].tolist() != [b.id for b in bodies]:
            raise RuntimeError("pymunk.batch does not walk bodies in insertion order; unsupported pymunk")
        # The set buffer wraps our array (it is read, never grown); the get buffer is owned by pymunk (its
        # push reallocates before the array is full, so it cannot wrap ours). Rows: x, y, vx, vy; offline
        # rows hold their parking spot at rest (written when the online set changes, never per step) and
        # the static body's row stays zero (at the origin, at rest).
        self._set_arr = np.zeros((n + 1, 4), dtype=np.float64)
        self._set_arr[:n, :2] = self._park
        self._set_buf = pm.batch.Buffer()
        self._set_buf.set_float_buf(self._set_arr)
        self._fields = pm.batch.BodyFields.POSITION | pm.batch.BodyFields.VELOCITY

        self._obj_kind = np.zeros(0, dtype=np.int8)
        self._obj_centre = np.zeros((0, 3))
        self._obj_half = np.zeros((0, 3))
        self._obj_world = np.zeros(0, dtype=np.int32)
        self._bottom: list[float] = []
        self._top: list[float] = []
        self.add_obstacles(obj_kind, obj_centre, obj_half, obj_world)

    @property
    def n_slots(self) -> int:
        """Number of agent slots S."""
        return int(self._radius.shape[0])

    @property
    def n_obstacles(self) -> int:
        """Number of obstacles O (all worlds, including those added at run time)."""
        return int(self._obj_kind.shape[0])

    def add_obstacles(
        self, obj_kind: np.ndarray, obj_centre: np.ndarray, obj_half: np.ndarray, obj_world: np.ndarray
    ) -> np.ndarray:
        """Add static obstacles (at construction or at run time); arrays as in the constructor.

        Args:
            obj_kind: Obstacle kind ``(K,)``: 0 box, 1 cylinder, 2 sphere.
            obj_centre: Centres ``(K, 3)``.
            obj_half: Half extents ``(K, 3)``.
            obj_world: World of each obstacle ``(K,)``.

        Returns:
            The obstacle indices given to the new obstacles ``(K,) int64``.
        """
        n_w = self._args["n_worlds"]
        kind, centre, half, world = _check_obstacles(obj_kind, obj_centre, obj_half, obj_world, n_w)
        first = self.n_obstacles
        pm = self._pm
        static = self._space.static_body
        shapes = []
        for i in range(kind.shape[0]):  # obstacles are few and added rarely
            cx = float(centre[i, 0] + world[i] * self._args["world_spacing"])
            cy = float(centre[i, 1])
            if kind[i] == BOX:
                hx, hy = float(half[i, 0]), float(half[i, 1])
                verts = [(cx - hx, cy - hy), (cx + hx, cy - hy), (cx + hx, cy + hy), (cx - hx, cy + hy)]
                shape = pm.Poly(static, verts)
            else:
                shape = pm.Circle(static, float(half[i, 0]), (cx, cy))
            shape.collision_type = _OBSTACLE_TYPE
            self._obj_of_shape[self._key(shape)] = first + i
            shapes.append(shape)
        half_z = np.where(kind == SPHERE, half[:, 0], half[:, 2])
        self._bottom.extend((centre[:, 2] - half_z).tolist())
        self._top.extend((centre[:, 2] + half_z).tolist())
        self._obj_kind = np.concatenate([self._obj_kind, kind])
        self._obj_centre = np.concatenate([self._obj_centre, centre])
        self._obj_half = np.concatenate([self._obj_half, half])
        self._obj_world = np.concatenate([self._obj_world, world])
        if shapes:
            self._space.add(*shapes)
        return np.arange(first, first + kind.shape[0], dtype=np.int64)

    def extend_obstacles(
        self, obj_kind: np.ndarray, obj_centre: np.ndarray, obj_half: np.ndarray, obj_world: np.ndarray
    ) -> bool:
        """Catch up with a scene that may only have gained obstacles since this backend saw it.

        Args:
            obj_kind: All obstacle kinds of the scene ``(O',)``.
            obj_centre: All centres ``(O', 3)``.
            obj_half: All half extents ``(O', 3)``.
            obj_world: All worlds ``(O',)``.

        Returns:
            True if this backend's obstacles are an unchanged prefix of the given ones (the rest are added
            with :meth:`add_obstacles`); False if not, in which case nothing changed and the caller must
            build a new backend.
        """
        k = self.n_obstacles
        kind, centre = np.asarray(obj_kind), np.asarray(obj_centre, dtype=np.float64)
        half, world = np.asarray(obj_half, dtype=np.float64), np.asarray(obj_world)
        if kind.ndim != 1 or kind.shape[0] < k:
            return False
        same = (
            np.array_equal(kind[:k], self._obj_kind)
            and np.array_equal(centre[:k], self._obj_centre)
            and np.array_equal(half[:k], self._obj_half)
            and np.array_equal(world[:k], self._obj_world)
        )
        if same and kind.shape[0] > k:
            self.add_obstacles(kind[k:], centre[k:], half[k:], world[k:])
        return bool(same)

    # Collision callbacks: pymunk calls them for every touching pair in every sub-step. The flag persists on
    # the arbiter between steps, so it is set explicitly both ways.
    def _pre_solve_agents(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._read_shapes(arbiter)
        a = self._slot_of_shape[self._pa[0]]
        b = self._slot_of_shape[self._pb[0]]
        r = self._r_list
        ok = abs(self._pos.item(a, 2) - self._pos.item(b, 2)) < r[a] + r[b]
        arbiter.process_collision = ok
        if ok:
            self._touch_now.add((a, b, -1) if a < b else (b, a, -1))

    def _pre_solve_obstacle(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._read_shapes(arbiter)
        a = self._slot_of_shape[self._pa[0]]
        o = self._obj_of_shape[self._pb[0]]
        z = self._pos.item(a, 2)
        r = self._r_list[a]
        ok = z - r < self._top[o] and z + r > self._bottom[o]
        arbiter.process_collision = ok
        if ok:
            self._touch_now.add((a, -1, o))

    def _set_online(self, online: np.ndarray) -> None:
        on = np.array(online, dtype=bool)  # own copy: the caller may change its array
        changed = np.flatnonzero(on != self._online)
        if changed.size:
            on_f = self._pm.ShapeFilter()
            off_f = self._pm.ShapeFilter(categories=0, mask=0)
            for s in changed.tolist():  # only slots whose status changed, which is rare
                self._agent_shapes[s].filter = on_f if on[s] else off_f
        went_off = changed[~on[changed]]  # their batch rows go back to the parking spot, at rest
        self._set_arr[went_off, :2] = self._park[went_off]
        self._set_arr[went_off, 2:] = 0.0
        self._online = on
        self._online_key = on.tobytes()

    def step(
        self, pos: np.ndarray, desired_vel: np.ndarray, online: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray, PhysicsContacts]:
        """Advance every world by ``dt`` under velocity control.

        Args:
            pos: Positions ``(S, 3)``; x, y start the step, z filters contacts. Offline rows are ignored.
            desired_vel: Commanded velocities ``(S, 3)``; only x, y are used.
            online: Which slots take part ``(S,) bool``.
            dt: Step length in s, positive.

        Returns:
            ``(new_xy (S, 2), new_vel_xy (S, 2), contacts)``: fresh arrays; offline rows repeat
            ``pos[:, :2]`` and ``desired_vel[:, :2]``; ``contacts`` holds the pairs that began touching
            (after the altitude filter) during this step and did not touch during the previous one.
        """
        n = self.n_slots
        half_band = 0.5 * self._args["world_spacing"]
        pos, vel, on = _check_step_inputs(pos, desired_vel, online, dt, n, half_band)
        new_xy = pos[:, :2].copy()
        new_vel = vel[:, :2].copy()
        contacts = self.step_unchecked(pos, vel, on, float(dt), new_xy, new_vel)
        return new_xy, new_vel, contacts

    def step_unchecked(
        self,
        pos: np.ndarray,
        desired_vel: np.ndarray,
        online: np.ndarray,
        dt: float,
        out_xy: np.ndarray,
        out_vel: np.ndarray,
    ) -> PhysicsContacts:
        """:meth:`step` without input checks, writing the online rows' results in place (the world's path).

        The caller guarantees what :meth:`step` checks: float64 ``pos (S, 3)`` and ``desired_vel (S, >= 2)``
        finite on online rows, ``online (S,) bool``, ``dt > 0`` and ``|x| < world_spacing / 2`` online.
        Results equal :meth:`step`'s bit for bit.

        Args:
            pos: Positions ``(S, 3)``; x, y start the step, z filters contacts.
            desired_vel: Commanded velocities ``(S, >= 2)``; columns 0 and 1 are used.
            online: Which slots take part ``(S,) bool``.
            dt: Step length in s.
            out_xy: Receives the new x, y in columns 0 and 1 of the online rows ``(S, >= 2)``; other entries
                are left alone. May be ``pos`` itself.
            out_vel: Receives the new vx, vy likewise ``(S, >= 2)``.

        Returns:
            The pairs that began touching during this step (as in :meth:`step`); the shared empty instance
            (read-only arrays) when there are none.
        """
        if online.tobytes() != self._online_key:  # a byte compare: cheaper than an array compare
            self._set_online(online)
        _pack(pos, desired_vel, self._online, self._x_offset, self._set_arr)
        self._pos = pos
        batch, space = self._pm.batch, self._space
        batch.set_space_bodies(space, self._fields, self._set_buf)

        if dt != self._dt:
            self._dt = dt
            self._substep = float(dt) / self._args["substeps"]
            # pymunk's bias is the fraction of overlap left after one second; derive it from the sub-step.
            space.collision_bias = (1.0 - self._correction) ** (1.0 / self._substep)
        h = self._substep
        for _ in range(self._args["substeps"]):
            space.step(h)

        self._get_buf.clear()
        batch.get_space_bodies(space, self._fields, self._get_buf)
        body = np.frombuffer(self._get_buf.float_buf(), dtype=np.float64).reshape(-1, 4)
        _unpack(body, self._online, self._x_offset, out_xy, out_vel)

        now, prev = self._touch_now, self._touch_prev
        began = now - prev if now else None
        self._touch_prev = now
        prev.clear()
        self._touch_now = prev  # reused as next step's (empty) set
        if not began:
            return _NO_CONTACTS
        rows = np.array(sorted(began), dtype=np.int64)
        return PhysicsContacts(rows[:, 0].copy(), rows[:, 1].copy(), rows[:, 2].copy())

    def reset(self) -> None:
        """Forget all contact history (call on episode reset for reproducible episodes).

        pymunk keeps hidden state between steps: cached contact impulses (warm starting) and the pending
        overlap correction of the last sub-step. Rebuilding the space drops it, along with the memory of
        which pairs touched during the previous step; obstacles added at run time are kept.
        """
        state = self.__getstate__()
        state["touch_prev"] = []
        self.__setstate__(state)

    def __getstate__(self) -> dict[str, Any]:
        """Constructor arguments, all obstacles, online flags and last step's touching pairs.

        Body positions need not be kept: every step sets them from ``pos``. The space is rebuilt on load,
        so pymunk's hidden contact state (see :meth:`reset`) is not kept: the next step is identical when
        no contact is active at pickling time, and otherwise differs by the solver's warm-start effect
        (order 1e-3 m for a resting contact, more in dense crowds).
        """
        obstacles = {
            "obj_kind": self._obj_kind,
            "obj_centre": self._obj_centre,
            "obj_half": self._obj_half,
            "obj_world": self._obj_world,
        }
        return {
            "args": dict(self._args),
            "obstacles": obstacles,
            "online": self._online.copy(),
            "touch_prev": sorted(self._touch_prev),
        }

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Rebuild the space from :meth:`__getstate__` output."""
        self.__init__(**state["args"], **state["obstacles"])  # type: ignore[misc]
        self._set_online(np.asarray(state["online"], dtype=bool))
        self._touch_prev = {(int(a), int(b), int(c)) for a, b, c in state["touch_prev"]}
