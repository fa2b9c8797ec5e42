"""Work allocation and the message protocol of the multi-UAV release baselines (domain reference 5.3).

Allocation (``split_work``). Zones are taken in order of decreasing weight (ties: lower zone index); the
sensors of the zones, each zone's in angular order, form one global sequence of ``S = sum N_k`` slots that
is cut into ``n_uavs`` contiguous chunks of ``c = ceil(S / n_uavs)`` (the last ones may be shorter). A
chunk becomes one *piece* per zone it touches: the zone, the wedge ``[t0 + 2 pi a / N, t0 + 2 pi b / N)``
of its local slots ``a..b`` (equal mass, the profiles being radially symmetric; ``t0`` points from the
zone centre toward the UAV base, so the first wedge faces the base) and the count ``b - a``. A piece
covering a whole zone has no wedge (``sector=None``).

Plans are a deterministic function of the mission parameters every UAV shares (zones, fleet, payload,
fall model, wind forecast, strategy, seed) and of the UAVs' start positions (which the first messages
carry), so every UAV can recompute every other UAV's targets: that is what makes reclaiming a lost UAV's
remaining work possible without shipping target lists over the bus.

Messages (group channel, one per UAV and step; payload of ``PAYLOAD_DIM = 6`` floats in [-1, 1]):

=====  ==============================================================================================
index  content
=====  ==============================================================================================
0      message type / 8: HELLO = 1, CLAIM = 2, RELEASED = 3, DONE = 4
1      sender's UAV index / 1024 (the inbox does not carry the sender, so the payload does)
2      CLAIM, RELEASED: zone index / 1024; HELLO, DONE: payload left / payload
3      CLAIM, RELEASED: piece index / 1024; HELLO, DONE: 0
4, 5   x / width * 2 - 1, y / height * 2 - 1: the target (CLAIM, RELEASED) or the sender (HELLO, DONE)
=====  ==============================================================================================

Indices up to 1023 are exact in float32. A CLAIM from a piece's planned owner claims the whole piece (its
``x, y`` is the piece's first target); a CLAIM from any other UAV claims the single target at ``x, y``
(overflow or reclaimed work). RELEASED names the target just released; DONE says the sender has no work
left (with its payload left). A UAV quiet for ``hello_every`` steps sends a heartbeat: HELLO while it has
work, DONE again once idle (so a lost DONE is repaired); any message counts as a sign of life. A UAV
whose target another UAV claims (it was taken for lost) leaves that target to the claimer.

Task lists (``plan_mission``). A task is ``(kind, target id, xy, aim, heading, zone)``: ``WAYPOINT`` (fly to
``xy``), ``FLY`` (release over target ``xy`` flying through, planned release point ``aim`` and heading) or
``HOVER`` (stop over ``aim``, release on target ``xy``). A UAV's plans beyond its payload are cut after its
``payload``-th release; the cut targets go, in order, to the lowest-id UAVs with spare payload.

Loss and reclaim (``MissionView``). A UAV not heard for more than ``lost_after`` steps that has not said
DONE is lost; its *orphans* are the targets it owns (in the viewer's knowledge) and has not announced
RELEASED. They are reclaimed, in plan order, by the lowest-id UAV that is alive, has said DONE (or is the
viewer, idle) and has payload left, while no other live UAV is still busy with a reclaim (deterministic:
ties go to the lower id). It takes as many as it can carry and announces a CLAIM per target.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agentsim_env.policies.release.planning import assemble_plan, plan_tour
from agentsim_env.policies.release.strategy import ReleaseStrategy
from agentsim_env.uav.zones import Zone, ZoneSet

__all__ = [
    "FLY",
    "HOVER",
    "IDLE",
    "WAYPOINT",
    "MSG_CLAIM",
    "MSG_DONE",
    "MSG_HELLO",
    "MSG_NAMES",
    "MSG_RELEASED",
    "PAYLOAD_DIM",
    "MissionView",
    "Piece",
    "TargetBook",
    "decode",
    "encode",
    "piece_tasks",
    "plan_mission",
    "rim_pull",
    "split_work",
    "target_tasks",
]

IDLE, WAYPOINT, FLY, HOVER = 0, 1, 2, 3
MSG_HELLO, MSG_CLAIM, MSG_RELEASED, MSG_DONE = 1, 2, 3, 4
MSG_NAMES = {MSG_HELLO: "HELLO", MSG_CLAIM: "CLAIM", MSG_RELEASED: "RELEASED", MSG_DONE: "DONE"}
PAYLOAD_DIM = 6
TYPE_SCALE = 8.0
INDEX_SCALE = 1024.0


@dataclass(frozen=True)
class Piece:
    """One UAV's share of one zone.

    Attributes:
        pid: Piece index (position in ``split_work``'s list).
        uav: Planned owner.
        zone: Zone index.
        sector: ``(theta0, theta1)`` wedge, or ``None`` for the whole zone.
        count: Sensors of the zone's quota in this piece.
    """

    pid: int
    uav: int
    zone: int
    sector: tuple[float, float] | None
    count: int


def split_work(zones: ZoneSet, n_uavs: int, payload: int) -> list[Piece]:
    """Cut the zones' sensors into contiguous per-UAV chunks of pieces (see the module docstring).

    Args:
        zones: The zone set (``base`` orients the wedges; the map centre is used without one).
        n_uavs: Number of UAVs (>= 1).
        payload: Sensors each UAV carries; must be >= ``ceil(S / n_uavs)``.

    Returns:
        Pieces ordered by UAV, then by the global sequence.

    Raises:
        ValueError: If ``n_uavs < 1`` or the chunk size exceeds ``payload``.
    """
    if isinstance(n_uavs, bool) or not isinstance(n_uavs, (int, np.integer)) or n_uavs < 1:
        raise ValueError(f"n_uavs must be an integer >= 1, got {n_uavs!r}")
    total = zones.n_sensors
    chunk = math.ceil(total / n_uavs)
    if chunk > payload:
        raise ValueError(f"payload must be >= ceil(total sensors / n_uavs) = {chunk}, got {payload}")
    order = sorted(range(len(zones.zones)), key=lambda k: (-zones.zones[k].weight, k))
    base = np.asarray(zones.base if zones.base is not None else np.asarray(zones.map_size) / 2.0)
    starts = np.cumsum([0] + [zones.zones[k].n_sensors for k in order])
    pieces: list[Piece] = []
    for j in range(n_uavs):
        lo, hi = j * chunk, min((j + 1) * chunk, total)
        for pos, k in enumerate(order):
            a, b = max(lo, starts[pos]) - starts[pos], min(hi, starts[pos + 1]) - starts[pos]
            if b <= a:
                continue
            z = zones.zones[k]
            n = z.n_sensors
            t0 = math.atan2(base[1] - z.centre[1], base[0] - z.centre[0])
            sector = None if (a == 0 and b == n) else (t0 + 2 * math.pi * a / n, t0 + 2 * math.pi * b / n)
            pieces.append(Piece(len(pieces), j, k, sector, int(b - a)))
    return pieces


def encode(
    kind: int,
    uav: int,
    xy: ArrayLike,
    map_size: tuple[float, float],
    *,
    zone: int = 0,
    piece: int = 0,
    payload_frac: float = 0.0,
) -> NDArray[np.float32]:
    """Payload of one message (layout in the module docstring).

    Args:
        kind: ``MSG_HELLO``, ``MSG_CLAIM``, ``MSG_RELEASED`` or ``MSG_DONE``.
        uav: Sender's index (0..1023).
        xy: Target (CLAIM, RELEASED) or sender position (HELLO, DONE), map metres.
        map_size: ``(width, height)`` of the map.
        zone: Zone index (CLAIM, RELEASED).
        piece: Piece index (CLAIM, RELEASED).
        payload_frac: Payload left / payload (HELLO, DONE).

    Returns:
        ``(PAYLOAD_DIM,)`` float32.
    """
    if kind not in MSG_NAMES:
        raise ValueError(f"kind must be one of {sorted(MSG_NAMES)} ({', '.join(MSG_NAMES.values())}), got {kind!r}")
    for name, v in (("uav", uav), ("zone", zone), ("piece", piece)):
        if not 0 <= v < INDEX_SCALE:
            raise ValueError(f"{name} must be in [0, {INDEX_SCALE:g}) to be encoded exactly, got {v!r}")
    counts = kind in (MSG_CLAIM, MSG_RELEASED)
    f2 = zone / INDEX_SCALE if counts else float(payload_frac)
    f3 = piece / INDEX_SCALE if counts else 0.0
    p = np.asarray(xy, dtype=np.float64).reshape(2)
    w, h = map_size
    out = np.array([kind / TYPE_SCALE, uav / INDEX_SCALE, f2, f3, p[0] / w * 2 - 1, p[1] / h * 2 - 1])
    return np.clip(out, -1.0, 1.0).astype(np.float32)


def decode(payload: ArrayLike, map_size: tuple[float, float], capacity: int) -> dict[str, NDArray]:
    """Decode message payloads ``(k, >= PAYLOAD_DIM)``.

    Args:
        payload: Payload rows as received.
        map_size: ``(width, height)`` of the map.
        capacity: Payload per UAV (to turn fractions back into counts).

    Returns:
        ``kind``, ``uav``, ``zone``, ``piece``, ``left`` (int64 ``(k,)``) and ``xy`` (``(k, 2)``).
    """
    p = np.asarray(payload, dtype=np.float64).reshape(-1, np.shape(payload)[-1])
    w, h = map_size
    return {
        "kind": np.rint(p[:, 0] * TYPE_SCALE).astype(np.int64),
        "uav": np.rint(p[:, 1] * INDEX_SCALE).astype(np.int64),
        "zone": np.rint(p[:, 2] * INDEX_SCALE).astype(np.int64),
        "piece": np.rint(p[:, 3] * INDEX_SCALE).astype(np.int64),
        "left": np.rint(p[:, 2] * capacity).astype(np.int64),
        "xy": np.column_stack([(p[:, 4] + 1) / 2 * w, (p[:, 5] + 1) / 2 * h]),
    }


@dataclass(eq=False)
class TargetBook:
    """Every planned landing target of the mission (shared knowledge).

    Attributes:
        xy: ``(m, 2)`` targets.
        zone: ``(m,)`` zone index.
        piece: ``(m,)`` piece index.
        owner: ``(m,)`` UAV that flies it in the plan.
        pieces: The pieces (``pieces[pid].uav`` is the piece's planned owner).
    """

    xy: NDArray[np.float64]
    zone: NDArray[np.int64]
    piece: NDArray[np.int64]
    owner: NDArray[np.int64]
    pieces: list[Piece]

    def find(self, piece: int, xy: ArrayLike, tol: float = 0.05) -> int:
        """Target id of piece ``piece`` at ``xy`` (within ``tol`` m), or -1."""
        ids = np.flatnonzero(self.piece == piece)
        if ids.size == 0:
            return -1
        d = np.hypot(*(self.xy[ids] - np.asarray(xy, dtype=np.float64).reshape(1, 2)).T)
        i = int(np.argmin(d))
        return int(ids[i]) if d[i] <= tol else -1


def rim_pull(xy: ArrayLike, centre: ArrayLike, radius: float, margin: float) -> NDArray[np.float64]:
    """Shift ``(n, 2)`` that moves points closer than ``margin`` to the rim radially in to ``radius - margin``.

    Targets hugging the rim would land outside the zone with any landing scatter; the cap never goes below
    half the radius.
    """
    off = np.asarray(xy, dtype=np.float64).reshape(-1, 2) - np.asarray(centre, dtype=np.float64)
    r = np.maximum(np.hypot(off[:, 0], off[:, 1]), 1e-9)
    cap = max(radius - margin, 0.5 * radius)
    return off * (np.minimum(r, cap) / r - 1.0)[:, None]


def plan_mission(
    pieces: list[Piece],
    starts: NDArray[np.float64],
    payload: int,
    plan_piece: Callable[[Piece, NDArray[np.float64]], list[tuple]],
    plan_targets: Callable[[int, NDArray[np.int64], NDArray[np.float64], TargetBook], list[tuple]],
) -> tuple[TargetBook, list[list[tuple]], list[list[int]]]:
    """Every UAV's task list: its pieces in order, then overflow targets of other UAVs (module docstring).

    Args:
        pieces: ``split_work`` output.
        starts: ``(n, 2)`` start positions.
        payload: Sensors per UAV.
        plan_piece: ``(piece, start) -> tasks`` with target id ``-1`` (ids are assigned here).
        plan_targets: ``(uav, target ids, start, book) -> tasks`` for loose targets.

    Returns:
        ``(book, tasks per UAV, overflow target ids given to each UAV)``.
    """
    n = starts.shape[0]
    tasks: list[list[tuple]] = [[] for _ in range(n)]
    xy: list[NDArray[np.float64]] = []
    meta: list[tuple[int, int, int]] = []  # zone, piece, owner of each target
    for pc in pieces:
        j = pc.uav
        for t in plan_piece(pc, tasks[j][-1][2] if tasks[j] else starts[j]):
            if t[0] != WAYPOINT:
                t = (t[0], len(xy), *t[2:])
                xy.append(t[2])
                meta.append((pc.zone, pc.pid, j))
            tasks[j].append(t)
    zone, piece, owner = np.array(meta, dtype=np.int64).reshape(-1, 3).T
    book = TargetBook(np.array(xy).reshape(-1, 2), zone.copy(), piece.copy(), owner.copy(), pieces)
    over: list[int] = []
    for j in range(n):
        rel = [i for i, t in enumerate(tasks[j]) if t[0] != WAYPOINT]
        if len(rel) > payload:
            over += [tasks[j][i][1] for i in rel[payload:]]
            del tasks[j][rel[payload] :]
    extra: list[list[int]] = [[] for _ in range(n)]
    for j in range(n):
        spare = payload - sum(t[0] != WAYPOINT for t in tasks[j])
        extra[j], over = over[: max(spare, 0)], over[max(spare, 0) :]
        if extra[j]:
            book.owner[extra[j]] = j
            tasks[j] += plan_targets(j, np.array(extra[j]), tasks[j][-1][2] if tasks[j] else starts[j], book)
    return book, tasks, extra


def piece_tasks(
    strategy: ReleaseStrategy,
    zone: Zone,
    pc: Piece,
    start: ArrayLike,
    altitude: float,
    speed: float,
    seed: int,
    fall: Any,
    wind: Any,
    rim_margin: float,
) -> list[tuple]:
    """Tasks ``(kind, -1, xy, aim, heading, zone)`` of one piece, planned by ``strategy.plan`` from ``start``.

    A teleport plan (not flyable) becomes hover releases over its targets (tour from ``start``); targets
    within ``rim_margin`` of the rim are pulled in (``rim_pull``), their release points moving with them (over
    flat ground the landing offset does not depend on where the release happens).
    """
    rng = np.random.default_rng([seed, pc.pid])
    plan = strategy.plan(
        zone.centre,
        zone.radial_profile(),
        zone.n_sensors,
        altitude,
        speed,
        rng,
        pc.sector,
        start,
        fall,
        wind,
    )
    if plan.mode == "teleport":
        tgt = plan.release_xy[plan_tour(plan.release_xy, start)]
        plan = assemble_plan(
            strategy.name,
            "hover",
            tgt,
            zone.centre,
            zone.radius,
            pc.sector,
            start,
            altitude,
            0.0,
            fall,
            wind,
            fall_dt=strategy.fall_dt,
        )
    kind = HOVER if plan.mode == "hover" else FLY
    shift = rim_pull(plan.release_xy, zone.centre, zone.radius, rim_margin)
    out: list[tuple] = []
    for w in range(plan.waypoints.shape[0]):
        rel = np.flatnonzero(plan.release_wp == w)
        if rel.size == 0:
            out.append((WAYPOINT, -1, plan.waypoints[w, :2], plan.waypoints[w, :2], 0.0, pc.zone))
        for i in rel:
            head = math.atan2(plan.release_vel[i, 1], plan.release_vel[i, 0])
            tgt, aim = plan.release_xy[i] + shift[i], plan.release_points[i, :2] + shift[i]
            out.append((kind, -1, tgt, aim, head, pc.zone))
    return out


def target_tasks(
    tids: NDArray[np.int64],
    start: ArrayLike,
    book: TargetBook,
    hover: bool,
    throw: Callable[[int, float], NDArray[np.float64]],
) -> list[tuple]:
    """Tasks for loose targets (overflow, reclaimed): an NN + 2-opt tour from ``start``, straight approaches.

    Args:
        tids: Target ids.
        start: Where the UAV starts.
        book: The targets.
        hover: Hover releases (else fly-through).
        throw: ``(zone, heading) -> (2,)`` landing offset of a release at the UAV's release speed and layer.
    """
    prev, out = np.asarray(start, dtype=np.float64), []
    for tid in tids[plan_tour(book.xy[tids], prev)]:
        tgt, k = book.xy[tid], int(book.zone[tid])
        head = math.atan2(tgt[1] - prev[1], tgt[0] - prev[0])
        out.append((HOVER if hover else FLY, int(tid), tgt, tgt - throw(k, head), head, k))
        prev = tgt
    return out


class MissionView:
    """What one UAV knows of the mission from its own inbox (plus the shared plan).

    Args:
        me: The viewer's UAV index.
        book: The shared targets.
        n_uavs: Fleet size.
        payload: Payload per UAV.
    """

    def __init__(self, me: int, book: TargetBook, n_uavs: int, payload: int) -> None:
        self.me, self.book = me, book
        self.owner = book.owner.copy()
        self.released_by = np.full(book.xy.shape[0], -1, dtype=np.int64)
        self.claimed_by = np.full(len(book.pieces), -1, dtype=np.int64)
        self.last_heard = np.zeros(n_uavs, dtype=np.int64)
        self.done = np.zeros(n_uavs, dtype=bool)
        self.left = np.full(n_uavs, payload, dtype=np.int64)
        self.reclaiming = np.zeros(n_uavs, dtype=bool)
        self.heard_kinds: set[int] = set()

    def hear(self, step: int, msg: dict[str, NDArray], i: int, lost_after: int) -> None:
        """Apply message ``i`` of a ``decode`` result received at ``step``."""
        kind, u = int(msg["kind"][i]), int(msg["uav"][i])
        if not 0 <= u < self.last_heard.size or u == self.me or kind not in MSG_NAMES:
            return
        self.heard_kinds.add(kind)
        self.last_heard[u] = step
        if kind in (MSG_HELLO, MSG_DONE):
            self.left[u] = msg["left"][i]
            if kind == MSG_DONE:
                self.done[u], self.reclaiming[u] = True, False
            return
        pid = int(msg["piece"][i])
        if not 0 <= pid < self.claimed_by.size:
            return
        if kind == MSG_CLAIM:
            self.done[u] = False
            if self.book.pieces[pid].uav == u:
                self.claimed_by[pid] = u
                return
        tid = self.book.find(pid, msg["xy"][i])
        if tid < 0:
            return
        if kind == MSG_RELEASED:
            self.released_by[tid] = u
            self.left[u] = max(self.left[u] - 1, 0)
        else:
            if self.is_lost(step, int(self.owner[tid]), lost_after):
                self.reclaiming[u] = True
            self.owner[tid] = u

    def is_lost(self, step: int, u: int, lost_after: int) -> bool:
        """Whether UAV ``u`` is silent for more than ``lost_after`` steps without having said DONE."""
        return u != self.me and not self.done[u] and step - self.last_heard[u] > lost_after

    def orphans(self, step: int, lost_after: int) -> NDArray[np.int64]:
        """Targets owned by lost UAVs and not announced RELEASED, in plan order."""
        lost = np.array([self.is_lost(step, u, lost_after) for u in range(self.done.size)])
        return np.flatnonzero(lost[self.owner] & (self.released_by < 0))

    def reclaim(self, step: int, lost_after: int, my_left: int) -> NDArray[np.int64]:
        """Orphans the viewer (idle, with ``my_left`` sensors) must take now; marks them as its own.

        Returns:
            Target ids in plan order (empty when another UAV has priority or nothing is orphaned).
        """
        if my_left <= 0:
            return np.zeros(0, dtype=np.int64)
        orphans = self.orphans(step, lost_after)
        if orphans.size == 0:
            return orphans
        n = self.done.size
        alive = np.array([u == self.me or step - self.last_heard[u] <= lost_after for u in range(n)])
        if np.any(alive & self.reclaiming & (np.arange(n) != self.me)):
            return np.zeros(0, dtype=np.int64)  # someone is still busy with a reclaim: wait for its DONE
        eligible = alive & (self.done | (np.arange(n) == self.me)) & (self.left > 0)
        eligible[self.me] = True
        if int(np.flatnonzero(eligible)[0]) != self.me:
            return np.zeros(0, dtype=np.int64)  # a lower-id UAV is free: it takes them
        take = orphans[:my_left]
        self.owner[take] = self.me
        self.reclaiming[self.me], self.done[self.me] = True, False
        return take
