"""The contracts of the step pipeline: the step context, the subsystem and sensor protocols, random streams.

Every stage of ``sim.World.step`` (motion, physics, payloads, collisions, groups, comms, sensors) is a
*subsystem*: an object built for B worlds that implements two methods,

- ``reset_world(w, rng)``: world ``w`` starts a new episode; ``rng`` is that subsystem's own generator for the
  episode (spawned from the world's ``SeedSequence`` by the subsystem's name, see :func:`stream`);
- ``step(ctx) -> events``: advance every world by one step, reading what it needs from the
  :class:`StepContext` and returning what happened as arrays.

A subsystem never calls back into the world or into another subsystem: it returns events and the world acts on
them (takes slots offline, hands one stage's events to the next through the context). A *sensor* is a
subsystem of stage 8 whose ``step`` returns a reading, plus an optional observation part that scenarios get
for free (see :class:`Sensor`).

These contracts live in ``core`` so that the subsystem packages can implement them without importing ``sim``.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from agentsim_env.core.collisions import CollisionEvents
from agentsim_env.core.scene import Scene
from agentsim_env.core.spatial import Grid
from agentsim_env.core.state import AgentState
from agentsim_env.core.validation import is_int, short_repr


@dataclass(slots=True)
class StepContext:
    """What a stage of one step may read (the world fills it in as the stages run).

    Attributes:
        state: The agents' struct of arrays (stages may write the fields they own, e.g. motion writes ``pos``).
        scene: Static objects.
        grid: The step's neighbour grid over the online slots (rebuilt after collisions and timeouts).
        object_grid: The static objects' grid (``None`` when the scene is empty).
        dt: Step length in seconds.
        tick: Global step counter (message timestamps); never reset per world.
        step_count: ``(B,)`` steps since each world's reset, before this step.
        collisions: Stage 5's collision events (empty before stage 5).
        outputs: Events of the stages that already ran this step, by subsystem name.
        fresh: Outside a step, after a reset: the worlds that were reset (the others did not move). A sensor
            with noise draws only for these, so a world's stream never depends on another world's resets.
        own: ``(S,)`` bool, the slots this process steps (a shard's own agents; its other online slots are
            ghosts, copies of agents stepped elsewhere), or ``None`` when it steps every slot.
    """

    state: AgentState
    scene: Scene
    grid: Grid
    object_grid: Grid | None
    dt: float
    tick: int
    step_count: np.ndarray
    collisions: CollisionEvents = field(default_factory=CollisionEvents.empty)
    outputs: dict[str, Any] = field(default_factory=dict)
    fresh: np.ndarray | None = None
    own: np.ndarray | None = None


@runtime_checkable
class Subsystem(Protocol):
    """One stage of the pipeline, built for B worlds (see the module docstring)."""

    name: str

    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """World ``w`` starts a new episode; ``rng`` is this subsystem's generator for it."""

    def step(self, ctx: StepContext) -> Any:
        """Advance every world by one step and return the step's events."""


@dataclass(frozen=True)
class Part:
    """One named part of an observation or action: a float32 box of fixed shape and finite bounds."""

    shape: tuple[int, ...]
    low: float
    high: float

    @property
    def size(self) -> int:
        """Number of scalars in the part."""
        return int(math.prod(self.shape))


@runtime_checkable
class Sensor(Subsystem, Protocol):
    """A stage-8 subsystem: ``step(ctx)`` measures every online slot on the step's shared grid.

    ``obs_part`` is ``None`` for a sensor whose part the scenario places among its own (the proximity scan: it
    declares ``lidar`` and writes it, the scenario puts it between ``self`` and ``task``); otherwise the
    scenario base adds ``observe(reading)`` (``(S, *obs_part.shape)`` float32, inside the bounds) to every
    observation under the sensor's ``name``.
    """

    @property
    def obs_part(self) -> Part | None:
        """The observation part this sensor adds, or ``None``."""

    def observe(self, reading: Any) -> np.ndarray:
        """The reading as an observation part ``(S, *obs_part.shape)`` float32."""


@runtime_checkable
class StepBridge(Protocol):
    """The exchanges of a world that steps part of a larger one (a shard; ``distributed.shard``).

    ``World.step`` calls it between stages; a world stepped on its own has none (``world.bridge is None``).
    """

    own: np.ndarray
    """``(S,)`` bool: the slots this world steps (its other online slots are ghosts)."""

    def after_motion(self, world: Any, ctx: StepContext) -> None:
        """After stages 2-4: hand over the agents that left, take in arrivals and this step's ghosts."""

    def after_offline(self, world: Any, ctx: StepContext, went: np.ndarray) -> np.ndarray:
        """After stages 5-6: share the own slots that went offline (``went``); the ghosts that did elsewhere."""

    def combine(self, partials: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The scenario's per-group partial sums over every shard."""


def stream(seed: np.random.SeedSequence, name: str) -> np.random.Generator:
    """The generator named ``name`` of one world episode's ``SeedSequence``.

    Children are keyed by name (not by spawn order), so adding a subsystem never shifts another's numbers, and
    the same seed gives the same streams in a single env and in any world of a batch.

    Args:
        seed: The world's episode seed sequence.
        name: Stream name (``"placement"``, ``"comms"``, ``"payloads"``, ...).

    Returns:
        A fresh PCG64 generator.
    """
    key = zlib.crc32(name.encode("utf-8"))
    child = np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, key), pool_size=seed.pool_size)
    return np.random.default_rng(child)


class EpisodeSeeds:
    """The seed sequences of successive episodes of one world.

    ``reset(seed)`` starts a new root (an int, a ``SeedSequence`` or ``None`` for fresh entropy); every call of
    ``next()`` returns the next episode's sequence. A world reset with seed ``s`` and a single env reset with
    ``seed=s`` therefore see the same episodes, including the ones that follow without a new seed.
    """

    __slots__ = ("_root",)

    def __init__(self, seed: int | np.random.SeedSequence | None = None) -> None:
        self.reset(seed)

    def reset(self, seed: int | np.random.SeedSequence | None) -> None:
        """Start again from ``seed``.

        Raises:
            ValueError: Unless ``seed`` is ``None``, a ``SeedSequence`` or an integer ``>= 0`` (numpy integers
                too; bools, floats and strings are refused).
        """
        if isinstance(seed, np.random.SeedSequence):
            self._root = seed
            return
        if seed is not None and not is_int(seed):
            raise ValueError(f"seed must be None or an integer >= 0, got {type(seed).__name__} {short_repr(seed)}")
        if seed is not None and seed < 0:
            raise ValueError(f"seed must be None or an integer >= 0, got {seed}")
        self._root = np.random.SeedSequence(None if seed is None else int(seed))

    def next(self) -> np.random.SeedSequence:
        """The next episode's seed sequence."""
        return self._root.spawn(1)[0]
