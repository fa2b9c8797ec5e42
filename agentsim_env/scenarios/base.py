"""The Scenario contract: four methods a scenario writes, everything else derived by this base class.

A scenario is one small file: a config extending ``ScenarioConfig``, a per-slot state dataclass extending
``SlotState``, and a ``Scenario[ConfigT]`` subclass with four required methods:

- ``make_world(n_worlds)``: build the ``World`` (geometry, sensors, optional payloads; the base adds comms);
- ``reset_world(world, w, rng)``: start an episode of world ``w`` (agents, goals, obstacles) from the
  placement generator ``rng``;
- ``score(world, events, acting)``: stage 9's rewards, terminations and infos;
- ``observe(world)``: the scenario's own observation parts.

Derived, never kept in step by hand: the observation parts (shapes from what ``observe`` returns on a probe
world, bounds from ``obs_bounds`` or the sensor declaring the part, as the proximity sensor declares ``lidar``),
the sensor parts (each sensor with an ``obs_part``), the comms parts
(``inbox``, ``comms`` observations and the ``comm`` action, added when the config has comms), the action parts
(``motion`` from ``action_mode`` plus ``extra_actions``), the global state and its size (the base's per-agent
block plus ``state_extra``). ``apply_actions`` (stage 1) has a default that decodes ``motion``; a scenario with
actions of its own (releases) extends it.

``run_step`` and ``reset_worlds`` are the one pipeline every env front end calls: stage 1, ``World.step``
(stages 2-8 and 10), stage 9.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from agentsim_env.core.budget import check_memory
from agentsim_env.core.pipeline import Part
from agentsim_env.motion import MotionLimits, decode_primitive
from agentsim_env.motion.actions import decode_velocity_unchecked
from agentsim_env.scenarios.config import ScenarioConfig
from agentsim_env.scenarios.flat_layout import INBOX_CLIP, check_rows_at, comms_width, flat_parts, write_comms
from agentsim_env.scenarios.rewards import combine_partials
from agentsim_env.sensors.proximity import ProximityConfig, ProximitySensor
from agentsim_env.sim.world import StepEvents, StepScores, World

ConfigT = TypeVar("ConfigT", bound=ScenarioConfig)
SlotT = TypeVar("SlotT", bound="SlotState")


@dataclass(slots=True)
class StepResult:
    """What the scenario computes in stage 9 (arrays over slots).

    Every array is fresh, never one of the world's state arrays (``world.task``, ``world.state``): the batched
    env hands them to the caller as they are, and a reset or a later step writes the state.

    Attributes:
        rewards: Reward per slot ``(S,)``.
        terminated: Slots whose episode ended this step (goal reached, collision, dead battery...) ``(S,)``.
        info: Per-slot scalar arrays copied into each agent's info dict (the same keys every step).
    """

    rewards: np.ndarray
    terminated: np.ndarray
    info: dict[str, np.ndarray]


def slot(shape: tuple[int, ...] = (), dtype: Any = np.float64, *, per_world: bool = False) -> Any:
    """Declare an array field of a ``SlotState``: ``(S, *shape)`` (or ``(B, *shape)`` when ``per_world``)."""
    return dataclasses.field(default=None, metadata={"shape": shape, "dtype": dtype, "per_world": per_world})


@dataclass(slots=True)
class SlotState:
    """Base of a scenario's per-slot state: declare each array with :func:`slot`; ``allocate`` sizes them.

    Fields declared without :func:`slot` (e.g. a per-world tracker object) are left to the scenario.
    """

    @classmethod
    def allocate(cls: type[SlotT], n_slots: int, n_worlds: int = 1) -> SlotT:
        """An instance whose every :func:`slot` field is a zeroed ``(n_slots or n_worlds, *shape)`` array."""
        arrays = {
            f.name: np.zeros(
                (n_worlds if f.metadata["per_world"] else n_slots, *f.metadata["shape"]),
                dtype=f.metadata["dtype"],
            )
            for f in dataclasses.fields(cls)  # type: ignore[arg-type]
            if "shape" in f.metadata
        }
        return cls(**arrays)


_BYTES_PER_SLOT = 1200
"""Fixed bytes per slot of the memory estimate (agent state, motion primitives, grid, bookkeeping)."""


@dataclass(frozen=True, slots=True)
class _Spec:
    obs: dict[str, Part]
    state_size: int
    info_keys: tuple[str, ...]


class Scenario(ABC, Generic[ConfigT]):
    """Base class of all scenarios (see the module docstring for the contract)."""

    name: ClassVar[str]
    config_cls: ClassVar[type]
    version: ClassVar[int] = 0
    agent_prefix: ClassVar[str] = "agent"
    #: Configs the conformance suite runs (each also in flat obs/action format); keep them small and fast.
    test_configs: ClassVar[tuple[dict[str, Any], ...]] = ({},)
    #: Bounds of the scenario's observation parts (default (-1, 1); a sensor's declared part has its own).
    obs_bounds: ClassVar[dict[str, tuple[float, float]]] = {}
    #: Scenario action parts after ``motion`` (name -> size), each a box in [-1, 1].
    extra_actions: ClassVar[dict[str, int]] = {}
    #: Info keys that count events (an evaluation sums them over an episode, per agent).
    event_keys: ClassVar[tuple[str, ...]] = ("arrived", "collided")
    #: Info keys whose value at the end of an episode is an outcome (an evaluation reports the last one).
    final_keys: ClassVar[tuple[str, ...]] = ()
    #: Whether the scenario runs over shards (``agentsim_env.distributed``): its stage 1 decodes motion from the
    #: agent's own state only, and its spatial work is the proximity scan, collisions and the comms range graph.
    shardable: ClassVar[bool] = False

    def __init__(self, config: ConfigT) -> None:
        self.config = config
        self.lidar = ProximityConfig(
            n_azimuth=config.sensing.n_azimuth, elevations_deg=tuple(config.sensing.elevations_deg)
        )
        self._spec: _Spec | None = None

    # -- the four required methods ------------------------------------------------------------------------
    @abstractmethod
    def make_world(self, n_worlds: int) -> World:
        """Create the world for ``n_worlds`` worlds (pass ``comms=self.config.comms``; set ``world.task``)."""

    @abstractmethod
    def reset_world(self, world: World, w: int, rng: np.random.Generator) -> None:
        """Start a new episode in world ``w``: place agents, goals, obstacles (draw only from ``rng``)."""

    @abstractmethod
    def score(
        self,
        world: World,
        events: StepEvents,
        acting: np.ndarray,
        totals: dict[str, np.ndarray] | None = None,
    ) -> StepResult:
        """Stage 9: rewards, terminations and infos of every slot after the world stepped.

        ``totals`` are the combined :meth:`group_partials` of every part of the world (``None``: the scenario
        computes its group terms over every slot itself). A scenario without group terms may ignore it.
        """

    @abstractmethod
    def observe(self, world: World) -> dict[str, np.ndarray]:
        """The scenario's observation parts ``{part: (S, *shape) float32}`` (inside ``obs_bounds``)."""

    # -- optional ------------------------------------------------------------------------------------------
    def group_partials(
        self, world: World, events: StepEvents, acting: np.ndarray, mine: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Stage 9's whole-group inputs summed over the slots in ``mine`` only (no state is changed).

        A process holding part of a world's slots (a shard) computes these over its own slots; adding them up
        over every part (:func:`combine_partials`) gives the totals :meth:`score` takes. Each value is an integer
        array (``task_big``, the values past the fixed point's range, is float64) indexed ``group * B + world``
        (``rewards.group_keys``), of shape ``(B * n_groups,)`` unless a slot
        of the part has a higher group id (then longer; the combine zero-pads), so the totals do not depend on
        how the slots were split. Default: ``{}`` (no group terms).

        Args:
            world: The world, after stages 2-8 of the step.
            events: The step's events.
            acting: Slots that acted this step.
            mine: ``(S,)`` bool, the slots this part sums.

        Returns:
            Partial sums by name (the scenario's own names), or ``{}``.
        """
        return {}

    def apply_actions(self, world: World, actions: dict[str, np.ndarray], acting: np.ndarray) -> None:
        """Stage 1: decode the acting slots' ``motion`` actions into motion primitives (validated, clipped)."""
        st = world.state
        if self.config.action_mode == "velocity":
            decode_velocity_unchecked(world.motion, acting, actions["motion"], st.max_speed)
        else:
            slots = np.flatnonzero(acting)
            decode_primitive(world.motion, slots, actions["motion"][slots], st.pos, self.motion_limits(world))

    def motion_limits(self, world: World) -> MotionLimits:
        """Limits of the ``primitive`` action mode (default: the body's, radius up to a quarter of the map)."""
        b = self.config.body
        x0, x1, y0, y1 = world.config.bounds
        return MotionLimits(
            max_speed=b.max_speed,
            max_accel=b.max_accel,
            max_radius=min(x1 - x0, y1 - y0) / 4,
            max_duration=10.0,
            z_min=b.altitude[0],
            z_max=b.altitude[1],
            max_omega=1.0,
            arrival_radius=1.0,
        )

    def state_extra(self, world: World, w: int) -> np.ndarray:
        """Scenario-specific global state of world ``w`` appended after the per-agent block (default none)."""
        return np.zeros(0)

    def markers(self, world: World, w: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Scenario markers for the renderer: ``(xy (m, 2), rgb (m, 3) uint8, radius (m,))`` or ``None``."""
        return None

    def view_markers(self, world: World, w: int) -> list[dict[str, Any]]:
        """What the 3D viewer draws on the ground for world ``w`` (sent once per episode; docs/viewer.md).

        Each marker is a dict: ``kind`` (``"goal"``, ``"target"``, ``"zone"`` or ``"marker"``), ``pos`` (x, y, z),
        ``radius`` (m), ``colour`` (``"#rrggbb"``), ``label``, and optionally ``slot`` (the agent it belongs to),
        ``group`` and, for zones, ``density`` (samples from the centre to the rim, max 1). The default draws
        ``markers()`` as plain discs; scenarios override it to say what each marker is.

        Args:
            world: The scenario's world.
            w: World index.

        Returns:
            The markers (possibly none).
        """
        found = self.markers(world, w)
        if found is None:
            return []
        xy, rgb, radius = found
        return [
            {
                "kind": "marker",
                "pos": [round(float(x), 3), round(float(y), 3), 0.0],
                "radius": round(float(r), 3),
                "colour": "#{:02x}{:02x}{:02x}".format(*(int(v) for v in c)),
                "label": f"marker {i}",
            }
            for i, ((x, y), c, r) in enumerate(zip(xy, rgb, radius))
        ]

    # -- sizes ---------------------------------------------------------------------------------------------
    @property
    def n_agents(self) -> int:
        """Agents per world."""
        return int(self.config.n_agents)

    @property
    def max_steps(self) -> int:
        """Steps after which every live agent is truncated."""
        return int(self.config.max_steps)

    @property
    def n_groups(self) -> int:
        """Groups per world (1 when the scenario has no groups)."""
        return int(getattr(self.config, "n_groups", None) or 1)

    def agent_names(self) -> list[str]:
        """Agent ids of one world, in slot order."""
        return [f"{self.agent_prefix}_{i}" for i in range(self.n_agents)]

    def extra_bytes(self) -> tuple[int, int]:
        """Memory the scenario adds beyond the shared estimate: ``(bytes per slot, bytes per world)``."""
        return 0, 0

    # -- derived -------------------------------------------------------------------------------------------
    def memory_estimate(self, n_worlds: int) -> int:
        """Estimated bytes of a world of ``n_worlds`` worlds with its observations (before allocating it).

        Calibrated on the shipped scenarios (state, motion, sensor readings, inbox, observation copies); the
        scenario adds its own part with ``extra_bytes``.
        """
        c = self.config
        rays = c.sensing.n_azimuth * len(c.sensing.elevations_deg)
        obs, act = 2 * rays + 16, 8
        if c.comms is not None:
            obs += c.comms.inbox_size * c.comms.features + 2
            act += c.comms.action_dim
        per_slot, per_world = self.extra_bytes()
        per_slot += _BYTES_PER_SLOT + 16 * obs + 24 * act
        return int(n_worlds) * (self.n_agents * per_slot + per_world)

    def build(self, n_worlds: int) -> World:
        """``make_world`` checked: the memory it needs fits the machine, and the world carries the comms settings.

        Raises:
            ValueError: When the estimated memory is over the limit (``core.budget``).
        """
        check_memory(
            f"{self.name} with n_agents={self.n_agents} x n_worlds={n_worlds}",
            self.memory_estimate(n_worlds),
            "lower n_agents or n_worlds (or the sensor rays, inbox_size and payload_dim)",
        )
        world = self.make_world(n_worlds)
        if (world.comms is None) != (self.config.comms is None):
            raise TypeError(f"{type(self).__name__}.make_world must pass comms=self.config.comms to World")
        return world

    def spec(self) -> _Spec:
        """Observation parts, state size and info keys, measured once on a probe world of one world."""
        if self._spec is None:
            world = self.build(1)
            reset_worlds(self, world, [0], [np.random.SeedSequence(0)])
            obs = self.observation(world)
            acting = np.ones(world.state.n_slots, dtype=bool)
            parts = {}
            for k, v in obs.items():
                shape = tuple(int(d) for d in v.shape[1:])
                declared = _declared_part(world, k)
                if declared is not None and declared.shape != shape:
                    raise ValueError(
                        f"{self.name}: observation part {k!r} has shape {shape}, its sensor declares {declared.shape}"
                    )
                lo, hi = self._bounds(world, k)
                parts[k] = Part(shape, lo, hi)
            res = run_step(
                self,
                world,
                {k: np.zeros((world.state.n_slots, p.size)) for k, p in self.act_parts().items()},
                acting,
            )[0]
            self._spec = _Spec(parts, int(self.state(world, 0).shape[0]), tuple(res.info))
        return self._spec

    def _bounds(self, world: World, part: str) -> tuple[float, float]:
        if part in ("inbox", "comms"):
            return (-INBOX_CLIP, INBOX_CLIP) if part == "inbox" else (0.0, 1.0)
        declared = _declared_part(world, part)
        if declared is not None:
            return declared.low, declared.high
        return self.obs_bounds.get(part, (-1.0, 1.0))

    def obs_parts(self) -> dict[str, Part]:
        """Observation parts in layout order: the scenario's, the sensors', then ``inbox`` and ``comms``."""
        return self.spec().obs

    def act_parts(self) -> dict[str, Part]:
        """Action parts in layout order: ``motion``, the scenario's ``extra_actions``, then ``comm``."""
        motion = 3 if self.config.action_mode == "velocity" else 8
        parts = {"motion": Part((motion,), -1.0, 1.0)}
        parts.update({k: Part((n,), -1.0, 1.0) for k, n in self.extra_actions.items()})
        if self.config.comms is not None:
            parts["comm"] = Part((self.config.comms.action_dim,), -1.0, 1.0)
        return parts

    def state_size(self) -> int:
        """Length of the global state vector of one world."""
        return self.spec().state_size

    def info_keys(self) -> tuple[str, ...]:
        """The keys of every agent's info dict (the same at reset and at every step)."""
        return self.spec().info_keys

    def observation(self, world: World) -> dict[str, np.ndarray]:
        """Every observation part of every slot: the scenario's, the sensors', the inbox and counters."""
        out = self.observe(world)
        for s in world.sensors:
            if s.obs_part is not None:
                out[s.name] = s.observe(world.readings[s.name])
        if world.comms is not None:
            out["inbox"], out["comms"] = world.comms.observe(world.state.pos, max(world.tick - 1, 0), INBOX_CLIP)
        return out

    def observe_rows(self, world: World, slots: np.ndarray) -> dict[str, np.ndarray]:
        """The scenario's observation parts of ``slots`` only, ``{part: (len(slots), *shape)}`` (the rows
        :meth:`observe` gives them; a scenario may compute just these rows)."""
        return {k: v[slots] for k, v in self.observe(world).items()}

    def observation_rows(self, world: World, slots: np.ndarray) -> dict[str, np.ndarray]:
        """:meth:`observation` for ``slots`` only: what a shard computes for its own agents."""
        out = self.observe_rows(world, slots)
        for s in world.sensors:
            if s.obs_part is not None:
                out[s.name] = s.observe(world.readings[s.name])[slots]
        if world.comms is not None:
            out["inbox"], out["comms"] = world.comms.observe_rows(
                world.state.pos, max(world.tick - 1, 0), slots, INBOX_CLIP
            )
        return out

    def flat_observation_rows(
        self, world: World, slots: np.ndarray, out: np.ndarray | None = None, at: np.ndarray | None = None
    ) -> np.ndarray:
        """:meth:`observation_rows` in the flat layout ``(len(slots), obs_dim)`` float32, into ``out`` when given:
        the rows :meth:`flat_observation` gives ``slots`` (a shard's own agents), the inbox and counters
        written in place. With ``at``, slot ``slots[r]``'s row goes to row ``at[r]`` of ``out`` (required then,
        e.g. an array of every slot's row with ``at = slots``).

        Raises:
            ValueError: For an ``out`` of the wrong shape or dtype, or an ``at`` that does not give each slot a row
                of ``out``.
        """
        n = int(np.asarray(slots).shape[0])
        if at is not None:
            if out is None:
                raise ValueError("at needs out: the array whose rows it names")
            at = check_rows_at(np.asarray(slots), at, out, sum(p.size for p in self.obs_parts().values()))
            if world.comms is None or type(self).observation is not Scenario.observation:
                out[at] = flat_parts(self.observation_rows(world, slots), n)
                return out
        if world.comms is None or type(self).observation is not Scenario.observation:
            return flat_parts(self.observation_rows(world, slots), n, out)
        parts = self.observe_rows(world, slots)
        for s in world.sensors:
            if s.obs_part is not None:
                parts[s.name] = s.observe(world.readings[s.name])[slots]
        lead = sum(int(np.prod(p.shape[1:], dtype=np.int64)) for p in parts.values())
        if out is None:
            out = np.empty((n, lead + comms_width(world)), dtype=np.float32)
        if at is None:
            flat_parts(parts, n, out[:, :lead])
        else:
            out[at, :lead] = flat_parts(parts, n)
        world.comms.observe_rows_flat(world.state.pos, max(world.tick - 1, 0), slots, out, lead, INBOX_CLIP, at)
        return out

    def flat_observation(self, world: World, out: np.ndarray | None = None) -> np.ndarray:
        """Every observation part of every slot in the flat layout ``(S, obs_dim)`` float32.

        The parts of :meth:`observation` concatenated in layout order, into ``out`` when given (else a fresh
        array); a scenario may write them straight into the flat array instead (same values).
        """
        if world.comms is None or type(self).observation is not Scenario.observation:
            return flat_parts(self.observation(world), world.state.n_slots, out, world.threads)
        # the scenario's and sensors' parts copied in, the inbox and counters written in place (no copy of the
        # largest part, no second pass to clip it)
        parts = self.observe(world)
        for s in world.sensors:
            if s.obs_part is not None:
                parts[s.name] = s.observe(world.readings[s.name])
        n = world.state.n_slots
        lead = sum(int(np.prod(p.shape[1:], dtype=np.int64)) for p in parts.values())
        if out is None:
            out = np.empty((n, lead + comms_width(world)), dtype=np.float32)
        flat_parts(parts, n, out[:, :lead], world.threads)
        write_comms(world, out, lead)
        return out

    def state(self, world: World, w: int) -> np.ndarray:
        """Global state of world ``w``: per agent pos / 100, vel / 10, online, group / 10; then ``state_extra``."""
        st = world.state
        sl = slice(w * self.n_agents, (w + 1) * self.n_agents)
        per = np.column_stack(
            [st.pos[sl] / 100.0, st.vel[sl] / 10.0, st.online[sl].astype(np.float64), st.group[sl] / 10.0]
        )
        extra = np.asarray(self.state_extra(world, w), dtype=np.float64).ravel()
        return np.clip(np.concatenate([per.ravel(), extra]), -10.0, 10.0).astype(np.float32)


def _declared_part(world: World, part: str) -> Part | None:
    """The observation part a sensor of ``world`` declares under the name ``part``, or ``None``: a sensor's
    ``obs_part`` (added by the base), or the proximity sensor's ``lidar`` (placed by the scenario)."""
    for s in world.sensors:
        if s.name == part and s.obs_part is not None:
            return s.obs_part
        if isinstance(s, ProximitySensor) and s.part_name == part:
            return s.part
    return None


def reset_worlds(
    scenario: Scenario[Any], world: World, worlds: Iterable[int], seeds: Sequence[np.random.SeedSequence]
) -> None:
    """Start new episodes of ``worlds``: every subsystem's stream, then the scenario's placement, then sensors.

    Args:
        scenario: The scenario.
        world: Its world.
        worlds: World indices to reset.
        seeds: One episode seed sequence per world reset.
    """
    ws = [int(w) for w in worlds]
    for w, seed in zip(ws, seeds, strict=True):
        placement = world.reset_world(w, seed)
        scenario.reset_world(world, w, placement)
    world.refresh(ws)


def run_step(
    scenario: Scenario[Any], world: World, parts: dict[str, np.ndarray], acting: np.ndarray
) -> tuple[StepResult, np.ndarray]:
    """One step of the pipeline shared by every env front end.

    Stage 1 decodes the validated action parts of the acting slots (motion, scenario parts, ``comm``), stages
    2-8 run in ``World.step``, stage 9 is the scenario's scoring (slots that ended leave the simulation), and
    stage 10 runs the world's step hooks with the scores in ``events.scores``.

    Returns:
        The scenario's result and the mask of slots that terminated this step.
    """
    scenario.apply_actions(world, parts, acting)
    if "comm" in parts:
        world.apply_comm(parts["comm"], acting)
    events = world.step(hooks=False)
    # 9. the group terms from per-group partial sums: one part holding every slot (a shard holds some of them
    # and the parts are added up elsewhere; the sums are exact, so both give the same scores)
    bridge = world.bridge
    mine = np.ones(world.state.n_slots, dtype=bool) if bridge is None else bridge.own
    partials = scenario.group_partials(world, events, acting, mine)
    if partials:
        totals = combine_partials([partials]) if bridge is None else bridge.combine(partials)
        res = scenario.score(world, events, acting, totals)
    else:
        res = scenario.score(world, events, acting)
    terminated = acting & (res.terminated | ~world.state.online)
    if terminated.any():
        world.set_offline(np.flatnonzero(terminated))
    if world.hooks:  # 10. step hooks, with the scores
        events.scores = StepScores(acting, res.rewards, terminated, res.info)
        world.run_hooks(events)
    return res, terminated
