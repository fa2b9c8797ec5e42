"""The world's geometry and stage switches (a frozen, validated dataclass)."""

from __future__ import annotations

import typing
from typing import Annotated, Literal

from pydantic import Field

from agentsim_env.core.config_model import Choice, FieldError, Flag, Int, Real, config

Physics = Annotated[Literal["kinematic", "pymunk"], Choice]
"""The physics modes (``"kinematic"``: motion only; ``"pymunk"``: planar contact resolution)."""
PHYSICS_MODES: tuple[str, ...] = typing.get_args(typing.get_args(Physics)[0])


@config()
class WorldConfig:
    """Geometry and pipeline switches of a world.

    Attributes:
        bounds: Map ``(xmin, xmax, ymin, ymax)`` in metres; agents are kept inside.
        z_range: Allowed altitude ``(zmin, zmax)``.
        dt: Step length in seconds.
        physics: ``"kinematic"`` (motion only) or ``"pymunk"`` (planar contact resolution).
        physics_substeps: Pymunk sub-steps per step.
        collisions: Whether distance-threshold collisions are detected (and end agents).
        collision_margin: Extra distance added to collision thresholds.
        collision_ends_agent: Whether a collision (or a pymunk contact) takes the agent offline; switch it off
            to let agents slide along walls under pymunk while still reporting contact events.
        grid_cell: Cell side of the neighbour grid (``None``: from the sensor range).
        max_waypoints: Waypoint capacity of path primitives.
    """

    bounds: tuple[Real, Real, Real, Real] = (0.0, 100.0, 0.0, 100.0)
    z_range: tuple[Real, Real] = (0.0, 50.0)
    dt: Annotated[Real, Field(gt=0)] = 0.1
    physics: Physics = "kinematic"
    physics_substeps: Annotated[Int, Field(ge=1)] = 4
    collisions: Flag = True
    collision_margin: Real = 0.0
    collision_ends_agent: Flag = True
    grid_cell: Annotated[Real, Field(gt=0.0)] | None = None
    max_waypoints: Int = 16

    def __post_init__(self) -> None:
        if not (self.bounds[1] > self.bounds[0] and self.bounds[3] > self.bounds[2]):
            raise FieldError(
                "bounds", f"must be (xmin, xmax, ymin, ymax) with xmin < xmax, ymin < ymax, got {self.bounds}"
            )
        if not self.z_range[1] > self.z_range[0]:
            raise FieldError("z_range", f"must be (zmin, zmax) with zmin < zmax, got {self.z_range}")
        # pymunk steps every world in one space, world w shifted by w * 1e5 m along x, and the world calls its
        # step without per-step input checks: keep the map well inside the +-5e4 m each world may use
        if self.physics == "pymunk" and max(abs(self.bounds[0]), abs(self.bounds[1])) >= 2.5e4:
            raise FieldError("bounds", f"x must lie within +-25000 m with physics='pymunk', got {self.bounds}")
