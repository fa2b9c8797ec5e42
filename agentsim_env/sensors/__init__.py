"""Sensors: the laser-scanner-like proximity sensor (vectorised ray casting with a per-slot range)."""

from agentsim_env.sensors.proximity import (
    HIT_AGENT,
    HIT_GROUND,
    HIT_NONE,
    HIT_OBJECT,
    ProximityConfig,
    ProximitySensor,
    ScanResult,
)

__all__ = [
    "HIT_AGENT",
    "HIT_GROUND",
    "HIT_NONE",
    "HIT_OBJECT",
    "ProximityConfig",
    "ProximitySensor",
    "ScanResult",
]
