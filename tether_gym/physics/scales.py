"""The characteristic scales of a chain on its orbit (poliastro's ``SystemChars`` style).

The numerical core is dimensionless (docs/model.md, "Dimensionless variables"); SI
units enter and leave only through :class:`Scales`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params import Gravity, OrbitParams, ReelParams, check_range
from .orbit import reel_accel
from .state import pack_params, tail_masses

__all__ = ["Scales"]


@dataclass(frozen=True)
class Scales:
    """Characteristic scales of a chain on its orbit: the one SI <-> dimensionless map.

    Parameters
    ----------
    orbit : OrbitParams
        Gives the rate scale n = sqrt(mu / p^3) [rad/s] and p [m].
    total_tether_length : float
        L0 [m], the length scale, > 0.

    Notes
    -----
    Lengths scale with L0, time derivatives with nu_dot = n k^2 (k = 1 + e cos nu):
    L_dot = L0 n k^2 l' and L_ddot = L0 n^2 (k^4 l'' - 2 e sin(nu) k^3 l')
    (:func:`tether_gym.physics.orbit.reel_accel`), so the reel limits become
    a_max / (L0 n^2) and v_max / (L0 n) (k^2 |l'| <= v_max / (L0 n)).
    """

    orbit: OrbitParams
    total_tether_length: float

    def __post_init__(self) -> None:
        check_range("total_tether_length", self.total_tether_length, 0.0, low_open=True)

    @property
    def rate(self) -> float:
        """n = sqrt(mu / p^3) [rad/s]."""
        return self.orbit.rate_scale

    @property
    def speed(self) -> float:
        """L0 n [m/s]: reel speed per unit of k^2 l'."""
        return self.total_tether_length * self.rate

    @property
    def accel(self) -> float:
        """L0 n^2 [m/s^2]: reel acceleration per unit of k^4 l'' - 2 e sin(nu) k^3 l'."""
        return self.total_tether_length * self.rate**2

    @property
    def length_ratio(self) -> float:
        """L0 / p [-] (enters the full gravity model only)."""
        return self.total_tether_length / self.orbit.semi_latus_rectum

    def accel_bound(self, accel_limit: float | None) -> float:
        """a_max / (L0 n^2) [-] for a reel acceleration limit [m/s^2]; inf for None."""
        return math.inf if accel_limit is None else accel_limit / self.accel

    def speed_bound(self, speed_limit: float | None) -> float:
        """v_max / (L0 n) [-] for a reel speed limit [m/s]; inf for None."""
        return math.inf if speed_limit is None else speed_limit / self.speed

    def param_rows(self, eccentricity, masses, gravity: Gravity, reels: ReelParams) -> np.ndarray:
        """Kernel parameter rows (:data:`~tether_gym.physics.state.PARAMS`).

        ``eccentricity`` of shape (...,) and ``masses`` of shape (..., n) broadcast;
        the reel limits of ``reels`` are made dimensionless here.
        """
        return pack_params(eccentricity, tail_masses(masses), gravity, self.length_ratio,
                           self.accel_bound(reels.accel_limit),
                           self.speed_bound(reels.speed_limit), reels.time_constant)

    def nu_dot(self, nu, eccentricity):
        """d nu / dt = n k^2 [rad/s]."""
        k = 1.0 + eccentricity * np.cos(nu)
        return self.rate * k**2

    def reel_rate_si(self, nu, eccentricity, dlength):
        """L_dot [m/s] from l' [-] (``nu`` broadcasts against ``dlength``)."""
        return self.speed * self.nu_dot(nu, eccentricity) / self.rate * dlength

    def reel_accel_si(self, nu, eccentricity, dlength, ddlength):
        """L_ddot [m/s^2] from l' and l'' [-]."""
        k = 1.0 + eccentricity * np.cos(nu)
        return self.accel * reel_accel.py_func(k, np.sin(nu), eccentricity, dlength, ddlength)
