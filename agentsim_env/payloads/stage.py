"""The payloads stage of the pipeline (stage 4): released objects fall with drag and wind, and land.

``PayloadStage`` is a subsystem (``core.pipeline``) any scenario can enable through ``sim.World``: stage 1
releases objects through ``release`` (the scenario decodes a release action), stage 4 advances every falling
object and reports the ones that landed. Each world has its own random streams, spawned at its reset from the
world's episode seed: the mean wind, the gusts and the bounce at landing from one, the release scatter (GNSS and
timing errors) from the other, so a world's objects never depend on the other worlds of a batch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agentsim_env.core.pipeline import StepContext
from agentsim_env.payloads.ballistic import FallParams
from agentsim_env.payloads.payload_set import PayloadSet, ScatterConfig
from agentsim_env.payloads.wind import WindConfig, WindModel


@dataclass(frozen=True, slots=True)
class PayloadEvents:
    """What stage 4 did this step.

    Attributes:
        landed: Ids of the objects that landed this step, ascending (index them with ``objects.index_of``).
        released: Ids of the objects released since the previous step (stage 1 of this step), in release order.
    """

    landed: NDArray[np.int64]
    released: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


class PayloadStage:
    """Released objects of B worlds: the ``PayloadSet``, the wind and the per-world random streams.

    Args:
        params: Physical parameters of every object.
        scatter: Release and landing errors.
        wind: Wind configuration (``None``: still air).
        n_worlds: Worlds B.
    """

    name = "payloads"

    def __init__(self, params: FallParams, scatter: ScatterConfig, wind: WindConfig | None, n_worlds: int) -> None:
        self.objects = PayloadSet(params, scatter)
        self.wind = WindModel(wind, None, n_worlds) if wind is not None else None
        self.n_worlds = int(n_worlds)
        # each world's streams come with its reset_world (a draw for a world never reset raises)
        self._fall_rng: list[np.random.Generator | None] = [None] * self.n_worlds
        self._released: list[NDArray[np.int64]] = []
        self._release_rng: list[np.random.Generator | None] = [None] * self.n_worlds

    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """Remove world ``w``'s objects, draw its episode's mean wind and take its new streams."""
        fall, release = rng.spawn(2)
        self.objects.clear_world(w)
        if self.wind is not None:
            self.wind.reset(fall, world=[w])
        self._fall_rng[w] = fall
        self._release_rng[w] = release

    def release(
        self,
        owner: ArrayLike,
        world: ArrayLike,
        pos: ArrayLike,
        vel: ArrayLike,
        t: float,
        zone: ArrayLike = -1,
        target_xy: ArrayLike | None = None,
    ) -> NDArray[np.int64]:
        """Release objects from the given states (stage 1); arguments as ``PayloadSet.release``.

        Returns:
            The new objects' ids.
        """
        ids = self.objects.release(owner, world, pos, vel, t, zone, target_xy, self._release_rng)
        if ids.size:
            self._released.append(ids)
        return ids

    def step(self, ctx: StepContext) -> PayloadEvents:
        """Stage 4: advance every falling object by ``dt``; report the landings."""
        released = np.concatenate(self._released) if self._released else np.zeros(0, dtype=np.int64)
        self._released = []
        return PayloadEvents(self.objects.step(ctx.dt, self.wind, self._fall_rng), released)
