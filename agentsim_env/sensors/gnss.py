"""A noisy GNSS receiver with a barometric altimeter: each agent's own position, with errors.

The second sensor of the package and the model for adding one: it implements the ``Sensor`` protocol of
``core.pipeline`` and nothing in ``sim`` or ``core`` knows about it. A scenario enables it by passing it to the
world; the scenario base then adds its observation part, ``gnss (3,)``, to every observation:

| idx | content                                                                     |
|-----|-----------------------------------------------------------------------------|
| 0   | measured x in [-1, 1] over the map's x range                                 |
| 1   | measured y in [-1, 1] over the map's y range                                 |
| 2   | measured altitude in [-1, 1] over the altitude band                          |

The horizontal error is Gaussian with ``sigma_h`` per axis, the altimeter's with ``sigma_v``; every reading is
new noise (no bias or random walk). Offline slots read zeros.

The noise is keyed, not streamed: the error of agent i of world w on axis a is
``core.keyed.keyed_normal(episode key of w, t, i, a)``, where the episode key is one 64-bit word drawn from the
generator the world's reset hands the sensor, and t is the episode step the reading describes (world ``w``'s
``step_count + 1`` inside a step; ``step_count`` when a reset or ``World.refresh`` re-reads the state, i.e. when
``ctx.fresh`` names the worlds). A reading therefore depends on neither the other worlds of a batch, nor the
other slots a process holds (a shard draws exactly the numbers one process draws for its slots), nor the steps
before the episode's reset; reading the same state twice gives the same noise.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field

from agentsim_env.core.config_model import Real, config
from agentsim_env.core.keyed import keyed_normal
from agentsim_env.core.pipeline import Part, StepContext

Sigma = Annotated[Real, Field(ge=0.0, le=1e3)]
"""A standard deviation in metres, 0..1e3."""


@config("gnss")
class GnssConfig:
    """Errors of the GNSS sensor.

    Attributes:
        sigma_h: Horizontal error per axis (standard deviation) in metres, >= 0.
        sigma_v: Altimeter error (standard deviation) in metres, >= 0.
    """

    sigma_h: Sigma = 1.5
    sigma_v: Sigma = 0.5


class GnssSensor:
    """Noisy own-position readings of B worlds of N agents.

    Args:
        config: Error model.
        n_worlds: Worlds B.
        n_agents: Agents per world N.
        bounds: Map ``(xmin, xmax, ymin, ymax)`` the reading is normalised over.
        z_range: Altitude band ``(zmin, zmax)`` the altitude is normalised over.
    """

    name = "gnss"
    obs_part = Part((3,), -1.0, 1.0)

    def __init__(
        self,
        config: GnssConfig,
        n_worlds: int,
        n_agents: int,
        bounds: tuple[float, float, float, float],
        z_range: tuple[float, float],
    ) -> None:
        self.config = config
        self.n_agents = int(n_agents)
        self._lo = np.array([bounds[0], bounds[2], z_range[0]], dtype=np.float64)
        self._span = np.array([bounds[1] - bounds[0], bounds[3] - bounds[2], z_range[1] - z_range[0]])
        self._sigma = np.array([config.sigma_h, config.sigma_h, config.sigma_v])
        self._keys = np.zeros(int(n_worlds), dtype=np.uint64)  # each world's episode key, drawn at its reset
        self._keyed = np.zeros(int(n_worlds), dtype=bool)
        self._reading = np.full((int(n_worlds) * self.n_agents, 3), np.nan)

    def reset_world(self, w: int, rng: np.random.Generator) -> None:
        """World ``w``'s noise this episode is keyed by one word drawn from ``rng``."""
        self._keys[w] = rng.integers(0, 2**64, dtype=np.uint64)
        self._keyed[w] = True

    def step(self, ctx: StepContext) -> np.ndarray:
        """Stage 8: measured positions ``(S, 3)`` in metres (NaN for offline slots).

        After a reset only the reset worlds are measured again (``ctx.fresh``); the others keep their reading.
        Only online slots draw noise, each from its own key (see the module docstring).
        """
        st = ctx.state
        n = self.n_agents
        reading = self._reading.copy()
        # A context naming fresh worlds re-reads the current state (a reset or World.refresh); without it the
        # reading is a step's and describes the state after the step.
        when = ctx.step_count if ctx.fresh is not None else ctx.step_count + 1
        worlds = np.arange(len(self._keys)) if ctx.fresh is None else np.asarray(ctx.fresh, dtype=np.int64)
        missing = worlds[~self._keyed[worlds]]
        if missing.size:
            raise ValueError(f"gnss: world {int(missing[0])} has no noise key yet: reset it (reset_world) first")
        rows = (worlds[:, None] * n + np.arange(n)).ravel()
        live = rows[st.online[rows]]
        w_of, agent = np.divmod(live, n)
        noise = keyed_normal(self._keys[w_of][:, None], when[w_of][:, None], agent[:, None], np.arange(3))
        reading[rows] = np.nan
        reading[live] = st.pos[live] + noise * self._sigma
        self._reading = reading
        return reading

    def observe(self, reading: np.ndarray) -> np.ndarray:
        """``(S, 3)`` float32 in [-1, 1] (zeros for offline slots)."""
        out = np.nan_to_num((reading - self._lo) / self._span * 2.0 - 1.0, nan=0.0)
        return np.clip(out, -1.0, 1.0).astype(np.float32)
