"""The Scenario contract: what a scenario file provides to the environment.

A scenario is one small file: a frozen config dataclass and a ``Scenario`` subclass that builds the world,
resets one world, decodes actions, observes, and scores. Observation and action *parts* are declared once
(name -> shape and bounds); the environment turns them into Dict spaces or one flat Box (parts concatenated in
declaration order), so every scenario gets both modes for free.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from agentsim_env.core.world import StepEvents, World


@dataclass(frozen=True)
class Part:
    """One named part of an observation or action: a float32 box of fixed shape and finite bounds."""

    shape: tuple[int, ...]
    low: float
    high: float

    @property
    def size(self) -> int:
        """Number of scalars in the part."""
        return int(np.prod(self.shape))


@dataclass(slots=True)
class StepResult:
    """What the scenario computes after the world stepped (arrays over slots).

    Attributes:
        rewards: Reward per slot ``(S,)``.
        terminated: Slots whose episode ended this step (goal reached, collision, dead battery...) ``(S,)``.
        info: Per-slot scalar arrays copied into each agent's info dict.
    """

    rewards: np.ndarray
    terminated: np.ndarray
    info: dict[str, np.ndarray]


class Scenario(ABC):
    """Base class of all scenarios.

    Subclasses set ``name``, ``config_cls`` and ``version`` and implement the abstract methods. A scenario may
    hold per-slot arrays of its own (goals, payloads...), allocated in ``build`` for ``n_worlds`` worlds.
    """

    name: ClassVar[str]
    config_cls: ClassVar[type]
    version: ClassVar[int] = 0
    agent_prefix: ClassVar[str] = "agent"
    #: Configs the conformance suite runs (each also in flat obs/action format); keep them small and fast.
    test_configs: ClassVar[tuple[dict[str, Any], ...]] = ({},)

    def __init__(self, config: Any) -> None:
        self.config = config

    # -- sizes -------------------------------------------------------------------------------------------
    @property
    @abstractmethod
    def n_agents(self) -> int:
        """Agents per world."""

    @property
    def max_steps(self) -> int:
        """Steps after which every live agent is truncated."""
        return int(self.config.max_steps)

    @property
    def n_groups(self) -> int:
        """Groups per world (1 when the scenario has no groups)."""
        return int(getattr(self.config, "n_groups", 1))

    def agent_names(self) -> list[str]:
        """Agent ids of one world, in slot order."""
        return [f"{self.agent_prefix}_{i}" for i in range(self.n_agents)]

    # -- lifecycle ---------------------------------------------------------------------------------------
    @abstractmethod
    def build(self, n_worlds: int) -> World:
        """Create the world (state, scene, subsystems) for ``n_worlds`` worlds and allocate scenario arrays."""

    @abstractmethod
    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        """Start a new episode in world ``w``: place agents, goals, obstacles; set motion primitives."""

    # -- spaces ------------------------------------------------------------------------------------------
    @abstractmethod
    def obs_parts(self) -> dict[str, Part]:
        """Observation parts in layout order."""

    @abstractmethod
    def act_parts(self) -> dict[str, Part]:
        """Action parts in layout order (each a box in [-1, 1])."""

    def state_size(self) -> int:
        """Length of the global state vector of one world."""
        return self.n_agents * 8

    # -- step --------------------------------------------------------------------------------------------
    @abstractmethod
    def apply_actions(self, world: World, actions: dict[str, np.ndarray], acting: np.ndarray) -> None:
        """Stage 1: decode actions ``{part: (S, size)}`` for the acting slots into motion commands."""

    def before_world_step(self, world: World) -> None:  # noqa: B027 - an optional hook
        """Hook run right before ``World.step`` (after actions are applied)."""

    @abstractmethod
    def after_world_step(self, world: World, events: StepEvents, acting: np.ndarray) -> StepResult:
        """Stages after the world pipeline: scenario subsystems, rewards and terminations."""

    @abstractmethod
    def observe(self, world: World) -> dict[str, np.ndarray]:
        """Observation parts ``{part: (S, *shape) float32}`` for every slot (clipped to the part bounds)."""

    def markers(self, world: World, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Scenario markers for the renderer: ``(xy (m, 2), rgb (m, 3) uint8, radius (m,))`` or ``None``."""
        return None

    # -- communication (shared by every scenario whose config has ``comms`` settings) ---------------------
    def comms_config(self) -> Any:
        """The scenario's ``CommsConfig`` or None (no bus, overlay, groups controller or inbox)."""
        return getattr(self.config, "comms", None)

    def comm_obs_parts(self) -> dict[str, Part]:
        """``inbox (M, F)`` (newest first; layout in ``comms.messages``) and ``comms (2,)`` counters."""
        cfg = self.comms_config()
        if cfg is None:
            return {}
        # payloads are in [-1, 1] when agents send them; environment messages carry ids (see comms.messages)
        return {"inbox": Part((cfg.inbox_size, cfg.features), -1e4, 1e4), "comms": Part((2,), 0.0, 1.0)}

    def comm_act_parts(self) -> dict[str, Part]:
        """``comm (3 + D,)``: channel, named receiver, hop limit, payload (layout in ``comms.stack``)."""
        cfg = self.comms_config()
        return {} if cfg is None else {"comm": Part((cfg.action_dim,), -1.0, 1.0)}

    def comm_observe(self, world: World) -> dict[str, np.ndarray]:
        """The inbox and counters of every slot, clipped to the part bounds."""
        if world.comms is None:
            return {}
        inbox, stats = world.comms.observe(world.state.pos, max(world.tick - 1, 0))
        return {"inbox": np.clip(inbox, -1e4, 1e4, out=inbox), "comms": stats}

    def state(self, world: World, w: int) -> np.ndarray:
        """Global state of world ``w`` for centralised critics: per agent pos, vel, online flag, group."""
        st = world.state
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        per = np.column_stack(
            [st.pos[sl] / 100.0, st.vel[sl] / 10.0, st.online[sl].astype(np.float64), st.group[sl] / 10.0]
        )
        return np.clip(per.ravel(), -10.0, 10.0).astype(np.float32)


def run_step(
    scenario: Scenario, world: World, parts: dict[str, np.ndarray], acting: np.ndarray
) -> tuple[StepResult, np.ndarray]:
    """One step of the pipeline (DESIGN §4) shared by every env front end.

    Stage 1 decodes the validated action parts of the acting slots (motion, scenario parts, ``comm``), stages
    2-8 run in ``World.step``, stage 9 is the scenario's scoring; slots that ended leave the simulation.

    Returns:
        The scenario's result and the mask of slots that terminated this step.
    """
    scenario.apply_actions(world, parts, acting)
    if "comm" in parts:
        world.apply_comm(parts["comm"], acting)
    scenario.before_world_step(world)
    events = world.step()
    res = scenario.after_world_step(world, events, acting)
    terminated = acting & (res.terminated | ~world.state.online)
    world.set_offline(np.flatnonzero(terminated))
    return res, terminated
