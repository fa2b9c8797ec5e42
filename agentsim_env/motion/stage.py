"""The motion stage of the pipeline (stage 2): the centralised movement worker.

``MotionStage`` owns the per-slot motion-primitive parameters (``MotionState``) and integrates every online
slot's primitive in one kernel. Stage 1 (the scenario) writes the primitives with the decoders of
``motion.actions``; a world reset puts the world's slots on hold.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

import numpy as np

from agentsim_env.core.pipeline import StepContext
from agentsim_env.core.threads import RowThreads
from agentsim_env.motion.integrate import integrate, integrate_unchecked
from agentsim_env.motion.primitives import set_hold
from agentsim_env.motion.state import MotionState


@dataclass(frozen=True, slots=True)
class MotionEvents:
    """What stage 2 reports: the horizontal positions before it moved (when ``keep_start`` is on)."""

    start_xy: np.ndarray | None


class MotionStage:
    """Motion primitives of every slot of B worlds of N agents.

    Args:
        n_worlds: Worlds B.
        n_agents: Agents per world N.
        max_waypoints: Waypoint capacity of path primitives.
        keep_start: Report the horizontal positions before each step (the physics stage needs them).
    """

    name = "motion"

    def __init__(self, n_worlds: int, n_agents: int, max_waypoints: int = 16, keep_start: bool = False) -> None:
        self.n_agents = int(n_agents)
        self.state = MotionState.create(int(n_worlds) * self.n_agents, max_waypoints)
        self.keep_start = keep_start
        self._checked: tuple[object, ...] = ()  # the arrays and dt the last validated call was given
        self.threads = RowThreads(1)
        """Row ranges for the integration (``World.set_num_threads``); the motion does not depend on them."""

    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """Every slot of world ``w`` holds its position until stage 1 commands otherwise."""
        del rng  # motion draws nothing
        set_hold(self.state, np.arange(w * self.n_agents, (w + 1) * self.n_agents))

    def step(self, ctx: StepContext) -> MotionEvents:
        """Stage 2: integrate every online slot's primitive over ``dt`` (writes pos, vel, heading)."""
        st = ctx.state
        start = st.pos[:, :2].copy() if self.keep_start else None
        args = (self.state, st.pos, st.vel, st.heading, st.max_speed, st.max_accel, st.online)
        seen = self._checked
        if len(seen) == 8 and seen[7] == ctx.dt and all(map(operator.is_, args, seen)):
            integrate_unchecked(*args, float(ctx.dt), self.threads)
        else:  # new arrays (or a new dt): checked once
            integrate(*args, ctx.dt)
            self._checked = (*args, ctx.dt)
        return MotionEvents(start)
