"""First-order radio energy model (Heinzelman, Chandrakasan, Balakrishnan, IEEE TWC 2002).

Transmitting ``k`` bits over ``d`` metres costs ``k E_elec + k eps_fs d^2`` below the crossover distance
``d0 = sqrt(eps_fs / eps_mp)`` and ``k E_elec + k eps_mp d^4`` from ``d0`` on; receiving costs ``k E_elec``;
aggregating costs ``k E_DA``. With the default constants ``d0`` is about 87.7 m and a 4000-bit packet costs
200 uJ to receive and 204 / 236 / 300 / 720 uJ to send over 10 / 30 / 50 / 100 m.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from agentsim_env.core.config_model import Int, Real, config

__all__ = ["RadioParams", "aggregation_energy", "rx_energy", "tx_energy"]


Positive = Annotated[Real, Field(gt=0.0)]
"""A finite number > 0."""
NonNegative = Annotated[Real, Field(ge=0.0)]
"""A finite number >= 0."""


@config("wsn.radio")
class RadioParams:
    """Constants of the first-order radio model, SI units.

    Attributes:
        e_elec: Electronics energy per bit, J/bit (> 0).
        eps_fs: Free-space amplifier energy, J/bit/m^2 (>= 0).
        eps_mp: Multipath amplifier energy, J/bit/m^4 (> 0).
        e_da: Data-aggregation energy per bit per signal, J/bit (>= 0).
        packet_bits: Packet length ``k`` in bits (> 0).
        e0: Initial energy of a node, J (> 0).
    """

    e_elec: Positive = 50e-9
    eps_fs: NonNegative = 10e-12
    eps_mp: Positive = 0.0013e-12
    e_da: NonNegative = 5e-9
    packet_bits: Annotated[Int, Field(gt=0)] = 4000
    e0: Positive = 0.5

    @property
    def d0(self) -> float:
        """Crossover distance ``sqrt(eps_fs / eps_mp)`` in metres between the d^2 and d^4 regimes."""
        return math.sqrt(self.eps_fs / self.eps_mp)


_DEFAULT = RadioParams()


def tx_energy(k: ArrayLike, d: ArrayLike, radio: RadioParams = _DEFAULT) -> NDArray[np.float64]:
    """Energy to transmit ``k`` bits over distance ``d``.

    Args:
        k: Bits per packet (broadcast against ``d``).
        d: Distances in metres (>= 0), any shape.
        radio: Radio constants.

    Returns:
        Energy in joules, broadcast shape of ``k`` and ``d`` (0-d array for scalars).
    """
    k_arr = np.asarray(k, dtype=np.float64)
    d_arr = np.asarray(d, dtype=np.float64)
    d2 = d_arr * d_arr
    amp = np.where(d_arr < radio.d0, radio.eps_fs * d2, radio.eps_mp * d2 * d2)
    return k_arr * (radio.e_elec + amp)


def rx_energy(k: ArrayLike, radio: RadioParams = _DEFAULT) -> NDArray[np.float64]:
    """Energy to receive ``k`` bits, ``k E_elec``.

    Args:
        k: Bits per packet, any shape.
        radio: Radio constants.

    Returns:
        Energy in joules, same shape as ``k``.
    """
    return np.asarray(k, dtype=np.float64) * radio.e_elec


def aggregation_energy(k: ArrayLike, radio: RadioParams = _DEFAULT) -> NDArray[np.float64]:
    """Energy to aggregate one ``k``-bit signal at a cluster head, ``k E_DA``.

    Args:
        k: Bits per packet, any shape.
        radio: Radio constants.

    Returns:
        Energy in joules, same shape as ``k``.
    """
    return np.asarray(k, dtype=np.float64) * radio.e_da
