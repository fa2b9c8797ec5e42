"""Autopilot mode of ``uav_release``: scripted sweep flight, so a policy only decides when to release.

With ``autopilot=True`` the scenario flies every UAV itself. The zones are covered by boustrophedon lanes
(parallel to x, ``autopilot_lane`` metres apart, clipped to each zone's disc; zones visited in nearest-first
order from the base); the lane length is split into ``n_agents`` pieces of equal length, one per UAV. A UAV
flies from the base to the start of its piece at ``max_speed`` ("transit"), then along it at
``autopilot_speed`` ("sweep"), slowing down before each corner, and hovers once its piece is done. The
altitude is held at ``autopilot_altitude``. With ``autopilot_offset=True`` the policy's ``motion[0]`` in [-1, 1]
shifts the waypoint a sweeping UAV flies to by up to half a lane spacing sideways (left of its flying direction
when positive), so it can move its releases between the lanes.

A release goes where the sensor is predicted to land: ``p + v * k + wind(z) * t_fall``, with ``k`` and
``t_fall`` calibrated once by the ballistic model (``payloads.ballistic.predict_landing``) at the sweep speed
and altitude, and the episode's mean wind. ``ClaimMap`` keeps, per world, the coverage lattice points already
claimed by a released sensor's predicted landing disc, so the predicted coverage gain of releasing now is the
importance of the unclaimed lattice points within ``r_s`` of the predicted landing point.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from agentsim_env.payloads import FallParams
from agentsim_env.payloads.ballistic import predict_landing
from agentsim_env.uav.tracking import DeploymentTracker
from agentsim_env.uav.zones import ZoneSet

if TYPE_CHECKING:
    from agentsim_env.sim import World
    from agentsim_env.uav.config import UavReleaseConfig

__all__ = ["ClaimMap", "SweepRoutes", "lane_segments", "throw_coefficients"]

LOOKAHEAD_M = 6.0
"""With lane offsets, how far ahead of its projection on its shifted leg a sweeping UAV aims (m)."""


def _zone_order(zones: ZoneSet, start: np.ndarray) -> list[int]:
    """Zone indices in nearest-first order from ``start``."""
    left = list(range(len(zones.zones)))
    centres = zones.centres()
    order, here = [], np.asarray(start, dtype=np.float64)
    while left:
        k = min(left, key=lambda i: float(np.hypot(*(centres[i] - here))))
        order.append(k)
        left.remove(k)
        here = centres[k]
    return order


def lane_segments(zones: ZoneSet, start: np.ndarray, spacing: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Boustrophedon lanes over every zone, in flying order.

    Args:
        zones: The hot zones.
        start: Where the fleet starts (the base).
        spacing: Distance between lanes in metres.

    Returns:
        ``(a, b)`` lane end points ``(2,)``, flown from ``a`` to ``b``.
    """
    out: list[tuple[np.ndarray, np.ndarray]] = []
    flip = False
    for k in _zone_order(zones, start):
        (cx, cy), r = zones.centres()[k], float(zones.radii()[k])
        n = max(int(np.floor(2 * r / spacing)), 1)
        offsets = (np.arange(n) - (n - 1) / 2) * spacing
        for dy in offsets:
            half = float(np.sqrt(max(r * r - dy * dy, 0.0)))
            a, b = np.array([cx - half, cy + dy]), np.array([cx + half, cy + dy])
            out.append((b, a) if flip else (a, b))
            flip = not flip
    return out


