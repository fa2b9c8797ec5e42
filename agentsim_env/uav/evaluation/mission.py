"""Fly one ``uav_release`` mission with a policy and account for its costs (domain reference 2.5).

``fly_mission`` resets the env and the policy with the seed and steps until the mission ends: the episode
ends (payload empty and nothing falling, every UAV down, or ``max_steps``), or, for a policy with a
``mission_complete`` property or method (``ReleasePolicy``), as soon as it reports its work done and no
sensor is still falling. The fleet usually carries a few spare sensors, and hovering with them until
``max_steps`` would only add time and energy.

Per step, ``MissionLog`` adds up the 3D distance flown, UAV pairs closer than ``NEAR_MISS_M`` (once per
pair and mission), UAVs lost to collisions, and agent messages sent and dropped. UAVs take off 3 m apart,
so a pair only counts as a near miss once it has been at least ``NEAR_MISS_M`` apart and closes in again;
otherwise every mission would start with near misses at the base.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["MISSION_KEYS", "NEAR_MISS_M", "MissionLog", "fly_mission", "sensor_rows"]

#: Distance under which two flying UAVs count as a near miss, metres (3D).
NEAR_MISS_M = 5.0
#: Keys of ``fly_mission``'s result, in order.
MISSION_KEYS: tuple[str, ...] = (
    "completed",
    "steps",
    "mission_time_s",
    "energy_j",
    "energy_fraction",
    "path_length_m",
    "sensors_required",
    "payload_total",
    "sensors_released",
    "sensors_landed",
    "delivered_fraction",
    "messages_sent",
    "messages_dropped",
    "near_misses",
    "collisions",
)


class MissionLog:
    """Per-step accounting of one mission in world 0 of an env (``env.world``, ``env.scenario.n_agents``).

    Args:
        env: The env, just reset.
    """

    def __init__(self, env: Any) -> None:
        self.n = int(env.scenario.n_agents)
        st = env.world.state
        self.prev = st.pos[: self.n].copy()
        self.path = 0.0
        self.iu = np.triu_indices(self.n, k=1)
        d = np.linalg.norm(self.prev[self.iu[0]] - self.prev[self.iu[1]], axis=1)
        self.armed = d >= NEAR_MISS_M  # pairs that have been apart at least once
        self.near = np.zeros(self.iu[0].size, dtype=bool)
        self.on_prev = st.online[: self.n].copy()
        self.collisions = 0
        self.sent = 0
        self.dropped = 0

    def update(self, env: Any) -> None:
        """Account for the step just taken (positions, online flags and ``world.last_events``)."""
        from agentsim_env.comms.messages import AGENT, GROUP

        world = env.world
        st = world.state
        pos = st.pos[: self.n]
        self.path += float(np.linalg.norm(pos - self.prev, axis=1).sum())
        self.prev = pos.copy()
        i, j = self.iu
        d = np.linalg.norm(pos[i] - pos[j], axis=1)
        # pairs flying together at the start of the step (a pair that collided went offline during it)
        pair_on = self.on_prev[i] & self.on_prev[j]
        self.near |= (d < NEAR_MISS_M) & pair_on & self.armed
        self.armed |= (d >= NEAR_MISS_M) & pair_on
        self.on_prev = st.online[: self.n].copy()
        ev = world.last_events
        self.collisions += int(ev.went_offline.size)
        comm = ev.comms
        if comm is not None and comm.bus is not None:
            # agent traffic only: heartbeats and environment messages are the simulator's, not the fleet's
            for log, attr in ((comm.bus.sent, "sent"), (comm.bus.dropped, "dropped")):
                mine = (log.sender >= 0) & np.isin(log.kind, (AGENT, GROUP))
                setattr(self, attr, getattr(self, attr) + int(mine.sum()))
        if world.comms is not None:
            self.sent += int(world.comms.overlay.stats.started)


def _work_done(policy: Any) -> bool:
    """The policy's ``mission_complete`` (a property or a method); False when it has none."""
    flag = getattr(policy, "mission_complete", None)
    if callable(flag):
        flag = flag()
    return bool(flag) if flag is not None else False


