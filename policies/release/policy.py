"""Scripted release strategies B0-B8 flying the ``uav_release`` scenario, with sector coordination.

``ReleasePolicy`` plans every UAV's work at the first ``act`` after ``reset`` (start positions come from
that observation), then flies it. Fixed mission parameters are read from ``env.scenario``: zones, fleet
size and payload, the sensors' fall parameters (``scenario.fall``), altitude band, ``dt``,
``target_scale``, ``max_speed``, ``max_accel`` and the mean wind ``scenario.wind.mean`` with its height
profile: the wind *forecast* a real mission would have (gusts are unknown and not compensated). The UAV's
own state comes from its observation (``self`` part, ``(lo, hi)`` the altitude band)::

    x = (s[0] + 1) / 2 * width     y = (s[1] + 1) / 2 * height     z = lo + (s[2] + 1) / 2 * (hi - lo)
    velocity = s[3:6] * max_speed  payload left = round(s[8] * payload)

Planning (``coordination.split_work`` / ``plan_mission``): each UAV plans its pieces with the strategy's
``plan`` (wedge, the zone's full ``N``, release speed, mean-wind compensation) from where the previous one
ended, working at its layer (``ReleaseStrategy.layer_altitudes``: by default ``h_jk = clip(zone altitude (or
default_altitude) + j * layer_spacing, lo, hi)``). Targets within ``rim_margin`` of a rim are pulled in (the
release point moves with them). A teleport plan (B8, not flyable) is flown as hover releases over its targets
(B8 at ``lo + j * layer_spacing``); the true zero-error oracle is evaluated separately by placing the points.

Altitude: a UAV climbs in place at take-off, flies between zones at its transit layer (above every working
layer), changes altitude only outside zones it is not working, and enters its zone slowly until it is at
its layer; idle UAVs hold position.

Guidance (vectorised over UAVs). Tables of the landing offset ``throw(speed, heading)`` per release
altitude give the predicted landing point ``L = p + throw(v)`` of a sensor released now. Fly-through:
the heading ``psi`` solves ``T - throw(s, psi) - p || e_psi`` (flying straight at release speed ``s``
lands on target ``T``), the speed ramps down to ``s``, and the sensor goes at the closest approach of ``L``
to ``T`` when within ``release_tol`` (and level at the layer). A target passed without a release gets a
lead-in point on its planned approach line (after 3 tries any closest approach is accepted). Hover: stop
over ``T - throw(0)``, release when slow and ``|L - T| <= 0.5`` m. The release action carries the intended
landing offset ``(T - p) / target_scale``. A release is announced (RELEASED) once the next observation
shows the payload count dropped.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from agentsim_env.payloads.ballistic import predict_landing
from agentsim_env.policies.release.coordination import (
    FLY,
    HOVER,
    IDLE,
    MSG_CLAIM,
    MSG_DONE,
    MSG_HELLO,
    MSG_RELEASED,
    PAYLOAD_DIM,
    WAYPOINT,
    MissionView,
    Piece,
    TargetBook,
    decode,
    encode,
    piece_tasks,
    plan_mission,
    split_work,
    target_tasks,
)
from agentsim_env.policies.release.registry import make_strategy
from agentsim_env.policies.release.strategy import ReleaseStrategy

__all__ = ["ReleasePolicy"]
_N_SPEED, _N_HEAD = 31, 36  # throw table grid: 0.5 m/s and 10 degree steps (linear interpolation)
_HOVER_TOL, _ARRIVE, _MAX_RETRIES, _BRAKE = 0.5, 1.5, 3, 0.6  # m, m, count, fraction of max_accel
_VZ = 4.0  # largest climb / descent rate commanded, m/s


def _throw_tables(alts: np.ndarray, vmax: float, fall: Any, wind: Any) -> np.ndarray:
    """Landing offsets ``(A, _N_SPEED, _N_HEAD, 2)`` of a level release at each altitude, speed, heading."""
    a, s, h = np.meshgrid(
        alts, np.linspace(0.0, vmax, _N_SPEED), 2 * np.pi * np.arange(_N_HEAD) / _N_HEAD, indexing="ij"
    )
    p0 = np.stack([np.zeros(a.size), np.zeros(a.size), a.ravel()], axis=1)
    v0 = np.stack([(s * np.cos(h)).ravel(), (s * np.sin(h)).ravel(), np.zeros(a.size)], axis=1)
    xy, _ = predict_landing(p0, v0, fall, wind, dt=0.02)
    return xy.reshape(*a.shape, 2)


def _forecast(wind: Any) -> Any:
    """Mean wind of world 0 as a fast ``z (n,) -> (n, 3)`` callable (``None`` in still air)."""
    mean = np.asarray(wind.mean[0], dtype=np.float64).copy()
    if not np.any(mean):
        return None
    factor = wind.config.profile_factor

    def at(z: np.ndarray) -> np.ndarray:
        out = np.zeros((np.shape(z)[0], 3))
        out[:, :2] = np.asarray(factor(z))[:, None] * mean[None, :]
        return out

    return at


class ReleasePolicy:
    """A registered release strategy flown by every UAV of a ``uav_release`` env (Dict observations).

    Args:
        env: A ``uav_release`` ParallelEnv (``action_mode="velocity"``, dict observations).
        strategy: A registered strategy name (``registry.strategy_names()``).
        cruise_speed: Transit speed in m/s (capped at the scenario's ``max_speed``).
        release_speed: Speed at fly-through releases; ``None``: the strategy's ``release_speed``.
        coordinate: Exchange CLAIM/RELEASED/DONE/HELLO messages and reclaim lost UAVs' work (``None``: when the
            env has comms; ``True`` without comms is an error).
        options: Strategy options (fields of the strategy class; ``fall_dt`` defaults to 0.02 s here).
        hello_every: Steps of silence after which a UAV sends a heartbeat.
        lost_after: Steps of silence (without DONE) after which a UAV is considered lost.
        release_tol: Largest predicted landing miss (m) accepted at a fly-through release.
        default_altitude: Release altitude of zones without one (m).
        layer_spacing: Altitude step between UAV layers (m).
        rim_margin: Targets closer than this to their zone's rim are pulled in radially to it (m; at most
            half the radius), so that the landing scatter keeps them inside.

    Attributes:
        strategy: The strategy's registered name.
        release_strategy: The strategy with its options.
        book: Every planned target (``TargetBook``), set at the first ``act`` of an episode.
        mission_complete: Every live UAV is idle and (coordinating) knows every other one is done or lost;
            evaluation loops stop there (the scenario itself runs on while spare sensors are on board).
    """

    def __init__(
        self,
        env: Any,
        strategy: str = "B5_cvt",
        *,
        cruise_speed: float = 12.0,
        release_speed: float | None = None,
        coordinate: bool | None = None,
        options: dict | None = None,
        hello_every: int = 10,
        lost_after: int = 50,
        release_tol: float = 1.0,
        default_altitude: float = 15.0,
        layer_spacing: float = 2.0,
        rim_margin: float = 1.0,
    ) -> None:
        # RK4 at 0.02 s: sub-millimetre, half the cost
        plan_with: ReleaseStrategy = make_strategy(strategy, **{"fall_dt": 0.02, **(options or {})})
        sc = env.scenario
        if getattr(sc, "name", None) != "uav_release":
            raise ValueError(f"env must be a 'uav_release' env, got scenario {getattr(sc, 'name', None)!r}")
        c = sc.config
        if c.action_mode != "velocity":
            raise ValueError(f"action_mode must be 'velocity' for ReleasePolicy, got {c.action_mode!r}")
        checks = (
            ("cruise_speed", cruise_speed, True),
            ("release_tol", release_tol, True),
            ("default_altitude", default_altitude, True),
            ("layer_spacing", layer_spacing, False),
            ("rim_margin", rim_margin, False),
        )
        for name, v, strict in checks:
            if not (math.isfinite(v) and (v > 0 if strict else v >= 0)):
                raise ValueError(f"{name} must be a finite number {'>' if strict else '>='} 0, got {v!r}")
        if release_speed is not None and not (math.isfinite(release_speed) and 0 <= release_speed <= c.body.max_speed):
            raise ValueError(
                f"release_speed must be None or in [0, max_speed = {c.body.max_speed}], got {release_speed!r}"
            )
        for name, v in (("hello_every", hello_every), ("lost_after", lost_after)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if getattr(c, "autopilot", False):
            raise ValueError(
                "ReleasePolicy flies the UAVs itself: it needs autopilot=False (with autopilot the "
                "scenario flies them and only the release is decided)"
            )
        if coordinate is None:
            coordinate = c.comms is not None
        if coordinate and c.comms is None:
            raise ValueError("coordinate=True needs comms (the env was built with comms=None)")
        if coordinate and c.comms.payload_dim < PAYLOAD_DIM:
            raise ValueError(
                f"comms.payload_dim must be >= {PAYLOAD_DIM} with coordinate=True, got {c.comms.payload_dim}"
            )
        self.env, self.coordinate = env, bool(coordinate)
        self.strategy, self.release_strategy = plan_with.name, plan_with
        self.cruise = min(float(cruise_speed), c.body.max_speed)
        speed = plan_with.release_speed if release_speed is None else float(release_speed)
        self.hover = speed == 0.0 or plan_with.hovers
        self.release_speed = 0.0 if self.hover else speed
        self.hello_every, self.lost_after, self.tol = hello_every, lost_after, float(release_tol)
        self.default_altitude, self.layer = float(default_altitude), float(layer_spacing)
        self.rim_margin = float(rim_margin)
        self._index = {a: i for i, a in enumerate(env.possible_agents)}
        self._seed, self._planned = 0, False

    @classmethod
    def for_env(cls, env: Any, strategy: str = "B5_cvt", **kw: Any) -> ReleasePolicy:
        """The policy for ``env`` (registry entry point)."""
        return cls(env, strategy, **kw)

    def reset(self, seed: int | None = None) -> None:
        """Start a new episode: plans are rebuilt at the next ``act`` (``seed`` drives B0, B1, B6, B7)."""
        self._seed, self._planned = (0 if seed is None else int(seed)), False

    # ------------------------------------------------------------------ planning
    def _plan(self, slots: np.ndarray, pos: np.ndarray) -> None:
        sc = self.env.scenario
        c, zs = sc.config, sc.zones
        n, k = c.n_uavs, len(zs.zones)
        self._n, self._payload, self._map = n, c.payload, zs.map_size
        self._dt, self._vmax, self._brake = c.dt, c.body.max_speed, _BRAKE * c.body.max_accel
        lo, hi = c.body.altitude
        start = np.tile(np.asarray(zs.base if zs.base is not None else (10.0, 10.0)), (n, 1))
        start[slots] = pos[:, :2]
        zone_alt = np.array([z.altitude or self.default_altitude for z in zs.zones])
        self._alts = self.release_strategy.layer_altitudes(zone_alt, n, self.layer, (lo, hi))
        # transit layers above every working layer, one per UAV
        self._transit = np.clip(self._alts.max() + self.layer * (1 + np.arange(n)), lo, hi)
        self._zc, self._zr = zs.centres(), zs.radii()
        self._wind = _forecast(self.env.world.payloads.wind)
        uniq, inv = np.unique(self._alts, return_inverse=True)
        self._tabs = _throw_tables(uniq, self._vmax, sc.fall, self._wind)
        self._tab_of = inv.reshape(n, k)
        pieces = split_work(zs, n, c.payload)
        self._queue: list[deque] = [deque() for _ in range(n)]
        self.book, self._tasks, extra = plan_mission(pieces, start, c.payload, self._piece_tasks, self._target_tasks)
        if self.coordinate:
            for pc in pieces:  # claim every piece (at its first target), then the overflow targets taken
                first = next(
                    (t[2] for t in self._tasks[pc.uav] if t[0] != WAYPOINT and self.book.piece[t[1]] == pc.pid),
                    start[pc.uav],
                )
                self._queue[pc.uav].append(encode(MSG_CLAIM, pc.uav, first, self._map, zone=pc.zone, piece=pc.pid))
            for j, tids in enumerate(extra):
                self._claim(j, tids)
        self._views = [MissionView(j, self.book, n, c.payload) for j in range(n)]
        self._ti = np.zeros(n, dtype=np.int64)
        self._kind = np.zeros(n, dtype=np.int64)
        self._goal, self._aim, self._lead, self._hold = (np.zeros((n, 2)) for _ in range(4))
        self._head, self._psi, self._alt = np.zeros(n), np.zeros(n), np.full(n, lo)
        self._tab, self._zone = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        self._has_lead, self._airborne, self._idle = (np.zeros(n, dtype=bool) for _ in range(3))
        self._retries, self._last_sent = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        self._left = np.full(n, c.payload, dtype=np.int64)
        self._pending = np.full(n, -1, dtype=np.int64)  # target released last step, to confirm and announce
        self._hold[:] = start
        self._step, self._planned = 0, True
        for j in range(n):
            self._load(j, np.append(start[j], lo))

    def _piece_tasks(self, pc: Piece, start: np.ndarray) -> list[tuple]:
        z = self.env.scenario.zones.zones[pc.zone]
        return piece_tasks(
            self.release_strategy,
            z,
            pc,
            start,
            float(self._alts[pc.uav, pc.zone]),
            self.release_speed,
            self._seed,
            self.env.scenario.fall,
            self._wind,
            self.rim_margin,
        )

    def _target_tasks(self, j: int, tids: np.ndarray, start: np.ndarray, book: TargetBook) -> list[tuple]:
        def throw(k: int, head: float) -> np.ndarray:
            return self._throw(np.array([self._tab_of[j, k]]), np.array([self.release_speed]), np.array([head]))[0]

        return target_tasks(tids, start, book, self.hover, throw)

    def _claim(self, j: int, tids: list[int] | np.ndarray) -> None:
        for tid in tids:
            b = self.book
            self._queue[j].append(
                encode(MSG_CLAIM, j, b.xy[tid], self._map, zone=int(b.zone[tid]), piece=int(b.piece[tid]))
            )

    def _load(self, j: int, pos: np.ndarray) -> None:
        """Make UAV ``j``'s next task current (or make it idle, announcing DONE)."""
        self._has_lead[j], self._retries[j] = False, 0
        tasks, owner = self._tasks[j], self._views[j].owner
        while self._ti[j] < len(tasks) and tasks[self._ti[j]][1] >= 0 and owner[tasks[self._ti[j]][1]] != j:
            self._ti[j] += 1  # another UAV claimed this target (it took us for lost): leave it to that UAV
        if self._ti[j] >= len(tasks):
            if not self._idle[j]:
                self._idle[j], self._kind[j] = True, IDLE
                self._hold[j] = pos[:2]
                if self.coordinate:
                    self._queue[j].append(self._status(j, MSG_DONE, pos))
            return
        kind, _, xy, aim, head, zone = self._tasks[j][self._ti[j]]
        self._idle[j], self._kind[j] = False, kind
        self._goal[j], self._aim[j], self._head[j], self._psi[j] = xy, aim, head, head
        self._alt[j], self._zone[j] = self._alts[j, zone], zone
        self._tab[j] = self._tab_of[j, zone]

    def _status(self, j: int, kind: int, pos: np.ndarray) -> np.ndarray:
        return encode(kind, j, pos[:2], self._map, payload_frac=self._left[j] / self._payload)

    # ------------------------------------------------------------------ acting
    def _throw(self, tab: np.ndarray, speed: np.ndarray, psi: np.ndarray) -> np.ndarray:
        """Bilinear lookup of the landing offset ``(m, 2)`` in the tables ``tab`` (per row)."""
        fs = np.clip(speed / self._vmax * (_N_SPEED - 1), 0.0, _N_SPEED - 1 - 1e-9)
        i0 = fs.astype(np.int64)
        w = (fs - i0)[:, None]
        fh = np.mod(psi, 2 * np.pi) / (2 * np.pi) * _N_HEAD
        j0 = np.floor(fh).astype(np.int64) % _N_HEAD
        u = (fh - np.floor(fh))[:, None]
        j1 = (j0 + 1) % _N_HEAD
        t = self._tabs
        return (1 - w) * ((1 - u) * t[tab, i0, j0] + u * t[tab, i0, j1]) + w * (
            (1 - u) * t[tab, i0 + 1, j0] + u * t[tab, i0 + 1, j1]
        )

    def act(self, observations: dict[str, Any]) -> dict[str, Any]:
        """Motion, release and comm actions for every UAV present in ``observations``."""
        if not observations:
            return {}
        names = list(observations)
        if not all(isinstance(observations[a], dict) for a in names):
            raise ValueError("observations must be Dict observations (make the env with obs_format='dict')")
        c = self.env.scenario.config
        slots = np.array([self._index[a] for a in names])
        s = np.stack([observations[a]["self"] for a in names]).astype(np.float64)
        (w, h), (lo, hi) = self.env.scenario.zones.map_size, c.body.altitude
        pos = np.column_stack([(s[:, 0] + 1) / 2 * w, (s[:, 1] + 1) / 2 * h, lo + (s[:, 2] + 1) / 2 * (hi - lo)])
        vel = s[:, 3:6] * c.body.max_speed
        if not self._planned:
            self._plan(slots, pos)
        left = np.rint(s[:, 8] * c.payload).astype(np.int64)
        for q in np.flatnonzero(self._pending[slots] >= 0):
            j, tid = int(slots[q]), int(self._pending[slots[q]])
            if left[q] <= self._left[j]:  # the release happened (an offline UAV releases nothing)
                self._views[j].released_by[tid] = j
                if self.coordinate:
                    b = self.book
                    self._queue[j].append(
                        encode(
                            MSG_RELEASED,
                            j,
                            b.xy[tid],
                            self._map,
                            zone=int(b.zone[tid]),
                            piece=int(b.piece[tid]),
                        )
                    )
            self._pending[j] = -1
        self._left[slots] = left
        if self.coordinate:
            self._read_inboxes(slots, [observations[a] for a in names])
            for i in range(slots.size):
                self._maybe_reclaim(int(slots[i]), pos[i])
        motion, release = self._guide(slots, pos, vel)
        comm = self._comm(slots, pos)
        self._step += 1
        out = {}
        for i, a in enumerate(names):
            out[a] = {"motion": motion[i], "release": release[i]}
            if comm is not None:
                out[a]["comm"] = comm[i]
        return out

    def _read_inboxes(self, slots: np.ndarray, obs: list[dict[str, np.ndarray]]) -> None:
        """Apply the GROUP messages received in the last step: the newest ``received`` rows, oldest first."""
        if any("inbox" not in o or "comms" not in o for o in obs):
            raise ValueError("coordinate=True needs the 'inbox' and 'comms' observation parts")
        inbox = np.stack([o["inbox"] for o in obs])
        got = np.array([o["comms"][0] for o in obs], dtype=np.float64)
        m = inbox.shape[1]
        new = np.where(got >= 1.0 - 1e-6, m, np.rint(got * m)).astype(np.int64)
        fresh = (np.arange(m)[None, :] < new[:, None]) & (inbox[:, :, 0] > 0.5) & (inbox[:, :, 2] > 0.5)
        who, row = np.nonzero(fresh)  # valid GROUP rows that arrived in the last step
        if who.size == 0:
            return
        order = np.lexsort((-row, who))
        who, row = who[order], row[order]
        msg = decode(inbox[who, row, 11 : 11 + PAYLOAD_DIM], self._map, self._payload)
        for q in range(who.size):
            self._views[slots[who[q]]].hear(self._step, msg, q, self.lost_after)

    def _maybe_reclaim(self, j: int, pos: np.ndarray) -> None:
        """An idle UAV with payload takes lost UAVs' remaining targets when it has priority."""
        if not self._idle[j] or self._left[j] <= 0:
            return
        take = self._views[j].reclaim(self._step, self.lost_after, int(self._left[j]))
        if take.size:
            self._tasks[j] += self._target_tasks(j, take, pos[:2], self.book)
            self._claim(j, take)
            self._load(j, pos)

    def _guide(self, slots: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Velocity commands and release decisions of the present UAVs (vectorised)."""
        c = self.env.scenario.config
        m = slots.size
        for i in np.flatnonzero((self._left[slots] <= 0) & ~self._idle[slots]):  # nothing left to release
            self._ti[slots[i]] = len(self._tasks[slots[i]])
            self._load(int(slots[i]), pos[i])
        kind, goal, tab = self._kind[slots], self._goal[slots], self._tab[slots]
        p, vxy = pos[:, :2], vel[:, :2]
        spd = np.hypot(vxy[:, 0], vxy[:, 1])
        land = p + self._throw(tab, spd, np.arctan2(vxy[:, 1], vxy[:, 0]))
        miss = land - goal
        dist = np.hypot(miss[:, 0], miss[:, 1])
        dz, hold_z, slow = self._altitude(slots, pos, kind == IDLE)
        level = (np.abs(dz) < 0.5) & (np.abs(vel[:, 2]) < 0.5)
        cmd = np.zeros((m, 3))
        cmd[:, 2] = np.where(hold_z, 0.0, np.clip(dz, -_VZ, _VZ))
        s = np.full(m, self.release_speed)
        # fly-through: heading that lands on the target when flown straight at s (warm-started fixed point)
        fly = (kind == FLY) & ~self._has_lead[slots]
        psi = self._psi[slots]
        for _ in range(2):
            th = self._throw(tab, s, psi)
            e = np.column_stack([np.cos(psi), np.sin(psi)])
            aim = goal - p - (th - np.sum(th * e, axis=1, keepdims=True) * e)
            psi = np.where(fly, np.arctan2(aim[:, 1], aim[:, 0]), psi)
        self._psi[slots] = psi
        e = np.column_stack([np.cos(psi), np.sin(psi)])
        leg = np.sum((goal - p - self._throw(tab, s, psi)) * e, axis=1)
        passing = np.sum(miss * vxy, axis=1) >= -0.5 * spd**2 * self._dt
        tol = np.where(self._retries[slots] >= _MAX_RETRIES, np.inf, self.tol)
        rel_fly = fly & level & passing & (dist <= tol)
        need_lead = fly & ~rel_fly & (leg < -max(0.5, 2 * self.release_speed * self._dt))
        mag = np.minimum(self.cruise, np.sqrt(s**2 + 2 * self._brake * np.maximum(leg, 0.0)))
        cmd[fly, :2] = e[fly] * mag[fly, None]
        # waypoints and lead-in points: arrive slowly, then go on
        way = (kind == WAYPOINT) | ((kind == FLY) & self._has_lead[slots])
        wpt = np.where(self._has_lead[slots, None], self._lead[slots], goal)
        d = wpt - p
        dd = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        v_arr = min(self.release_speed, 2.0) if self.release_speed > 0 else 1.0
        mag = np.minimum(self.cruise, np.sqrt(v_arr**2 + 2 * self._brake * dd))
        cmd[way, :2] = (d / dd[:, None] * mag[:, None])[way]
        reached = way & (dd < _ARRIVE)
        # hover: stop over the drift-compensated point, release when slow and on target
        hov = kind == HOVER
        d = self._aim[slots] - p
        dd = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        mag = np.minimum.reduce([np.full(m, self.cruise), np.sqrt(2 * self._brake * dd), 1.5 * dd])
        cmd[hov, :2] = (d / dd[:, None] * mag[:, None])[hov]
        rel_hov = hov & level & (spd < 0.25) & (dist <= _HOVER_TOL)
        idle = kind == IDLE
        cmd[idle, :2] = np.clip(self._hold[slots] - p, -2.0, 2.0)[idle]
        # take-off: climb before moving sideways (UAVs start side by side at the same height)
        self._airborne[slots] |= np.abs(dz) < 1.0
        cmd[~self._airborne[slots], :2] = 0.0
        sxy = np.maximum(np.hypot(cmd[:, 0], cmd[:, 1]), 1e-9)
        cmd[slow, :2] *= np.minimum(1.0, 2.0 / sxy[slow])[:, None]
        release = np.zeros((m, 3))
        release[:, 0] = -1.0
        fire = (rel_fly | rel_hov) & (self._left[slots] > 0)
        release[fire, 0] = 1.0
        release[fire, 1:] = np.clip((goal[fire] - p[fire]) / c.target_scale, -1.0, 1.0)
        for i in np.flatnonzero(fire | reached | need_lead):
            self._event(int(slots[i]), pos[i], bool(fire[i]), bool(reached[i]))
        return (cmd / c.body.max_speed).astype(np.float32), release.astype(np.float32)

    def _altitude(self, slots: np.ndarray, pos: np.ndarray, idle: np.ndarray) -> tuple[np.ndarray, ...]:
        """Altitude error, hold-altitude mask and slow-down mask of the present UAVs.

        Layers keep UAVs apart only while each stays on its own: a UAV works at its layer within ``R + 30``
        m of its task's zone centre, flies between zones at its transit layer (above every working layer),
        never changes altitude over a zone it is not working (another UAV's layer may be there), and moves
        sideways at 2 m/s at most inside its zone until it is at its layer. Idle UAVs hold position.
        """
        p = pos[:, :2]
        r = np.hypot(*(p[:, None, :] - self._zc[None, :, :]).transpose(2, 0, 1))  # (m, K)
        zone = self._zone[slots]
        own = r[np.arange(slots.size), zone] - self._zr[zone]
        # start the descent early enough to be at the layer before the rim, at cruise speed
        near = (own <= 30.0 + self.cruise * np.abs(self._transit[slots] - self._alt[slots]) / _VZ) | idle
        alt = np.where(near, self._alt[slots], self._transit[slots])
        foreign = np.any(r <= self._zr[None, :] + 5.0, axis=1) & ~near
        dz = alt - pos[:, 2]
        hold_z = foreign
        slow = (own <= 5.0) & (np.abs(dz) > 1.0) & ~idle
        return dz, hold_z, slow

    def _event(self, j: int, pos: np.ndarray, fired: bool, reached: bool) -> None:
        """Advance UAV ``j`` after a release, a waypoint or a missed target."""
        if fired:  # announced once the next observation shows the payload count dropped
            self._pending[j] = self._tasks[j][self._ti[j]][1]
            self._left[j] -= 1
        elif reached and self._has_lead[j]:
            self._has_lead[j] = False
            return
        elif not reached:  # missed: come back along the planned approach line
            s = np.array([self.release_speed])
            th = self._throw(self._tab[j : j + 1], s, self._head[j : j + 1])[0]
            back = float(np.clip(self.release_speed**2 / (2 * self._brake), 10.0, 40.0))
            lead = self._goal[j] - th - back * np.array([math.cos(self._head[j]), math.sin(self._head[j])])
            self._lead[j] = np.clip(lead, 5.0, np.asarray(self._map) - 5.0)  # stay inside the map
            self._has_lead[j] = True
            self._retries[j] += 1
            return
        self._ti[j] += 1
        self._load(j, pos)

    def _comm(self, slots: np.ndarray, pos: np.ndarray) -> np.ndarray | None:
        """One message per UAV and step: the queue first, else a heartbeat when quiet for ``hello_every``."""
        cfg = self.env.scenario.config.comms
        if cfg is None:
            return None
        out = np.zeros((slots.size, 3 + cfg.payload_dim), dtype=np.float32)
        out[:, 0] = -1.0  # channel "none"
        if not self.coordinate:
            return out
        for i, j in enumerate(slots):
            q = self._queue[j]
            if not q and self._step - self._last_sent[j] >= self.hello_every:
                q.append(self._status(j, MSG_DONE if self._idle[j] else MSG_HELLO, pos[i]))
            if q:
                out[i, 0] = -0.4  # channel "group"
                out[i, 3 : 3 + PAYLOAD_DIM] = q.popleft()
                self._last_sent[j] = self._step
        return out

    @property
    def mission_complete(self) -> bool:
        """Every UAV still flying is idle and (coordinating) knows every other UAV is done or lost."""
        if not self._planned:
            return False
        live = np.array([self._index[a] for a in self.env.agents], dtype=np.int64)
        if not np.all(self._idle[live]):
            return False
        if not self.coordinate:
            return True
        return all(
            self._views[j].done[u] or self._views[j].is_lost(self._step, u, self.lost_after)
            for j in live
            for u in range(self._n)
            if u != j
        )
