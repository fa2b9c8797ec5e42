"""Configuration of the ``uav_release`` scenario (a frozen, validated dataclass).

Nested parts (``body``, ``sensing``, ``wind``, ``scatter``, ``wsn``, ``reward``, ``comms``) accept dicts of the
fields to change from this scenario's defaults; ``zones`` is a
zones JSON path, a dict in that format (``docs/zones.md``), a ``ZoneSet``, ``"tiny"``, or ``None`` / ``"default"``
for the shipped default file. The fleet's payload must hold every zone's sensors.
"""

from __future__ import annotations

import math
import os
from dataclasses import field
from typing import Annotated, Any, ClassVar

from pydantic import Field

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.config_model import Flag, Int, Real, config, in_range
from agentsim_env.core.validation import check_text, short_repr
from agentsim_env.payloads import ScatterConfig, WindConfig
from agentsim_env.scenarios.config import BodyConfig, ScenarioConfig, SensingConfig
from agentsim_env.scenarios.rewards import RewardConfig
from agentsim_env.uav.wsn.evaluate import WsnConfig
from agentsim_env.uav.zones import ZoneSet, load_zones, validate_against_payload, zones_from_dict

ZONES_ACCEPTED = (
    "a zones JSON path (str or Path), a dict in the zones format (docs/zones.md), a ZoneSet, 'tiny', 'default' or None"
)
"""What the ``zones`` field accepts (named in its errors)."""


Weight = Annotated[Real, Field(ge=0.0, le=1e6)]
"""A reward weight, 0..1e6."""


