"""Configuration of the ``uav_release`` scenario (a frozen, validated dataclass).

Nested parts (``wind``, ``scatter``, ``wsn``, ``reward``, ``comms``) accept dicts of their fields; ``zones`` is a
zones JSON path, a dict in that format (``docs/zones.md``), a ``ZoneSet``, ``"tiny"``, or ``None`` / ``"default"``
for the shipped default file. The fleet's payload must hold every zone's sensors.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from agentsim_env.comms.stack import CommsConfig
from agentsim_env.core.world import PHYSICS_MODES
from agentsim_env.payloads import ScatterConfig, WindConfig
from agentsim_env.scenarios.config import build_config, check_choice, check_float, check_int
from agentsim_env.scenarios.rewards import RewardConfig
from agentsim_env.scenarios.uav_zones import ZoneSet, load_zones, validate_against_payload, zones_from_dict
from agentsim_env.wsn.evaluate import WsnConfig

_NESTED = {
    "wind": WindConfig,
    "scatter": ScatterConfig,
    "wsn": WsnConfig,
    "reward": RewardConfig,
    "comms": CommsConfig,
}


@dataclass(frozen=True)
class UavReleaseConfig:
    """Configuration of ``uav_release`` (validated; nested parts accept dicts of their fields)."""

    zones: Any = (
        None  # a zones JSON path, a dict in that format, a ZoneSet, "tiny", or None / "default" (shipped)
    )
    n_uavs: int = 4
    payload: int = 40
    sensor_mass: float = 0.05
    sensor_cd: float = 1.05
    sensor_area: float = 0.0025
    battery_j: float = 321_000.0
    max_speed: float = 15.0
    max_accel: float = 4.0
    altitude: tuple[float, float] = (5.0, 60.0)
    uav_radius: float = 0.6
    sensor_range: float = 20.0
    n_azimuth: int = 8
    elevations_deg: tuple[float, ...] = (0.0, -45.0)
    target_scale: float = 60.0
    grid_cells: int = 8
    grid_extent: float = 80.0
    action_mode: str = "velocity"
    physics: str = "kinematic"
    collisions: bool = True
    dt: float = 0.1
    max_steps: int = 6000
    wind: WindConfig = field(default_factory=lambda: WindConfig(mean_speed=2.0))
    scatter: ScatterConfig = field(default_factory=lambda: ScatterConfig(1.0, 0.05, 0.5))
    wsn: WsnConfig = field(default_factory=WsnConfig)
    reward: RewardConfig = field(
        default_factory=lambda: RewardConfig(collision_penalty=20.0, message_cost=0.001)
    )
    comms: CommsConfig = field(
        default_factory=lambda: CommsConfig(payload_dim=6, inbox_size=8, overlay_range=150.0)
    )
    w_coverage: float = 10.0
    w_fidelity: float = 1.0
    w_energy: float = 1.0
    w_miss: float = 0.1
    w_out: float = 1.0
    w_lcc: float = 5.0
    w_lifetime: float = 5.0

    def __post_init__(self) -> None:
        check_int("n_uavs", self.n_uavs, 1, 1024)
        check_int("payload", self.payload, 1)
        for name in (
            "sensor_mass",
            "sensor_cd",
            "sensor_area",
            "battery_j",
            "max_speed",
            "max_accel",
            "uav_radius",
            "sensor_range",
            "target_scale",
            "grid_extent",
            "dt",
        ):
            check_float(name, getattr(self, name), 0.0, lo_open=True)
        for name in ("w_coverage", "w_fidelity", "w_energy", "w_miss", "w_out", "w_lcc", "w_lifetime"):
            check_float(name, getattr(self, name), 0.0)
        check_int("n_azimuth", self.n_azimuth, 1, 1024)
        check_int("grid_cells", self.grid_cells, 1, 64)
        check_int("max_steps", self.max_steps, 1)
        check_choice("action_mode", self.action_mode, ("velocity", "primitive"))
        check_choice("physics", self.physics, PHYSICS_MODES)
        check_float("altitude[0]", self.altitude[0], 0.0)
        check_float("altitude[1]", self.altitude[1], self.altitude[0], lo_open=True)
        for name, cls in _NESTED.items():
            v = getattr(self, name)
            if isinstance(v, dict):
                object.__setattr__(self, name, build_config(cls, v))
            elif not isinstance(v, cls):
                raise ValueError(f"{name} must be a {cls.__name__} or a dict of its fields, got {v!r}")
        zs = self.zone_set()
        object.__setattr__(self, "zones", zs)
        validate_against_payload(zs, self.n_uavs, self.payload)

    def zone_set(self) -> ZoneSet:
        """The zones, loaded and validated."""
        z = self.zones
        if isinstance(z, ZoneSet):
            return z
        if isinstance(z, dict):
            return zones_from_dict(z)
        from agentsim_env.scenarios.uav_zones import default_zones_path, tiny_zones_path

        named = {None: default_zones_path, "default": default_zones_path, "tiny": tiny_zones_path}
        if z in named:
            return load_zones(named[z]())
        try:
            return load_zones(z)
        except OSError as exc:
            raise ValueError(f"zones: cannot read zones file {str(z)!r}: {exc.strerror or exc}") from None
