"""Radial sensor-density profiles over a circular hot zone.

A profile is a probability density over the *area* of a disc of radius ``R`` centred on the zone's
centroid, radially symmetric, written as a function of the distance ``r`` from the centre. It is
normalised so that ``integral_0^R 2 pi r density(r) dr = 1``: multiply by the number of sensors ``N``
to get the expected areal density (sensors per square metre). The radial CDF
``F(r) = integral_0^r 2 pi s density(s) ds`` is the fraction of sensors within ``r``; sampling uses
``r = F^-1(u)`` with ``u ~ U(0, 1)`` and an independent uniform angle.

Kinds (``x = r / R``):

========= ========================= ===================================================
kind      density proportional to   radial CDF ``F``
========= ========================= ===================================================
uniform   1                         ``x^2``
power     ``r^-alpha``, 0<=alpha<2  ``x^(2 - alpha)`` (alpha = 1 is "R-random")
gauss     ``exp(-r^2 / 2 sigma^2)`` ``(1 - exp(-r^2/2s^2)) / (1 - exp(-R^2/2s^2))``
linear    ``1 - r / R`` (cone)      ``3 x^2 - 2 x^3``
========= ========================= ===================================================

A ``floor`` ``eta`` mixes the profile with the uniform one *by mass*: ``(1 - eta) * profile + eta *
uniform``, a connectivity safeguard that keeps the rim populated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["GOLDEN_ANGLE", "PROFILE_KINDS", "RadialProfile"]

PROFILE_KINDS: tuple[str, ...] = ("uniform", "power", "gauss", "linear")

#: Golden angle in radians, ``pi * (3 - sqrt(5))``: consecutive sunflower points never line up.
GOLDEN_ANGLE: float = 2.39996322972865

# Bisection steps for a floor mixture: 60 halvings of [0, 1] leave an interval below 1e-18, and every
# element converges in the same fixed number of vectorised passes.
_BISECTION_STEPS = 60


@dataclass(frozen=True)
class RadialProfile:
    """A radially symmetric areal density over a disc of radius ``radius``.

    Attributes:
        kind: One of ``PROFILE_KINDS``.
        radius: Disc radius ``R`` in metres (> 0).
        alpha: Power-law exponent, ``0 <= alpha < 2`` (used by ``"power"`` only).
        sigma: Gaussian width in metres (> 0); ``None`` means ``radius / 2``. For ``"gauss"`` the
            default is resolved at construction, so ``profile.sigma`` is always a float there.
        floor: Uniform mixture weight ``eta`` in ``[0, 1)``, by mass.
    """

    kind: str
    radius: float
    alpha: float = 1.0
    sigma: float | None = None
    floor: float = 0.0

    def __post_init__(self) -> None:
        """Validate the fields and resolve the default Gaussian width."""
        if self.kind not in PROFILE_KINDS:
            raise ValueError(f"kind must be one of {PROFILE_KINDS}, got {self.kind!r}")
        if not (math.isfinite(self.radius) and self.radius > 0.0):
            raise ValueError(f"radius must be a finite number > 0, got {self.radius!r}")
        if not (math.isfinite(self.alpha) and 0.0 <= self.alpha < 2.0):
            raise ValueError(f"alpha must satisfy 0 <= alpha < 2, got {self.alpha!r}")
        if self.sigma is not None and not (math.isfinite(self.sigma) and self.sigma > 0.0):
            raise ValueError(f"sigma must be None or a finite number > 0, got {self.sigma!r}")
        if not (math.isfinite(self.floor) and 0.0 <= self.floor < 1.0):
            raise ValueError(f"floor must satisfy 0 <= floor < 1, got {self.floor!r}")
        if self.kind == "gauss" and self.sigma is None:
            # Frozen dataclass: resolve the documented default once so that equal profiles compare equal.
            object.__setattr__(self, "sigma", 0.5 * float(self.radius))

    # ------------------------------------------------------------------ shape of the pure profile
    def _pure_density_x(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Density of the pure profile (no floor) at ``x = r / R`` in [0, 1], in units of 1 / R^2."""
        if self.kind == "uniform":
            return np.full_like(x, 1.0 / math.pi)
        if self.kind == "power":
            a = self.alpha
            if a == 0.0:
                return np.full_like(x, 1.0 / math.pi)
            with np.errstate(divide="ignore"):
                return (2.0 - a) / (2.0 * math.pi) * np.power(x, -a)
        if self.kind == "gauss":
            s = float(self.sigma) / self.radius  # type: ignore[arg-type]
            # 2 pi s^2 (1 - exp(-1 / 2 s^2)) is the mass of exp(-x^2 / 2 s^2) over the unit disc.
            norm = -2.0 * math.pi * s * s * math.expm1(-0.5 / (s * s))
            return np.exp(-0.5 * (x / s) ** 2) / norm
        return 3.0 / math.pi * (1.0 - x)  # linear cone: mass of (1 - x) over the unit disc is pi / 3

    def _pure_cdf_x(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Radial CDF of the pure profile at ``x = r / R`` in [0, 1]."""
        if self.kind == "uniform":
            return x * x
        if self.kind == "power":
            return np.power(x, 2.0 - self.alpha)
        if self.kind == "gauss":
            s = float(self.sigma) / self.radius  # type: ignore[arg-type]
            # expm1 keeps full precision when sigma >> R (nearly uniform) and near x = 0.
            # Clipped because rounding can put F(R) one ulp above 1.
            return np.minimum(np.expm1(-0.5 * (x / s) ** 2) / math.expm1(-0.5 / (s * s)), 1.0)
        return x * x * (3.0 - 2.0 * x)

    def _pure_inverse_x(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """Closed-form inverse of the pure profile's radial CDF, returning ``x = r / R``."""
        if self.kind == "uniform":
            return np.sqrt(u)
        if self.kind == "power":
            return np.power(u, 1.0 / (2.0 - self.alpha))
        if self.kind == "gauss":
            s = float(self.sigma) / self.radius  # type: ignore[arg-type]
            with np.errstate(divide="ignore"):  # u = 1 with a tiny sigma gives log(0) -> x = inf -> 1
                x = s * np.sqrt(-2.0 * np.log1p(u * math.expm1(-0.5 / (s * s))))
            return np.minimum(x, 1.0)
        # 3x^2 - 2x^3 = u is the smoothstep cubic; its root in [0, 1] is 1/2 - sin(asin(1 - 2u) / 3).
        # Rewritten as a product, with b = (2/3) asin(sqrt(u)), so that it does not cancel near u = 0.
        b = (2.0 / 3.0) * np.arcsin(np.sqrt(u))
        return np.clip(2.0 * np.cos(math.pi / 6.0 - 0.5 * b) * np.sin(0.5 * b), 0.0, 1.0)

    # ------------------------------------------------------------------ public API
    def density(self, r: ArrayLike) -> NDArray[np.float64]:
        """Areal probability density at distance ``r`` from the centre (per square metre).

        Args:
            r: Distances in metres (any shape). Outside ``[0, radius]`` the density is 0. A power
                profile with ``alpha > 0`` is infinite at ``r = 0`` (an integrable singularity).

        Returns:
            Array of the same shape as ``r`` (0-d for a scalar).
        """
        r_arr = np.asarray(r, dtype=np.float64)
        x = r_arr / self.radius
        inside = (x >= 0.0) & (x <= 1.0)
        xc = np.clip(x, 0.0, 1.0)
        d = (1.0 - self.floor) * self._pure_density_x(xc) + self.floor / math.pi
        out = np.where(inside, d, 0.0) / (self.radius * self.radius)
        return out[()] if out.ndim == 0 else out

    def cdf(self, r: ArrayLike) -> NDArray[np.float64]:
        """Radial CDF: fraction of the mass within distance ``r`` (0 below 0, 1 beyond ``radius``).

        Args:
            r: Distances in metres (any shape).

        Returns:
            Array of the same shape as ``r`` with values in [0, 1].
        """
        x = np.clip(np.asarray(r, dtype=np.float64) / self.radius, 0.0, 1.0)
        out = self._cdf_x(x)
        return out[()] if out.ndim == 0 else out

    def _cdf_x(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Radial CDF of the (floored) profile at ``x = r / R`` in [0, 1]."""
        if self.floor == 0.0:
            return self._pure_cdf_x(x)
        return (1.0 - self.floor) * self._pure_cdf_x(x) + self.floor * x * x

    def inverse_cdf(self, u: ArrayLike) -> NDArray[np.float64]:
        """Radius below which a fraction ``u`` of the mass lies.

        Closed form for every pure kind; a floor mixture has none, so it is inverted by a vectorised
        bisection that is exact to float64 rounding (the CDF is strictly increasing).

        Args:
            u: Probabilities in [0, 1] (any shape).

        Returns:
            Radii in metres, same shape as ``u``.

        Raises:
            ValueError: If any ``u`` is outside [0, 1] or not finite.
        """
        u_arr = np.asarray(u, dtype=np.float64)
        if u_arr.size and not (np.all(np.isfinite(u_arr)) and u_arr.min() >= 0.0 and u_arr.max() <= 1.0):
            raise ValueError("u must contain finite probabilities in [0, 1]")
        if self.floor == 0.0:
            x = self._pure_inverse_x(u_arr)
        else:
            x = self._mixture_inverse_x(u_arr)
        out = x * self.radius
        return out[()] if out.ndim == 0 else out

    def _mixture_inverse_x(self, u: NDArray[np.float64]) -> NDArray[np.float64]:
        """Invert the floored CDF ``G(x) = (1 - eta) F(x) + eta x^2`` numerically (exact to rounding).

        Two bisection phases, because neither variable alone resolves every kind. Phase one runs on
        ``p = F(x)`` (the pure profile's CDF): a steep power law puts u = 1e-3 at x ~ 1e-30, far below
        any fixed resolution in ``x``, while ``G`` has slope >= 1 - eta in ``p``. But ``p`` saturates
        at 1 in a narrow Gaussian's tail, where the floor alone sets ``G``; so phase two bisects in
        ``x`` inside the bracket that phase one found.
        """
        eta = self.floor
        lo = np.zeros_like(u)
        hi = np.minimum(u / (1.0 - eta), 1.0)  # G(p) >= (1 - eta) p bounds the root from above
        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            below = self._cdf_x(self._pure_inverse_x(mid)) < u
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        lo = self._pure_inverse_x(lo)
        hi = np.maximum(self._pure_inverse_x(hi), lo)
        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            below = self._cdf_x(mid) < u
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        return 0.5 * (lo + hi)

    def sample(self, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """Draw ``n`` independent points from the profile.

        Args:
            n: Number of points (>= 0).
            rng: Random generator (consumes ``n`` radii then ``n`` angles).

        Returns:
            ``(n, 2)`` offsets from the zone centre in metres.
        """
        n = _check_count(n)
        u = rng.random(n)
        theta = rng.random(n) * (2.0 * math.pi)
        return _polar(self.inverse_cdf(u), theta)

    def low_discrepancy(self, n: int, indices: ArrayLike | None = None) -> NDArray[np.float64]:
        """Deterministic sunflower (Vogel spiral) set that follows the profile exactly.

        Radii come from the quantiles ``u_i = (i - 1/2) / n`` and angles are ``theta_i = i *
        GOLDEN_ANGLE`` for ``i = 1..n``, so points are evenly spread and the radial CDF of the set
        matches ``cdf`` to within ``1 / (2n)``.

        Args:
            n: Number of points (>= 0).
            indices: Only these points of the set (0-based, in ``0..n-1``), e.g. a thinned preview of a large
                set without computing the rest; None: all ``n``.

        Returns:
            ``(n, 2)`` offsets from the zone centre in metres (``(len(indices), 2)`` with ``indices``).
        """
        n = _check_count(n)
        i = np.arange(n, dtype=np.float64) if indices is None else np.asarray(indices, dtype=np.float64)
        i = i + 1.0
        return _polar(self.inverse_cdf((i - 0.5) / max(n, 1)), i * GOLDEN_ANGLE)

    def mass_between(self, r0: ArrayLike, r1: ArrayLike) -> NDArray[np.float64]:
        """Fraction of the mass in the annulus ``r0 <= r < r1`` (``cdf(r1) - cdf(r0)``).

        Args:
            r0: Inner radii in metres.
            r1: Outer radii in metres (broadcast against ``r0``).

        Returns:
            Broadcast array of masses (negative where ``r1 < r0``).
        """
        return np.asarray(self.cdf(r1)) - np.asarray(self.cdf(r0))


def _check_count(n: int) -> int:
    """Validate a point count."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"n must be an integer >= 0, got {n!r}")
    return int(n)


def _polar(r: NDArray[np.float64], theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Stack polar coordinates into ``(n, 2)`` Cartesian offsets."""
    out = np.empty((r.shape[0], 2), dtype=np.float64)
    out[:, 0] = r * np.cos(theta)
    out[:, 1] = r * np.sin(theta)
    return out
