"""Rotary-wing UAV propulsion power and battery (Zeng, Xu, Zhang, IEEE TWC 18(4), 2019).

Power drawn at horizontal airspeed ``V`` by a rotorcraft of weight ``W`` (newtons)::

    P(V, W) = P0 (1 + 3 V^2 / U_tip^2)                                  blade profile
            + Pi(W) (sqrt(1 + V^4 / (4 v0(W)^4)) - V^2 / (2 v0(W)^2))^(1/2)  induced
            + 1/2 d0 rho s A V^3                                        fuselage (parasite) drag
            + W max(vz, 0)                                              climb

with ``P0 = delta/8 rho s A Omega^3 R^3``, ``U_tip = Omega R``, ``Pi(W) = (1 + k) W^(3/2) / sqrt(2 rho A)``
and ``v0(W) = sqrt(W / (2 rho A))`` (the mean rotor induced velocity in hover). With the default primitives
(the paper's table) ``P0 = 79.86 W``, ``Pi = 88.63 W``, ``U_tip = 120 m/s`` and ``v0 = 4.03 m/s`` at
``W = 20 N``.

Payload effect: ``Pi`` grows as ``W^(3/2)`` and ``v0`` as ``W^(1/2)``, so both are recomputed from the current
weight (airframe plus the sensors still on board) at every call; releasing sensors lowers the power.

Climb term: raising the weight at ``vz`` m/s costs ``m g vz = W vz`` watts of potential energy (the induced
power correction for axial flight is neglected). Descending gives no credit: the rotors still have to carry
the weight and no energy is recovered, so the term is ``W max(vz, 0)``.

Reference operating points at 20 N (computed from the formula): hover 168.5 W; 5 m/s 143.6 W; 10.2 m/s
126.0 W (minimum power, maximum endurance); 15 m/s 138.5 W; 18.3 m/s 161.6 W (maximum range, 8.83 J/m).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field
from scipy.optimize import minimize_scalar

from agentsim_env.core.config_model import Real, config
from agentsim_env.core.validation import check_float

__all__ = [
    "DEFAULT_BATTERY",
    "DEFAULT_ROTOR",
    "GRAVITY",
    "BatteryParams",
    "RotorParams",
    "energy_per_metre",
    "energy_step",
    "induced_power",
    "induced_velocity",
    "max_range_speed",
    "min_power_speed",
    "power",
]

#: Standard gravity used to turn masses into weights (m/s^2), the same value as the ballistic payload model.
GRAVITY: float = 9.81

#: A finite number > 0 (most primitives).
Positive = Annotated[Real, Field(gt=0.0)]
#: A finite number >= 0 (``k``, ``d0``).
NonNegative = Annotated[Real, Field(ge=0.0)]


@config("RotorParams")
class RotorParams:
    """Primitive rotorcraft constants of the Zeng-Xu-Zhang model (defaults: the paper's table).

    Attributes:
        delta: Profile drag coefficient of the blades.
        rho: Air density (kg/m^3).
        s: Rotor solidity (blade area / disc area).
        A: Rotor disc area (m^2).
        omega: Blade angular velocity (rad/s).
        R: Rotor radius (m).
        k: Incremental correction factor of the induced power.
        W: Reference weight (N) of the empty aircraft; ``mass_kg = W / GRAVITY``.
        d0: Fuselage drag ratio.
    """

    delta: Positive = 0.012
    rho: Positive = 1.225
    s: Positive = 0.05
    A: Positive = 0.503
    omega: Positive = 300.0
    R: Positive = 0.4
    k: NonNegative = 0.1
    W: Positive = 20.0
    d0: NonNegative = 0.6

    @property
    def P0(self) -> float:
        """Blade profile power in hover (W): ``delta/8 rho s A Omega^3 R^3``."""
        return self.delta / 8.0 * self.rho * self.s * self.A * (self.omega * self.R) ** 3

    @property
    def Pi(self) -> float:
        """Induced power in hover at the reference weight (W): ``(1 + k) W^1.5 / sqrt(2 rho A)``."""
        return float(induced_power(self.W, self))

    @property
    def U_tip(self) -> float:
        """Rotor blade tip speed (m/s): ``Omega R``."""
        return self.omega * self.R

    @property
    def v0(self) -> float:
        """Mean rotor induced velocity in hover at the reference weight (m/s): ``sqrt(W / (2 rho A))``."""
        return float(induced_velocity(self.W, self))

    @property
    def mass_kg(self) -> float:
        """Mass of the empty aircraft (kg) implied by the reference weight."""
        return self.W / GRAVITY


@config("BatteryParams")
class BatteryParams:
    """Battery capacity and the reserve kept for the return to base.

    Defaults: a DJI Phantom 4 Pro class pack, 89.2 Wh (about 321 kJ), with a 20 % reserve.

    Attributes:
        capacity_j: Energy of a full battery (J, > 0).
        reserve_frac: Fraction of the capacity that must be left on landing, in ``[0, 1)``.
    """

    capacity_j: Positive = 321_000.0
    reserve_frac: Annotated[Real, Field(ge=0.0, lt=1.0)] = 0.2

    @property
    def reserve_j(self) -> float:
        """Energy that must remain at the end of the mission (J)."""
        return self.capacity_j * self.reserve_frac

    @property
    def usable_j(self) -> float:
        """Energy available for the mission before the reserve is touched (J)."""
        return self.capacity_j - self.reserve_j


DEFAULT_ROTOR = RotorParams()
DEFAULT_BATTERY = BatteryParams()


def induced_power(weight_N: ArrayLike, params: RotorParams = DEFAULT_ROTOR) -> NDArray[np.float64]:
    """Induced power in hover ``Pi(W) = (1 + k) W^1.5 / sqrt(2 rho A)`` (W).

    Args:
        weight_N: Total weights in newtons (any shape, > 0).
        params: Rotor constants.

    Returns:
        Array of the shape of ``weight_N``.
    """
    w = np.asarray(weight_N, dtype=np.float64)
    return (1.0 + params.k) * w**1.5 / math.sqrt(2.0 * params.rho * params.A)


def induced_velocity(weight_N: ArrayLike, params: RotorParams = DEFAULT_ROTOR) -> NDArray[np.float64]:
    """Mean rotor induced velocity in hover ``v0(W) = sqrt(W / (2 rho A))`` (m/s).

    Args:
        weight_N: Total weights in newtons (any shape, > 0).
        params: Rotor constants.

    Returns:
        Array of the shape of ``weight_N``.
    """
    return np.sqrt(np.asarray(weight_N, dtype=np.float64) / (2.0 * params.rho * params.A))


def power(
    v: ArrayLike,
    weight_N: ArrayLike | None = None,
    *,
    vz: ArrayLike | None = None,
    params: RotorParams = DEFAULT_ROTOR,
) -> NDArray[np.float64]:
    """Propulsion power at horizontal speed ``v`` (W), with the payload effect and the climb term.

    Args:
        v: Horizontal airspeeds in m/s, shape ``(n,)`` (any shape broadcasting with the others; sign ignored).
        weight_N: Current total weights in newtons (airframe plus payload on board), broadcast against ``v``;
            ``None`` uses the reference weight ``params.W``.
        vz: Vertical speeds in m/s (z up), broadcast against ``v``; only climbing (``vz > 0``) costs
            ``W vz``. ``None`` means level flight.
        params: Rotor constants.

    Returns:
        Power in watts, the broadcast shape of the inputs.

    Raises:
        ValueError: If a weight is not finite and > 0.
    """
    speed = np.abs(np.asarray(v, dtype=np.float64))
    w = np.asarray(params.W if weight_N is None else weight_N, dtype=np.float64)
    if w.size and not (np.all(np.isfinite(w)) and w.min() > 0.0):
        raise ValueError("weight_N must contain finite weights > 0 (newtons)")
    v0 = induced_velocity(w, params)
    a = speed * speed / (2.0 * v0 * v0)
    # sqrt(1 + a^2) - a cancels catastrophically at high speed; 1 / (sqrt(1 + a^2) + a) is the same value.
    induced = induced_power(w, params) * np.sqrt(1.0 / (np.sqrt(1.0 + a * a) + a))
    profile = params.P0 * (1.0 + 3.0 * speed * speed / (params.U_tip * params.U_tip))
    parasite = 0.5 * params.d0 * params.rho * params.s * params.A * speed**3
    out = profile + induced + parasite
    if vz is not None:
        out = out + w * np.maximum(np.asarray(vz, dtype=np.float64), 0.0)
    return out


def energy_step(vel: ArrayLike, mass: ArrayLike, dt: float, params: RotorParams = DEFAULT_ROTOR) -> NDArray[np.float64]:
    """Energy spent by each UAV over one step of constant velocity (J).

    The horizontal speed ``hypot(vx, vy)`` sets the forward-flight power and ``vz`` the climb term.

    Args:
        vel: Velocities ``(n, 3)`` in m/s (z up).
        mass: Current total masses ``(n,)`` in kg (airframe plus the sensors still on board; the airframe of
            the default rotor is ``params.mass_kg`` = 2.04 kg).
        dt: Step length in seconds (>= 0).
        params: Rotor constants.

    Returns:
        Energies ``(n,)`` in joules.

    Raises:
        ValueError: On bad shapes, a negative ``dt`` or a non-positive mass.
    """
    vel_arr = np.asarray(vel, dtype=np.float64)
    mass_arr = np.asarray(mass, dtype=np.float64)
    if vel_arr.ndim != 2 or vel_arr.shape[1] != 3:
        raise ValueError(f"vel must have shape (n, 3), got {vel_arr.shape}")
    if mass_arr.shape != (vel_arr.shape[0],):
        raise ValueError(f"mass must have shape ({vel_arr.shape[0]},), got {mass_arr.shape}")
    check_float("dt", dt, 0.0)
    speed = np.hypot(vel_arr[:, 0], vel_arr[:, 1])
    return power(speed, mass_arr * GRAVITY, vz=vel_arr[:, 2], params=params) * dt


def energy_per_metre(
    v: ArrayLike,
    weight_N: ArrayLike | None = None,
    params: RotorParams = DEFAULT_ROTOR,
) -> NDArray[np.float64]:
    """Energy per metre flown in level flight, ``P(V) / V`` (J/m; infinite in hover).

    Args:
        v: Horizontal speeds in m/s (any shape).
        weight_N: Total weights in newtons, or ``None`` for ``params.W``.
        params: Rotor constants.

    Returns:
        Array of the broadcast shape.
    """
    speed = np.abs(np.asarray(v, dtype=np.float64))
    with np.errstate(divide="ignore"):
        return power(speed, weight_N, params=params) / speed


def _check_weight(weight_N: float | None, params: RotorParams) -> float:
    """Resolve and validate a scalar weight for the speed optimisers."""
    w = params.W if weight_N is None else weight_N
    check_float("weight_N", w, 0.0, lo_open=True)
    return float(w)


def _argmin_speed(f: Callable[[float], float], lo: float, v_max: float) -> float:
    """Speed in ``[lo, v_max]`` minimising ``f`` (bounded scalar search to 1e-6 m/s)."""
    check_float("v_max", v_max, 0.0, lo_open=True)
    res = minimize_scalar(f, bounds=(lo, v_max), method="bounded", options={"xatol": 1e-6})
    return float(res.x)


def min_power_speed(
    weight_N: float | None = None,
    params: RotorParams = DEFAULT_ROTOR,
    v_max: float = 40.0,
) -> float:
    """Speed of minimum power (maximum endurance), by bounded numeric minimisation of ``P(V)``.

    Args:
        weight_N: Total weight in newtons, or ``None`` for ``params.W`` (about 10.2 m/s there).
        params: Rotor constants.
        v_max: Upper end of the search interval (m/s).

    Returns:
        The optimal horizontal speed in m/s.
    """
    w = _check_weight(weight_N, params)
    return _argmin_speed(lambda x: float(power(x, w, params=params)), 0.0, v_max)


def max_range_speed(
    weight_N: float | None = None,
    params: RotorParams = DEFAULT_ROTOR,
    v_max: float = 40.0,
) -> float:
    """Speed of maximum range (minimum energy per metre), by bounded numeric minimisation of ``P(V) / V``.

    Args:
        weight_N: Total weight in newtons, or ``None`` for ``params.W`` (about 18.3 m/s there).
        params: Rotor constants.
        v_max: Upper end of the search interval (m/s).

    Returns:
        The optimal horizontal speed in m/s.
    """
    w = _check_weight(weight_N, params)
    # P(V) / V diverges at V = 0, so the search starts just above it; the optimum lies well beyond v0.
    return _argmin_speed(lambda x: float(energy_per_metre(x, w, params)), 1e-3, v_max)
