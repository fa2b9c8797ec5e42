"""Horizontal wind: a per-episode mean with a height profile, plus Ornstein-Uhlenbeck gusts.

Conventions:
- ``direction`` is the direction the wind blows *toward*, in radians counter-clockwise from +x (a
  wind with direction 0 pushes objects toward +x). ``mean_speed`` is the speed at ``z_ref``.
- Height profiles: ``"log"`` ``u(z) = u_ref ln(z / z0) / ln(z_ref / z0)`` (0 at and below ``z0``),
  ``"power"`` ``u(z) = u_ref (z / z_ref)^(1/7)`` (0 at and below ground), ``"uniform"`` ``u(z) = u_ref``.
- Gusts are horizontal, one Ornstein-Uhlenbeck state per falling object (not one shared field):
  every node then draws its own turbulence, which is what produces the independent gust term of the
  landing-scatter model. Their standard deviation is ``gust_sigma_frac * speed`` of the object's world,
  the same at every height (in the surface layer the velocity variance is roughly height-independent),
  and their correlation time is ``gust_tau``. The caller owns the gust array (``PayloadSet`` keeps one
  row per object) and advances it with ``advance_gusts``.
- One ``WindModel`` serves ``n_worlds`` independent worlds (a batched vector env), each with its own
  mean wind; pass ``world`` indices to select it per object.
"""

from __future__ import annotations

import math
import typing
from collections.abc import Sequence
from typing import Annotated, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, Field

from agentsim_env.core.config_model import Choice, FieldError, Real, config, ordered

__all__ = ["WIND_PROFILES", "WindConfig", "WindModel"]

WindProfile = Annotated[Literal["log", "power", "uniform"], Choice]
"""Height profiles of the mean wind."""
WIND_PROFILES: tuple[str, ...] = typing.get_args(typing.get_args(WindProfile)[0])
Speed = Annotated[Real, Field(ge=0.0)]
"""A wind speed in m/s, >= 0."""


@config("wind")
class WindConfig:
    """Wind configuration (validated).

    Attributes:
        mean_speed: Mean speed at ``z_ref`` in m/s (>= 0), used when ``randomise_speed`` is ``None``.
        direction: Direction the wind blows toward, radians from +x; ``None`` draws one per episode.
        randomise_speed: ``(lo, hi)`` with ``0 <= lo <= hi``: draw the speed uniformly per episode.
        profile: Height profile, one of ``WIND_PROFILES``.
        z0: Roughness length in metres, 1e-4..10 (0.03 for grass or open land).
        z_ref: Reference height in metres, ``max(2 x z0, 0.1)``..1000.
        gust_sigma_frac: Gust standard deviation as a fraction of the mean speed (>= 0).
        gust_tau: Gust correlation time in seconds (> 0).
    """

    mean_speed: Speed = 0.0
    direction: Real | None = None
    randomise_speed: Annotated[tuple[Speed, Speed], AfterValidator(ordered)] | None = None
    profile: WindProfile = "log"
    z0: Annotated[Real, Field(ge=1e-4, le=10.0)] = 0.03
    z_ref: Annotated[Real, Field(le=1e3)] = 10.0  # at least max(2 x z0, 0.1)
    gust_sigma_frac: Annotated[Real, Field(ge=0.0)] = 0.2
    gust_tau: Annotated[Real, Field(gt=0.0)] = 2.0

    def __post_init__(self) -> None:
        """The rule across fields: ``z_ref`` lies above the roughness length."""
        if self.z_ref < max(2.0 * self.z0, 0.1):
            raise FieldError(
                "z_ref",
                f"must be a number in [max(2 x z0, 0.1), 1000] = [{max(2.0 * self.z0, 0.1):g}, 1000] "
                f"(metres), got {self.z_ref!r}",
            )

    def profile_factor(self, z: ArrayLike) -> NDArray[np.float64]:
        """Ratio ``u(z) / u(z_ref)`` of the height profile (0 at and below the ground or ``z0``).

        Args:
            z: Heights in metres.

        Returns:
            Non-negative factors, same shape as ``z``.
        """
        z_arr = np.asarray(z, dtype=np.float64)
        if self.profile == "uniform":
            return np.ones_like(z_arr)
        if self.profile == "power":
            return np.power(np.maximum(z_arr, 0.0) / self.z_ref, 1.0 / 7.0)
        # The log law is negative below z0; clip there (the node is on the ground anyway).
        return np.log(np.maximum(z_arr, self.z0) / self.z0) / math.log(self.z_ref / self.z0)


