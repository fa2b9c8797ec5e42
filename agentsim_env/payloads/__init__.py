"""Objects agents release (sensor nodes): ballistic fall with quadratic drag and wind, and landing."""

from agentsim_env.payloads.ballistic import (
    FallParams,
    compensated_release_xy,
    fall_time_vertical_drag,
    predict_landing,
    vacuum_landing,
)
from agentsim_env.payloads.payload_set import PAYLOAD_FIELDS, PayloadSet, ScatterConfig
from agentsim_env.payloads.wind import WIND_PROFILES, WindConfig, WindModel

__all__ = [
    "PAYLOAD_FIELDS",
    "WIND_PROFILES",
    "FallParams",
    "PayloadSet",
    "ScatterConfig",
    "WindConfig",
    "WindModel",
    "compensated_release_xy",
    "fall_time_vertical_drag",
    "predict_landing",
    "vacuum_landing",
]
