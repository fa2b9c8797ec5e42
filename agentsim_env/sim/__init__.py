"""The simulation layer: the ``World`` that owns the state, the scene and the subsystems and runs the pipeline."""

from agentsim_env.sim.config import PHYSICS_MODES, WorldConfig
from agentsim_env.sim.world import StepEvents, StepHook, StepScores, World

__all__ = ["PHYSICS_MODES", "StepEvents", "StepHook", "StepScores", "World", "WorldConfig"]