class SweepRoutes:
    """Per-UAV waypoint routes over equal shares of the lane length.

    Args:
        zones: The hot zones.
        start: The base.
        n_agents: UAVs per world.
        spacing: Lane spacing in metres.
    """

    def __init__(self, zones: ZoneSet, start: np.ndarray, n_agents: int, spacing: float) -> None:
        segs = lane_segments(zones, start, spacing)
        lengths = np.array([np.hypot(*(b - a)) for a, b in segs])
        cum = np.concatenate([[0.0], np.cumsum(lengths)])
        total = float(cum[-1])
        routes: list[np.ndarray] = []
        for j in range(n_agents):
            lo, hi = total * j / n_agents, total * (j + 1) / n_agents
            pts: list[np.ndarray] = []
            for i, (a, b) in enumerate(segs):
                s0, s1 = max(lo, cum[i]), min(hi, cum[i + 1])
                if s1 <= s0 or lengths[i] <= 0:
                    continue
                u = (b - a) / lengths[i]
                for p in (a + u * (s0 - cum[i]), a + u * (s1 - cum[i])):
                    if not pts or np.hypot(*(p - pts[-1])) > 1e-6:
                        pts.append(p)
            routes.append(np.array(pts) if pts else np.asarray(start, dtype=np.float64)[None, :].copy())
        self.n_wp = np.array([len(r) for r in routes], dtype=np.int64)
        self.points = np.zeros((n_agents, int(self.n_wp.max()), 2))
        self.cum = np.zeros((n_agents, int(self.n_wp.max())))  # path length from the first waypoint
        for j, r in enumerate(routes):
            self.points[j, : len(r)] = r
            self.points[j, len(r) :] = r[-1]
            c = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(r, axis=0), axis=1))])
            self.cum[j, : len(r)] = c
            self.cum[j, len(r) :] = c[-1]
        self.length = np.maximum(self.cum[:, -1], 1e-9)

    def command(
        self,
        agent: np.ndarray,
        pos: np.ndarray,
        wp: np.ndarray,
        speed: float,
        transit_speed: float,
        altitude: float,
        max_accel: float,
        max_speed: float,
        offset: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Velocity commands ``(S, 3)`` / ``max_speed`` and the advanced waypoint indices.

        ``wp`` is the index of the waypoint flown to (0: transit to the route's start); a slot whose
        ``wp`` is past its last waypoint hovers. ``offset`` ``(S,)`` m shifts a sweeping slot's leg (from
        waypoint ``wp - 1`` to ``wp``) sideways, to its left when positive, and the slot follows the shifted leg
        (``_pursue``); without it, the slot flies straight at its waypoint.
        """
        n = self.n_wp[agent]
        if offset is not None:
            return self._pursue(agent, pos, wp, n, offset, speed, transit_speed, altitude, max_accel, max_speed)
        done = wp >= n
        k = np.minimum(wp, n - 1)
        goal = self.points[agent, k]
        d = np.linalg.norm(goal - pos[:, :2], axis=1)
        wp = np.where(~done & (d < 1.5), wp + 1, wp)
        done = wp >= n
        k = np.minimum(wp, n - 1)
        goal = self.points[agent, k]
        delta = goal - pos[:, :2]
        d = np.linalg.norm(delta, axis=1)
        return self._velocity(delta, d, wp, done, pos, speed, transit_speed, altitude, max_accel, max_speed), wp

    @staticmethod
    def _velocity(
        delta: np.ndarray,
        stop: np.ndarray,
        wp: np.ndarray,
        done: np.ndarray,
        pos: np.ndarray,
        speed: float,
        transit_speed: float,
        altitude: float,
        max_accel: float,
        max_speed: float,
    ) -> np.ndarray:
        # towards ``delta`` at the sweep (or transit) speed, slowing to stop ``stop`` m ahead; altitude held
        v = np.where(wp == 0, transit_speed, speed)
        v = np.minimum(v, np.sqrt(2.0 * 0.8 * max_accel * np.maximum(stop, 0.0)))  # stop at the corner
        vxy = delta / np.maximum(np.linalg.norm(delta, axis=1), 1e-9)[:, None] * v[:, None]
        vxy[done] = 0.0
        vz = np.clip(altitude - pos[:, 2], -3.0, 3.0)
        cmd = np.column_stack([vxy, vz]) / max_speed
        return np.clip(cmd, -1.0, 1.0)

    def _legs(
        self, agent: np.ndarray, wp: np.ndarray, n: np.ndarray, offset: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each slot's leg (to waypoint ``wp``) shifted by ``offset`` to its left when sweeping: ``(start, unit
        direction, length, sweeping)``."""
        k = np.minimum(wp, n - 1)
        b = self.points[agent, k]
        a = self.points[agent, np.maximum(k - 1, 0)]
        leg = b - a
        length = np.linalg.norm(leg, axis=1)
        u = leg / np.maximum(length, 1e-9)[:, None]
        sweeping = (wp >= 1) & (wp < n) & (length > 1e-9)
        shift = np.where(sweeping, offset, 0.0)
        return a + np.column_stack([-u[:, 1], u[:, 0]]) * shift[:, None], u, length, sweeping

    def _pursue(
        self,
        agent: np.ndarray,
        pos: np.ndarray,
        wp: np.ndarray,
        n: np.ndarray,
        offset: np.ndarray,
        speed: float,
        transit_speed: float,
        altitude: float,
        max_accel: float,
        max_speed: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``command`` with lateral offsets: a sweeping slot follows its shifted leg (it aims ``LOOKAHEAD_M``
        ahead of its projection on it) and moves on once less than 1.5 m of the leg is left; transit as without."""
        xy = pos[:, :2]
        done = wp >= n
        start, u, length, sweeping = self._legs(agent, wp, n, offset)
        left = length - np.einsum("ij,ij->i", xy - start, u)
        d0 = np.linalg.norm(self.points[agent, np.minimum(wp, n - 1)] - xy, axis=1)
        arrived = np.where(sweeping, left < 1.5, d0 < 1.5)
        wp = np.where(~done & arrived, wp + 1, wp)
        done = wp >= n
        start, u, length, sweeping = self._legs(agent, wp, n, offset)
        along = np.einsum("ij,ij->i", xy - start, u)
        aim = start + u * np.clip(along + LOOKAHEAD_M, 0.0, length)[:, None]
        goal = self.points[agent, np.minimum(wp, n - 1)]
        delta = np.where(sweeping[:, None], aim - xy, goal - xy)
        stop = np.where(sweeping, length - along, np.linalg.norm(goal - xy, axis=1))
        return self._velocity(delta, stop, wp, done, pos, speed, transit_speed, altitude, max_accel, max_speed), wp

    def progress(self, agent: np.ndarray, pos: np.ndarray, wp: np.ndarray) -> np.ndarray:
        """Fraction of each UAV's route flown, in [0, 1] (0 during transit, 1 once done)."""
        n = self.n_wp[agent]
        k = np.clip(wp, 1, n - 1)
        ahead = np.linalg.norm(self.points[agent, k] - pos[:, :2], axis=1)
        flown = np.where(wp >= n, self.length[agent], np.clip(self.cum[agent, k] - ahead, 0.0, None))
        return np.where(wp == 0, 0.0, np.clip(flown / self.length[agent], 0.0, 1.0))


def throw_coefficients(fall: FallParams, speed: float, altitude: float) -> tuple[float, float]:
    """``(k, t_fall)``: a sensor released at ``speed`` from ``altitude`` lands ``speed * k`` ahead (still air)."""
    xy, t = predict_landing(np.array([0.0, 0.0, altitude]), np.array([max(speed, 1e-3), 0.0, 0.0]), fall)
    return float(xy[0, 0]) / max(speed, 1e-3), float(t[0])


class ClaimMap:
    """Per-world coverage lattice points claimed by released sensors' predicted landing discs.

    Args:
        tracker: The scenario's deployment tracker (lattice, importance ``phi``, ``r_s``).
        n_worlds: Number of worlds.
    """

    def __init__(self, tracker: DeploymentTracker, n_worlds: int) -> None:
        self.tracker = tracker
        self.claimed = np.zeros((n_worlds, tracker.phi.size), dtype=bool)
        self.predicted: dict[int, tuple[int, float]] = {}  # payload id -> (world, predicted gain), while it falls
        pts = tracker.grid.points
        # largest gain a single sensor can have: a whole disc at the most important place
        sums = [
            tracker.phi[h].sum()
            for h in tracker.grid.tree.query_ball_point(pts[:: max(len(pts) // 4000, 1)], tracker.r_s)
        ]
        self.max_gain = float(max(sums)) if sums else 1.0

    def reset_world(self, w: int) -> None:
        """Forget world ``w``'s claims."""
        self.claimed[w] = False
        self.predicted = {i: wg for i, wg in self.predicted.items() if wg[0] != w}

    def _hits(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(row, lattice index)`` pairs within ``r_s`` of each point."""
        hits = self.tracker.grid.tree.query_ball_point(xy, self.tracker.r_s)
        sizes = np.fromiter((len(h) for h in hits), dtype=np.int64, count=len(hits))
        idx = np.concatenate([np.asarray(h, dtype=np.int64) for h in hits]) if sizes.sum() else np.zeros(0, np.int64)
        return np.repeat(np.arange(len(hits)), sizes), idx

    def gain(self, world: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """Importance of the lattice points within ``r_s`` of ``xy`` (k, 2) that are neither claimed nor covered."""
        row, idx = self._hits(xy)
        if idx.size == 0:
            return np.zeros(xy.shape[0])
        w = world[row]
        free = ~(self.claimed[w, idx] | self.tracker.covered[w, idx])
        return np.bincount(row, weights=self.tracker.phi[idx] * free, minlength=xy.shape[0])

    def claim(self, world: np.ndarray, xy: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """Claim the discs around ``xy`` of new sensors ``ids`` in order; returns and remembers their gains."""
        out = np.zeros(xy.shape[0])
        for i in range(xy.shape[0]):
            out[i] = self.gain(world[i : i + 1], xy[i : i + 1])[0]
            row, idx = self._hits(xy[i : i + 1])
            self.claimed[int(world[i]), idx] = True
        self.predicted.update(zip(ids.tolist(), zip(world.tolist(), out.tolist())))
        return out

    def landed(self, ids: np.ndarray) -> np.ndarray:
        """The predicted gains of landed sensors (forgotten now)."""
        return np.array([self.predicted.pop(int(i), (0, 0.0))[1] for i in ids], dtype=np.float64)


class AutopilotMode:
    """The scenario side of autopilot mode: flight commands, release placement, shaping and the observation.

    Per-slot state lives in the scenario's slots (``wp``, ``route_done``, ``release_gain``); the claims and the
    predicted gain of each falling sensor (by payload id) live here, per world.

    Args:
        config: The scenario config (``UavReleaseConfig`` with ``autopilot=True``).
        zones: The hot zones.
        fall: The sensors' fall parameters.
    """

    def __init__(self, config: UavReleaseConfig, zones: ZoneSet, fall: FallParams) -> None:
        c = config
        base = np.asarray(zones.base if zones.base is not None else (10.0, 10.0), dtype=np.float64)
        self.c = c
        self.routes = SweepRoutes(zones, base, int(c.n_agents), float(c.autopilot_lane))
        self.k, self.t_fall = throw_coefficients(fall, float(c.autopilot_speed), float(c.autopilot_altitude))
        self.n_sensors = zones.n_sensors
        self.gain_scale = zones.n_sensors / 4.0  # 1 = four times the mean gain per sensor (coverage 1 / N)

    def landing(self, world: World) -> np.ndarray:
        """Predicted landing point ``(S, 2)`` of a sensor released now by each slot."""
        st = world.state
        xy = st.pos[:, :2] + st.vel[:, :2] * self.k
        assert world.payloads is not None
        wind = world.payloads.wind
        if wind is not None:
            xy = xy + wind.mean_velocity_at(st.pos[:, 2], st.world_id)[:, :2] * self.t_fall
        return xy

    def fly(self, world: World, wp: np.ndarray, lateral: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Velocity commands ``(S, 3)`` (/ ``max_speed``) and the advanced waypoint indices; ``lateral`` ``(S,)``
        in [-1, 1] offsets each sweeping UAV from its lane by ``lateral x autopilot_lane / 2`` m (to the left of
        its flying direction when positive)."""
        c, st = self.c, world.state
        offset = None if lateral is None else np.clip(lateral, -1.0, 1.0) * (float(c.autopilot_lane) / 2.0)
        agent = np.arange(st.n_slots) % int(c.n_agents)
        b = c.body
        return self.routes.command(
            agent,
            st.pos,
            wp,
            float(c.autopilot_speed),
            float(b.max_speed),
            float(c.autopilot_altitude),
            float(b.max_accel),
            float(b.max_speed),
            offset,
        )

    def progress(self, world: World, wp: np.ndarray) -> np.ndarray:
        """Fraction of each slot's piece swept ``(S,)``, in [0, 1]."""
        st = world.state
        return self.routes.progress(np.arange(st.n_slots) % int(self.c.n_agents), st.pos, wp)

    def on_route(self, wp: np.ndarray, n_slots: int) -> np.ndarray:
        """Slots sweeping their piece (releases are masked out in transit and once the piece is done)."""
        agent = np.arange(n_slots) % int(self.c.n_agents)
        return (wp >= 1) & (wp < self.routes.n_wp[agent])

    def shaping(self, world: World, t: Any) -> np.ndarray:
        """This step's autopilot reward terms per slot (scenario docstring); updates progress and sweeps done.

        Args:
            world: The world, after the step.
            t: Its task state (``payload_left``, ``released``, ``release_gain``, ``progress``, ``wp``,
                ``route_done``).

        Returns:
            ``w_coverage x predicted gain - c`` per release, minus the carrying cost ``c x d(left x progress)``.
        """
        c = self.c
        cost = c.w_coverage * c.release_cost / self.n_sensors
        out = c.w_coverage * t.release_gain - cost * t.released
        prog = self.progress(world, t.wp)
        out -= cost * (t.payload_left * prog - (t.payload_left + t.released) * t.progress)
        t.progress[:] = prog
        t.route_done |= ~self.on_route(t.wp, world.state.n_slots) & (t.wp > 0)
        return out

    def observe(
        self, world: World, claims: ClaimMap, wp: np.ndarray, payload_frac: np.ndarray, in_zone: np.ndarray
    ) -> np.ndarray:
        """The ``autopilot`` observation part ``(S, 4)``, in [-1, 1] (scenario docstring)."""
        st = world.state
        gain = claims.gain(st.world_id, self.landing(world))
        prog = self.progress(world, wp)
        out = np.column_stack(
            [
                gain * self.gain_scale * 2 - 1,
                prog * 2 - 1,
                np.where(in_zone, 1.0, -1.0),
                payload_frac - (1.0 - prog),
            ]
        )
        return np.clip(out, -1.0, 1.0).astype(np.float32)