RngLike = np.random.Generator | Sequence[np.random.Generator | None]
"""One generator, or one per world (each object's numbers then come from its own world's generator; ``None``
for a world that has none yet, which raises when that world needs a draw)."""


def normals(rng: RngLike, shape: tuple[int, ...], world: ArrayLike | None = None) -> NDArray[np.float64]:
    """Standard normals of ``shape`` (rows = objects), drawn per world when ``rng`` holds one generator each.

    Per-world draws take each world's rows in row order from that world's generator, so a world's numbers
    never depend on what the other worlds of a batch hold.

    Args:
        rng: A generator, or a sequence of one generator per world.
        shape: ``(n, ...)`` output shape.
        world: ``(n,)`` world of each row (required with per-world generators and more than one of them).

    Returns:
        The normals.
    """
    if isinstance(rng, np.random.Generator):
        return rng.standard_normal(shape)
    gens = list(rng)
    if world is None:
        if len(gens) != 1:
            raise ValueError(f"world must be given with {len(gens)} per-world generators")
        world = np.zeros(shape[0], dtype=np.int64)
    w_of = np.asarray(world, dtype=np.int64)
    out = np.empty(shape)
    for w in np.unique(w_of).tolist():
        g = gens[w]
        if g is None:
            raise ValueError(f"world {w} has no random stream yet: reset it (reset_world) first")
        rows = np.flatnonzero(w_of == w)
        out[rows] = g.standard_normal((rows.size, *shape[1:]))
    return out


