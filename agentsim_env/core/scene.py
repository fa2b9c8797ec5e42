"""Static scene: boxes, vertical cylinders, spheres and the ground, as arrays.

Objects are rows of arrays (kind, centre, half extents, world). Boxes are axis aligned; a cylinder stands
vertically with its radius in ``half[:, 0]`` and half-height in ``half[:, 2]``; a sphere keeps its radius in
``half[:, 0]`` (all three columns hold it). The ground is the plane ``z = 0`` when ``ground`` is true.
Objects are placed explicitly or at seeded random positions without overlaps, and can be added at run time.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

BOX = 0
CYLINDER = 1
SPHERE = 2
KIND_NAMES = {"box": BOX, "cylinder": CYLINDER, "sphere": SPHERE}


def _as_rows(a: np.ndarray | list, width: int, name: str) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != width:
        raise ValueError(f"{name} must have shape (n, {width}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


@dataclass(slots=True)
class Scene:
    """All static objects of every world.

    Attributes:
        kind: Shape kind per object ``(O,)`` (``BOX``, ``CYLINDER``, ``SPHERE``).
        centre: Object centres ``(O, 3)``.
        half: Half extents ``(O, 3)`` (see module docstring).
        world: World id per object ``(O,)``.
        ground: Whether the plane ``z = 0`` is solid.
        version: Incremented on every change so caches (grids, physics) know to rebuild.
    """

    kind: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    centre: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    half: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    world: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int32))
    ground: bool = True
    version: int = 0

    @property
    def n_objects(self) -> int:
        """Number of objects over all worlds."""
        return int(self.kind.shape[0])

    def add(
        self,
        kind: str | int | np.ndarray,
        centre: np.ndarray | list,
        half: np.ndarray | list,
        world: int | np.ndarray = 0,
    ) -> np.ndarray:
        """Add objects (at construction or at run time).

        Args:
            kind: ``"box"``, ``"cylinder"``, ``"sphere"`` (or their int codes), one or one per object.
            centre: Centres ``(n, 3)``.
            half: Half extents ``(n, 3)``; must be positive.
            world: World id, one or one per object.

        Returns:
            The ids (row indices) of the new objects.
        """
        c = _as_rows(centre, 3, "centre")
        h = _as_rows(half, 3, "half")
        n = c.shape[0]
        if h.shape[0] != n:
            raise ValueError(f"half must have {n} rows to match centre, got {h.shape[0]}")
        if np.any(h <= 0):
            raise ValueError("half extents must be > 0")
        if isinstance(kind, str):
            if kind not in KIND_NAMES:
                raise ValueError(f"kind must be one of {sorted(KIND_NAMES)}, got {kind!r}")
            k = np.full(n, KIND_NAMES[kind], dtype=np.int8)
        else:
            k = np.broadcast_to(np.asarray(kind, dtype=np.int8), (n,)).copy()
            if np.any((k < BOX) | (k > SPHERE)):
                raise ValueError(f"kind codes must be in {{0, 1, 2}}, got {np.unique(k)}")
        sph = k == SPHERE
        h = h.copy()
        h[sph] = h[sph, :1]  # a sphere's extent is its radius along every axis
        w = np.broadcast_to(np.asarray(world, dtype=np.int32), (n,)).copy()
        ids = np.arange(self.n_objects, self.n_objects + n)
        self.kind = np.concatenate([self.kind, k])
        self.centre = np.vstack([self.centre, c])
        self.half = np.vstack([self.half, h])
        self.world = np.concatenate([self.world, w])
        self.version += 1
        return ids

    def footprint_radius(self) -> np.ndarray:
        """Radius of the horizontal bounding circle of each object ``(O,)``."""
        r = self.half[:, 0].copy()
        box = self.kind == BOX
        r[box] = np.hypot(self.half[box, 0], self.half[box, 1])
        return r

    def index_in_world(self, ids: np.ndarray) -> np.ndarray:
        """Each object's index among the objects of its own world, in id order (what a single world numbers it).

        Object ids run over every world of a batch, and a world reset moves its objects to the end; the index
        within the world is the same as in a single env of the same seed.

        Args:
            ids: Object ids ``(k,)``; -1 (no object) stays -1.

        Returns:
            ``(k,)`` int64 indices.
        """
        ids = np.asarray(ids, dtype=np.int64)
        out = np.full(ids.shape, -1, dtype=np.int64)
        hit = ids >= 0
        if hit.any():
            order = np.argsort(self.world, kind="stable")  # by world, id order within each world
            place = np.empty(self.n_objects, dtype=np.int64)
            place[order] = np.arange(self.n_objects)
            counts = np.bincount(self.world)
            first = np.cumsum(counts) - counts  # where each world's objects start in that order
            hit_ids = ids[hit]
            out[hit] = place[hit_ids] - first[self.world[hit_ids]]
        return out

    def top(self) -> np.ndarray:
        """Top z of each object ``(O,)``."""
        return self.centre[:, 2] + self.half[:, 2]

    def place_random(
        self,
        rng: np.random.Generator,
        n: int,
        bounds: tuple[float, float, float, float],
        *,
        world: int = 0,
        size_range: tuple[float, float] = (1.0, 3.0),
        height_range: tuple[float, float] = (5.0, 30.0),
        kinds: tuple[str, ...] = ("box", "cylinder"),
        clearance: float = 1.0,
        keep_clear: np.ndarray | None = None,
        keep_clear_radius: float = 0.0,
        max_tries: int = 50,
    ) -> np.ndarray:
        """Place up to ``n`` objects at seeded random positions without overlapping each other.

        Objects stand on the ground (their base at z = 0). Candidates are drawn in batches and accepted greedily
        when their footprint circle keeps ``clearance`` from every accepted object of this world and
        ``keep_clear_radius`` from every point of ``keep_clear`` (e.g. spawn points and goals).

        Args:
            rng: The random generator (the only source of randomness).
            n: Number of objects wanted.
            bounds: ``(xmin, xmax, ymin, ymax)`` of the area.
            world: World id of the new objects.
            size_range: Range of footprint half sizes (box half side, cylinder radius).
            height_range: Range of object heights.
            kinds: Shape kinds to draw from.
            clearance: Minimum gap between footprints.
            keep_clear: Points ``(m, 2)`` or ``(m, 3)`` to keep free.
            keep_clear_radius: Minimum distance between a footprint and those points.
            max_tries: Candidate batches before giving up (fewer objects are placed then).

        Returns:
            The ids of the placed objects.
        """
        if n <= 0:
            return np.zeros(0, dtype=np.int64)
        for k in kinds:
            if k not in ("box", "cylinder"):
                raise ValueError(f"kinds must be among ('box', 'cylinder') for ground objects, got {k!r}")
        xmin, xmax, ymin, ymax = bounds
        mine = self.world == world
        acc_xy = [self.centre[mine, :2]]
        acc_r = [self.footprint_radius()[mine]]
        new_c, new_h, new_k = [], [], []
        pts = None if keep_clear is None else np.asarray(keep_clear, dtype=np.float64)[:, :2]
        placed = 0
        for _ in range(max_tries):
            m = 4 * (n - placed)
            kk = rng.integers(0, len(kinds), m)
            hs = rng.uniform(*size_range, m)
            hh = rng.uniform(*height_range, m) / 2.0
            fr = np.where(np.asarray(kinds)[kk] == "box", hs * np.sqrt(2.0), hs)
            xy = np.column_stack([rng.uniform(xmin + fr, xmax - fr), rng.uniform(ymin + fr, ymax - fr)])
            for i in range(m):
                cx, cr = np.concatenate(acc_xy), np.concatenate(acc_r)
                if cx.shape[0] and np.any(np.hypot(*(cx - xy[i]).T) < cr + fr[i] + clearance):
                    continue
                if pts is not None and pts.shape[0] and np.any(np.hypot(*(pts - xy[i]).T) < fr[i] + keep_clear_radius):
                    continue
                acc_xy.append(xy[i : i + 1])
                acc_r.append(fr[i : i + 1])
                new_c.append([xy[i, 0], xy[i, 1], hh[i]])
                new_h.append([hs[i], hs[i], hh[i]])
                new_k.append(KIND_NAMES[kinds[kk[i]]])
                placed += 1
                if placed == n:
                    break
            if placed == n:
                break
        if not new_c:
            return np.zeros(0, dtype=np.int64)
        return self.add(np.asarray(new_k, dtype=np.int8), np.asarray(new_c), np.asarray(new_h), world)

    def copy(self) -> Scene:
        """Return a deep copy."""
        return copy.deepcopy(self)
