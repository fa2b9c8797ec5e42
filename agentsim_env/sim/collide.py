"""The collisions stage of the pipeline (stage 5): distance-threshold agent-agent and agent-object events."""

from __future__ import annotations

import numpy as np

from agentsim_env.core.collisions import CollisionEvents, find_collisions
from agentsim_env.core.pipeline import StepContext
from agentsim_env.core.threads import RowThreads


class CollisionStage:
    """Finds every contact on the step's grid; the world takes the hit agents offline (when configured).

    Args:
        enabled: Whether collisions are detected at all.
        margin: Extra distance added to every threshold.
    """

    name = "collisions"

    def __init__(self, enabled: bool = True, margin: float = 0.0) -> None:
        self.enabled = enabled
        self.margin = float(margin)
        self.threads = RowThreads(1)
        """Row ranges for the kernels (``World.set_num_threads``); the events do not depend on them."""

    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """Collisions keep no per-world state."""
        del w, rng

    def step(self, ctx: StepContext) -> CollisionEvents:
        """Stage 5: collision events of the online slots (who, the other agent or the object)."""
        if not self.enabled:
            return CollisionEvents.empty()
        st, sc = ctx.state, ctx.scene
        return find_collisions(
            st.pos,
            st.radius,
            st.online,
            st.world_id,
            ctx.grid,
            sc.kind,
            sc.centre,
            sc.half,
            sc.world,
            ctx.object_grid,
            self.margin,
            self.threads,
        )
