"""Reel actuators: commanded reel rate -> actual l', l'' under physical limits.

Each tether has a reel whose rate l' follows the command l'_cmd as a first-order lag
with time constant tau [rad] (tau -> 0 is the paper's ideal reel, whose l'' it forms
by a backward difference over one step). The reel's physical acceleration
L_ddot = L0 n^2 (k^4 l'' - 2 e sin(nu) k^3 l') [m/s^2] is saturated at +-a_max
(paper Sec. 4.3: 0.01 m/s^2 per tether), and the command is clipped to an optional
speed limit |L_dot| = L0 n k^2 |l'| <= v_max [m/s]. The law itself is
:func:`tether_gym.physics.kernels.reel_ddlength`, evaluated inside the integrator at
every Runge-Kutta stage, so the saturation holds along the whole trajectory.
"""

from __future__ import annotations

import math

import numpy as np

from ..params import OrbitParams, ReelParams, check_range
from . import kernels, orbit

__all__ = ["ReelActuator", "lengths_within"]


class ReelActuator:
    """The reels of a chain, with their limits made dimensionless for one orbit.

    Parameters
    ----------
    orbit_params : OrbitParams
        Gives e and n = sqrt(mu / p^3).
    total_tether_length : float
        L0 [m].
    reel : ReelParams
        Acceleration limit [m/s^2], speed limit [m/s] and time constant [rad].

    Attributes
    ----------
    accel_bound : float
        a_max / (L0 n^2) [-] (inf without a limit); 0.776 for the paper's case.
    speed_bound : float
        v_max / (L0 n) [-] (inf without a limit).
    """

    def __init__(self, orbit_params: OrbitParams, total_tether_length: float,
                 reel: ReelParams | None = None):
        reel = ReelParams() if reel is None else reel
        self.orbit = orbit_params
        self.reel = reel
        self.L0 = check_range("total_tether_length", total_tether_length, 0.0, low_open=True)
        n = orbit_params.rate_scale
        self.rate_scale = n
        inf = math.inf
        self.accel_bound = inf if reel.accel_limit is None else reel.accel_limit / (self.L0 * n**2)
        self.speed_bound = inf if reel.speed_limit is None else reel.speed_limit / (self.L0 * n)
        self.time_constant = reel.time_constant

    def ddlength(self, nu, dlength, command):
        """l'' [-] the reels produce at (nu, l') under the command l'_cmd [-]."""
        dl = np.atleast_2d(np.asarray(dlength, dtype=float))
        cmd = np.broadcast_to(np.asarray(command, dtype=float), dl.shape)
        nu_b = np.broadcast_to(np.asarray(nu, dtype=float), dl.shape[:1])
        out = np.empty_like(dl)
        par = kernels.pack_params(self.orbit.eccentricity, np.ones(dl.shape[1]),
                                  accel_bound=self.accel_bound, speed_bound=self.speed_bound,
                                  time_constant=self.time_constant)[None]
        kernels.reel_batch(np.ascontiguousarray(nu_b), np.ascontiguousarray(dl),
                           np.ascontiguousarray(cmd), par, out)
        return out.reshape(np.shape(dlength))

    def physical_accel(self, nu, dlength, ddlength):
        """L_ddot [m/s^2] of each reel."""
        nu_a = np.asarray(nu, dtype=float)[..., None] if np.ndim(dlength) > np.ndim(nu) else nu
        return orbit.reel_accel_to_physical(nu_a, dlength, ddlength, self.orbit.eccentricity,
                                            self.rate_scale, self.L0)

    def physical_rate(self, nu, dlength):
        """L_dot [m/s] of each reel."""
        nu_a = np.asarray(nu, dtype=float)[..., None] if np.ndim(dlength) > np.ndim(nu) else nu
        return orbit.reel_rate_to_physical(nu_a, dlength, self.orbit.eccentricity,
                                           self.rate_scale, self.L0)


def lengths_within(length, low, high):
    """True where every l_i lies in [low, high] (checked along the last axis)."""
    length = np.asarray(length)
    return np.all((length >= low) & (length <= high), axis=-1)