def fly_mission(env: Any, policy: Any, seed: int) -> dict[str, float]:
    """Reset ``env`` and ``policy`` with ``seed`` and fly until the mission ends (module docstring).

    Args:
        env: A ``uav_release`` ParallelEnv (one world).
        policy: Acts on the live agents' observations.
        seed: Reset seed of both.

    Returns:
        The ``MISSION_KEYS`` values (floats); the env's payload set then holds the released sensors.
    """
    state: dict[str, Any] = {}

    def on_step(env: Any, step: int, view: Any) -> bool:
        if step == 0:  # right after the reset: the start positions
            state["log"], state["ps"] = MissionLog(env), env.world.payloads.objects
            return False
        state["log"].update(env)
        return bool(state["ps"].n_falling == 0 and _work_done(policy))

    # through env.rollout: the strategies still act on dicts (they plan over the whole fleet), but the env steps
    # on arrays; the episode ends by max_steps at the latest
    res = env.rollout(policy, env.scenario.max_steps, seed=seed, on_step=on_step)
    log, ps, steps = state["log"], state["ps"], res.steps
    work_done = bool(ps.n_falling == 0 and _work_done(policy)) if steps else False
    return mission_metrics(env, log, steps, work_done)


def mission_metrics(env: Any, log: MissionLog, steps: int, work_done: bool) -> dict[str, float]:
    """The ``MISSION_KEYS`` values of a mission flown for ``steps`` steps (``work_done``: it ended by itself)."""
    cfg = env.scenario.config
    ps = env.world.payloads.objects
    mine = ps.get("world") == 0
    landed = int(np.count_nonzero(ps.get("landed") & mine))
    needed = env.scenario.zones.n_sensors
    energy = float(env.world.state.energy[: log.n].sum())
    values = (
        float(work_done or steps < env.scenario.max_steps),
        steps,
        steps * float(cfg.dt),
        energy,
        energy / (cfg.n_uavs * cfg.battery_j),
        log.path,
        needed,
        cfg.n_uavs * cfg.payload,
        int(np.count_nonzero(mine)),
        landed,
        min(landed / needed, 1.0),
        log.sent,
        log.dropped,
        int(np.count_nonzero(log.near)),
        log.collisions,
    )
    return {k: float(v) for k, v in zip(MISSION_KEYS, values, strict=True)}


def sensor_rows(payloads: Any, head: dict[str, Any]) -> list[dict[str, Any]]:
    """The released sensors of world 0 as ``sensors.csv`` rows (domain reference 2.6), ``head`` first.

    The release position is the effective one (GNSS and timing errors included): where the sensor left the
    UAV. An unlanded sensor has NaN landing fields.

    Args:
        payloads: The scenario's ``PayloadSet``.
        head: Leading columns (``zones``, ``strategy``, ``seed``).

    Returns:
        One dict per sensor, in id order.
    """
    a = payloads.as_dict()
    rel, vel = a["release_pos"], a["release_vel"]
    cols = {
        "sensor_id": a["id"],
        "uav_id": a["owner"],
        "zone_id": a["zone"],
        "t_release": a["release_t"],
        "x_rel": rel[:, 0],
        "y_rel": rel[:, 1],
        "z_rel": rel[:, 2],
        "vx_rel": vel[:, 0],
        "vy_rel": vel[:, 1],
        "x_target": a["target_xy"][:, 0],
        "y_target": a["target_xy"][:, 1],
        "x_land": a["land_xy"][:, 0],
        "y_land": a["land_xy"][:, 1],
        "t_land": a["land_t"],
    }
    return [{**head, **{k: v[i].item() for k, v in cols.items()}} for i in np.flatnonzero(a["world"] == 0)]
