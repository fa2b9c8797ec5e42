"""The physics stage of the pipeline (stage 3): pymunk resolves horizontal contacts; altitude stays with motion.

``PhysicsStage`` turns motion's horizontal displacement of the step into a commanded velocity, lets pymunk move
every online slot from the step's start position (sliding along walls, pushing other agents) and writes the
result back into the state. Contacts become collision events like the distance-threshold ones. The pymunk
backend is built lazily (pymunk is imported only by ``physics.pymunk_backend``) and rebuilt when the scene
changed other than by appending objects, which also drops pymunk's hidden contact state so that a reset episode
replays exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from agentsim_env.core.collisions import CollisionEvents
from agentsim_env.core.pipeline import StepContext
from agentsim_env.core.scene import Scene
from agentsim_env.core.state import AgentState


class PhysicsStage:
    """Planar contact resolution for B worlds with pymunk.

    Args:
        substeps: Pymunk sub-steps per step.
        report_contacts: Whether contacts are reported as collision events.
    """

    name = "physics"

    def __init__(self, substeps: int = 4, report_contacts: bool = True) -> None:
        self.substeps = int(substeps)
        self.report_contacts = report_contacts
        self.backend: Any = None
        self._version = -1

    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """Nothing per world: a reset's new scene rebuilds the backend at the world's ``refresh``."""
        del w, rng

    def sync(self, state: AgentState, scene: Scene) -> Any:
        """The backend for the current scene (objects appended: extended in place; otherwise rebuilt)."""
        from agentsim_env.physics.pymunk_backend import PymunkPlanarBackend

        if self.backend is None or self._version != scene.version:
            be = self.backend
            if be is None or not be.extend_obstacles(scene.kind, scene.centre, scene.half, scene.world):
                self.backend = PymunkPlanarBackend(
                    state.radius,
                    state.world_id,
                    state.n_worlds,
                    scene.kind,
                    scene.centre,
                    scene.half,
                    scene.world,
                    substeps=self.substeps,
                )
            self._version = scene.version
        return self.backend

    def step(self, ctx: StepContext) -> CollisionEvents:
        """Stage 3: move x, y from the step's start with pymunk (motion's ``start_xy``); contacts as events."""
        st = ctx.state
        start = ctx.outputs["motion"].start_xy
        # motion's horizontal displacement becomes the commanded velocity; pymunk moves x, y from the step's
        # start and writes the online rows' x, y and vx, vy back in place (the new z stays)
        desired = st.pos[:, :2] - start
        desired /= ctx.dt
        st.pos[:, :2] = start
        contacts = self.sync(st, ctx.scene).step_unchecked(st.pos, desired, st.online, ctx.dt, st.pos, st.vel)
        if self.report_contacts and len(contacts.agent):
            return CollisionEvents(contacts.agent, contacts.other_agent, contacts.obj)
        return CollisionEvents.empty()
