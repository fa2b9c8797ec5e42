"""The world's geometry and stage switches (a frozen, validated dataclass)."""

from __future__ import annotations

from dataclasses import dataclass

from agentsim_env.core.validation import check_choice, check_float, check_int, coerce_fields

PHYSICS_MODES = ("kinematic", "pymunk")


@dataclass(frozen=True)
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

    bounds: tuple[float, float, float, float] = (0.0, 100.0, 0.0, 100.0)
    z_range: tuple[float, float] = (0.0, 50.0)
    dt: float = 0.1
    physics: str = "kinematic"
    physics_substeps: int = 4
    collisions: bool = True
    collision_margin: float = 0.0
    collision_ends_agent: bool = True
    grid_cell: float | None = None
    max_waypoints: int = 16

    def __post_init__(self) -> None:
        coerce_fields(self, "")
        check_choice("physics", self.physics, PHYSICS_MODES)
        if not self.dt > 0:
            raise ValueError(f"dt must be > 0, got {self.dt}")
        check_int("physics_substeps", self.physics_substeps, 1)
        if len(self.bounds) != 4 or not (self.bounds[1] > self.bounds[0] and self.bounds[3] > self.bounds[2]):
            raise ValueError(
                f"bounds must be (xmin, xmax, ymin, ymax) with xmin < xmax, ymin < ymax, got {self.bounds}"
            )
        if len(self.z_range) != 2 or not self.z_range[1] > self.z_range[0]:
            raise ValueError(f"z_range must be (zmin, zmax) with zmin < zmax, got {self.z_range}")
        if self.grid_cell is not None:
            check_float("grid_cell", self.grid_cell, 0.0, lo_open=True)
        # pymunk steps every world in one space, world w shifted by w * 1e5 m along x, and the world calls its
        # step without per-step input checks: keep the map well inside the +-5e4 m each world may use
        if self.physics == "pymunk" and max(abs(self.bounds[0]), abs(self.bounds[1])) >= 2.5e4:
            raise ValueError(f"bounds x must lie within +-25000 m with physics='pymunk', got {self.bounds}")
