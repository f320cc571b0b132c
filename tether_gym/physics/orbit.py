"""Kepler-orbit terms of the reel dynamics: the one copy of each formula.

Sign conventions: the true anomaly nu [rad] increases in the direction of motion and
is measured from perigee; it is *not* wrapped, so nu = 2 pi m is the start of orbit
m + 1.

With k = 1 + e cos(nu), the orbit radius is r = p / k and nu_dot = n k^2 with the
rate scale n = sqrt(mu / p^3) (paper Sec. 2); nu_ddot = -2 n^2 e sin(nu) k^3. For a
tether length L = L0 l(nu), differentiating twice in time gives
(docs/model.md, "Dimensionless variables")::

    L_dot  = L0 n k^2 l'                                  [m/s]
    L_ddot = L0 n^2 (k^4 l'' - 2 e sin(nu) k^3 l')        [m/s^2]

The functions below are compiled for the kernels and inlined there; as plain
arithmetic they also take numpy arrays (``func.py_func``), which is how
:class:`tether_gym.params.Scales` converts recorded trajectories to SI units.
"""

from __future__ import annotations

from numba import njit

from .jit import INLINE

__all__ = ["coriolis", "reel_accel", "ddlength_from_accel"]


@njit(**INLINE)
def coriolis(k, sin_nu, e, dlength):
    """2 e sin(nu) k^3 l' [-]: the part of L_ddot / (L0 n^2) that reeling at l' costs."""
    return 2.0 * e * sin_nu * (k * k) * k * dlength


@njit(**INLINE)
def reel_accel(k, sin_nu, e, dlength, ddlength):
    """Physical reel acceleration L_ddot / (L0 n^2) = k^4 l'' - 2 e sin(nu) k^3 l' [-]."""
    k2 = k * k
    return k2 * k2 * ddlength - coriolis(k, sin_nu, e, dlength)


@njit(**INLINE)
def ddlength_from_accel(k4, coriolis_term, accel):
    """l'' [-] from L_ddot / (L0 n^2) = ``accel`` (inverse of :func:`reel_accel`).

    ``k4`` = k^4 and ``coriolis_term`` = :func:`coriolis` at the same state.
    """
    return (accel + coriolis_term) / k4