class WindModel:
    """Per-episode mean wind for ``n_worlds`` worlds and the Ornstein-Uhlenbeck gust dynamics.

    Args:
        config: Wind configuration.
        rng: Generator used to draw the first episode's mean wind (``None``: the configured mean speed and
            direction, or calm direction 0, until a world's ``reset``).
        n_worlds: Number of independent worlds (>= 1).
    """

    __slots__ = ("_direction", "_speed", "config", "n_worlds")

    def __init__(self, config: WindConfig, rng: np.random.Generator | None = None, n_worlds: int = 1) -> None:
        if isinstance(n_worlds, bool) or not isinstance(n_worlds, (int, np.integer)) or n_worlds < 1:
            raise ValueError(f"n_worlds must be an integer >= 1, got {n_worlds!r}")
        self.config = config
        self.n_worlds = int(n_worlds)
        self._speed = np.zeros(self.n_worlds)
        self._direction = np.zeros(self.n_worlds)
        if rng is not None:
            self.reset(rng)
        else:
            self._speed[:] = config.mean_speed
            self._direction[:] = 0.0 if config.direction is None else config.direction

    def reset(self, rng: np.random.Generator, world: ArrayLike | None = None) -> None:
        """Draw a new mean wind (speed and direction as configured) for all or some worlds.

        Args:
            rng: Random generator.
            world: World indices to redraw (``None``: all).
        """
        idx = np.arange(self.n_worlds) if world is None else np.atleast_1d(np.asarray(world, dtype=np.intp))
        cfg = self.config
        if cfg.randomise_speed is None:
            self._speed[idx] = cfg.mean_speed
        else:
            self._speed[idx] = rng.uniform(cfg.randomise_speed[0], cfg.randomise_speed[1], idx.size)
        if cfg.direction is None:
            self._direction[idx] = rng.uniform(0.0, 2.0 * math.pi, idx.size)
        else:
            self._direction[idx] = cfg.direction

    @property
    def speed(self) -> NDArray[np.float64]:
        """Mean speed at ``z_ref`` per world ``(n_worlds,)`` (a copy)."""
        return self._speed.copy()

    @property
    def direction(self) -> NDArray[np.float64]:
        """Direction the wind blows toward per world ``(n_worlds,)`` in radians (a copy)."""
        return self._direction.copy()

    @property
    def mean(self) -> NDArray[np.float64]:
        """Mean horizontal wind at ``z_ref`` per world ``(n_worlds, 2)``."""
        return self._speed[:, None] * np.stack([np.cos(self._direction), np.sin(self._direction)], axis=1)

    @property
    def gust_sigma(self) -> NDArray[np.float64]:
        """Gust standard deviation per horizontal component, per world ``(n_worlds,)``."""
        return self.config.gust_sigma_frac * self._speed

    def world_index(self, world: ArrayLike | None, n: int) -> NDArray[np.intp]:
        """Resolve per-object world indices.

        Args:
            world: World index per object ``(n,)``, a scalar, or ``None`` (only when ``n_worlds == 1``).
            n: Number of objects.

        Returns:
            ``(n,)`` indices into the per-world arrays.
        """
        if world is None:
            if self.n_worlds != 1:
                raise ValueError(f"world must be given when n_worlds > 1 (n_worlds = {self.n_worlds})")
            return np.zeros(n, dtype=np.intp)
        w = np.broadcast_to(np.asarray(world, dtype=np.intp), (n,))
        if n and (w.min() < 0 or w.max() >= self.n_worlds):
            raise ValueError(f"world must be in [0, {self.n_worlds}), got range [{w.min()}, {w.max()}]")
        return w

    def mean_velocity_at(self, z: ArrayLike, world: ArrayLike | None = None) -> NDArray[np.float64]:
        """Mean wind velocity (no gusts) at heights ``z``.

        Args:
            z: Heights ``(n,)`` in metres.
            world: World index per object ``(n,)`` or a scalar (``None`` when ``n_worlds == 1``).

        Returns:
            ``(n, 3)`` velocities with zero vertical component.
        """
        z_arr = np.atleast_1d(np.asarray(z, dtype=np.float64))
        w = self.world_index(world, z_arr.shape[0])
        out = np.zeros((z_arr.shape[0], 3))
        out[:, :2] = self.mean[w] * self.config.profile_factor(z_arr)[:, None]
        return out

    def velocity_at(
        self, z: ArrayLike, gusts: ArrayLike | None = None, world: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Wind velocity at heights ``z``: height-profiled mean plus the objects' gusts.

        Args:
            z: Heights ``(n,)`` in metres.
            gusts: Horizontal gust velocities ``(n, 2)``, or ``None`` for the mean only.
            world: World index per object ``(n,)`` or a scalar (``None`` when ``n_worlds == 1``).

        Returns:
            ``(n, 3)`` velocities with zero vertical component.
        """
        out = self.mean_velocity_at(z, world)
        if gusts is not None:
            g = np.asarray(gusts, dtype=np.float64)
            if g.shape != (out.shape[0], 2):
                raise ValueError(f"gusts must have shape ({out.shape[0]}, 2), got {g.shape}")
            out[:, :2] += g
        return out

    def init_gusts(self, n: int, rng: RngLike, world: ArrayLike | None = None) -> NDArray[np.float64]:
        """Draw gusts from the stationary distribution ``N(0, sigma^2 I)`` of each object's world.

        Args:
            n: Number of objects.
            rng: Random generator, or one per world (consumes ``2 n`` normals).
            world: World index per object (``None`` when ``n_worlds == 1``).

        Returns:
            ``(n, 2)`` gust velocities.
        """
        sigma = self.gust_sigma[self.world_index(world, n)]
        return normals(rng, (n, 2), world) * sigma[:, None]

    def advance_gusts(
        self,
        gusts: NDArray[np.float64],
        dt: float,
        rng: RngLike,
        world: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """Advance the gusts by ``dt`` with the exact Ornstein-Uhlenbeck transition.

        ``g' = g e^(-dt/tau) + sigma sqrt(1 - e^(-2 dt/tau)) xi`` keeps the stationary variance for any
        ``dt``, so the result does not depend on the sub-step.

        Args:
            gusts: Current gusts ``(n, 2)``.
            dt: Time step in seconds (>= 0).
            rng: Random generator, or one per world (consumes ``2 n`` normals).
            world: World index per object (``None`` when ``n_worlds == 1``).

        Returns:
            New ``(n, 2)`` gusts.
        """
        g = np.asarray(gusts, dtype=np.float64)
        if g.ndim != 2 or g.shape[1] != 2:
            raise ValueError(f"gusts must have shape (n, 2), got {g.shape}")
        decay = math.exp(-dt / self.config.gust_tau)
        sigma = self.gust_sigma[self.world_index(world, g.shape[0])]
        noise = normals(rng, g.shape, world) * (sigma * math.sqrt(max(0.0, 1.0 - decay * decay)))[:, None]
        return g * decay + noise