@config()
class UavReleaseConfig(ScenarioConfig):
    """Configuration of ``uav_release`` (validated; nested parts accept dicts of their fields).

    The fleet size is ``n_agents``, 1..1,024 (``n_uavs`` is accepted as an alias key and readable as a property).
    Ranges: ``payload`` 1..100,000 sensors per UAV; ``sensor_mass`` 1e-4..100 kg; ``sensor_cd`` 0.01..10;
    ``sensor_area`` 1e-6..10 m^2, with the sensors' terminal fall speed ``sqrt(2 m g / (rho cd A))`` at least
    1 m/s; ``battery_j`` 1..1e9 J; ``target_scale`` 1e-3..1e6; ``grid_extent`` 1..1e5 m; ``grid_cells``
    1..64; reward weights ``w_*`` 0..1e6; with ``physics="pymunk"`` the zones' map at most 20 km.

    Autopilot mode (``autopilot=True``, see ``uav_autopilot`` and the scenario docstring): the scenario flies a
    sweep at ``autopilot_speed`` m/s (0.5..``body.max_speed``) and ``autopilot_altitude`` m (inside
    ``body.altitude``) over lanes ``autopilot_lane`` m apart (1..1e4); ``release_cost`` (0..100, in units of the mean
    weighted coverage per required sensor, ``1 / zones.n_sensors``) is the shaping baseline of a release;
    ``autopilot_offset`` (bool) lets the policy's ``motion[0]`` offset each UAV sideways from its lane by up to half
    a lane spacing. These fields do nothing when ``autopilot`` is off.
    """

    nested: ClassVar[dict[str, type]] = {
        **ScenarioConfig.nested,
        "wind": WindConfig,
        "scatter": ScatterConfig,
        "wsn": WsnConfig,
    }
    aliases: ClassVar[dict[str, str]] = {"n_uavs": "n_agents"}

    zones: Any = None  # a zones JSON path, a dict in that format, a ZoneSet, "tiny", or None / "default" (shipped)
    n_agents: Annotated[Int, Field(ge=1, le=1024)] = 4
    payload: Annotated[Int, Field(ge=1, le=100_000)] = 40
    # the physical fields' ranges: outside them the physics and rewards overflow
    sensor_mass: Annotated[Real, Field(ge=1e-4, le=100.0)] = 0.05  # kg
    sensor_cd: Annotated[Real, Field(ge=0.01, le=10.0)] = 1.05
    sensor_area: Annotated[Real, Field(ge=1e-6, le=10.0)] = 0.0025  # m^2
    battery_j: Annotated[Real, Field(ge=1.0, le=1e9)] = 321_000.0  # J
    target_scale: Annotated[Real, Field(ge=1e-3, le=1e6)] = 60.0
    grid_cells: Annotated[Int, Field(ge=1, le=64)] = 8
    grid_extent: Annotated[Real, Field(ge=1.0, le=1e5)] = 80.0  # m
    max_steps: Annotated[Int, Field(ge=1, le=10**9)] = 6000
    body: BodyConfig = field(
        default_factory=lambda: BodyConfig(radius=0.6, max_speed=15.0, max_accel=4.0, altitude=(5.0, 60.0))
    )
    sensing: SensingConfig = field(
        default_factory=lambda: SensingConfig(range=20.0, n_azimuth=8, elevations_deg=(0.0, -45.0))
    )
    wind: WindConfig = field(default_factory=lambda: WindConfig(mean_speed=2.0))
    scatter: ScatterConfig = field(default_factory=lambda: ScatterConfig(1.0, 0.05, 0.5))
    wsn: WsnConfig = field(default_factory=WsnConfig)
    reward: RewardConfig = field(default_factory=lambda: RewardConfig(collision_penalty=20.0, message_cost=0.001))
    comms: CommsConfig | None = field(
        default_factory=lambda: CommsConfig(payload_dim=6, inbox_size=8, overlay_range=150.0)
    )
    w_coverage: Weight = 10.0
    w_fidelity: Weight = 1.0
    w_energy: Weight = 1.0
    w_miss: Weight = 0.1
    w_out: Weight = 1.0
    w_lcc: Weight = 5.0
    w_lifetime: Weight = 5.0
    autopilot: Flag = False
    autopilot_speed: Real = 8.0  # 0.5..body.max_speed
    autopilot_altitude: Real = 10.0  # inside body.altitude
    autopilot_lane: Annotated[Real, Field(ge=1.0, le=1e4)] = 16.0
    release_cost: Annotated[Real, Field(ge=0.0, le=100.0)] = 1.0
    autopilot_offset: Flag = False

    def __post_init__(self) -> None:
        in_range("autopilot_speed", self.autopilot_speed, 0.5, self.body.max_speed)
        in_range("autopilot_altitude", self.autopilot_altitude, *self.body.altitude)
        v_t = math.sqrt(2.0 * self.sensor_mass * 9.81 / (1.225 * self.sensor_cd * self.sensor_area))
        if v_t < 1.0:
            raise ValueError(
                f"sensor_mass, sensor_cd and sensor_area give a terminal fall speed of {v_t:.3g} m/s; it must be "
                "at least 1 m/s (sqrt(2 m g / (rho cd A)) >= 1) or sensors drift for minutes: raise sensor_mass "
                "or lower sensor_cd or sensor_area"
            )
        zs = self.zone_set()
        object.__setattr__(self, "zones", zs)
        if self.physics == "pymunk" and max(zs.map_size) > 2e4:
            raise ValueError(f"zones: map_size {list(zs.map_size)} is over 20000 m, the limit with physics='pymunk'")
        validate_against_payload(zs, self.n_agents, self.payload)

    @property
    def n_uavs(self) -> int:
        """UAVs per world (the same as ``n_agents``)."""
        return int(self.n_agents)

    def zone_set(self) -> ZoneSet:
        """The zones, loaded and validated."""
        z = self.zones
        if isinstance(z, ZoneSet):
            return z
        if isinstance(z, dict):
            return zones_from_dict(z)
        from agentsim_env.uav.zones import default_zones_path, tiny_zones_path

        if isinstance(z, (list, tuple)):
            raise ValueError(
                f"zones: a bare list of zones is not accepted; give a dict in the zones format, "
                f"{{'map_size': [width, height], 'zones': [...]}} (docs/zones.md), or {ZONES_ACCEPTED}"
            )
        if not (z is None or isinstance(z, (str, os.PathLike))):
            raise ValueError(f"zones must be {ZONES_ACCEPTED}; got {type(z).__name__} {short_repr(z)}")
        if isinstance(z, str) and not z.strip():
            raise ValueError(f"zones must be {ZONES_ACCEPTED}; got an empty string")
        if z is not None:
            check_text("zones", os.fsdecode(z))  # a path is echoed in messages: no terminal escapes
        named = {None: default_zones_path, "default": default_zones_path, "tiny": tiny_zones_path}
        if z is None or z in named:
            return load_zones(named[z]())
        try:
            return load_zones(z)
        except OSError as exc:
            raise ValueError(
                f"zones: cannot read zones file {str(z)!r}: {exc.strerror or exc} (zones must be {ZONES_ACCEPTED})"
            ) from None
