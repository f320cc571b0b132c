"""Keplerian orbit of the main satellite and the time <-> true anomaly maps.

Sign conventions: the true anomaly nu [rad] increases in the direction of motion and
is measured from perigee; it is *not* wrapped, so nu = 2 pi m is the start of orbit
m + 1. All functions broadcast over numpy arrays.

Relations (paper Sec. 2; shared/paper/NOTES.md):

* k = 1 + e cos(nu),  r = p / k
* n = sqrt(mu / p^3)  (the rate scale; not the Keplerian mean motion)
* nu_dot = n k^2,  nu_ddot = -2 n^2 e sin(nu) k^3
* for any q(nu):  q_dot = nu_dot q',  q_ddot = nu_dot^2 q'' + nu_ddot q'

Reel conversions follow from L = L0 l(nu):

* L_dot  = L0 n k^2 l'                                  [m/s]
* L_ddot = L0 n^2 (k^4 l'' - 2 e sin(nu) k^3 l')        [m/s^2]
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "k_factor",
    "radius",
    "rate_scale",
    "nu_dot",
    "nu_ddot",
    "time_from_true_anomaly",
    "true_anomaly_from_time",
    "reel_rate_to_physical",
    "reel_rate_from_physical",
    "reel_accel_to_physical",
    "reel_accel_from_physical",
]


def k_factor(nu, e):
    """k = 1 + e cos(nu) [-]."""
    return 1.0 + e * np.cos(nu)


def radius(nu, p, e):
    """Orbit radius r = p / k [same unit as p]."""
    return p / k_factor(nu, e)


def rate_scale(p, mu):
    """n = sqrt(mu / p^3) [rad/s]."""
    return np.sqrt(mu / np.asarray(p, dtype=float) ** 3)


def nu_dot(nu, e, n):
    """d nu / dt = n k^2 [rad/s]."""
    return n * k_factor(nu, e) ** 2


def nu_ddot(nu, e, n):
    """d^2 nu / dt^2 = -2 n^2 e sin(nu) k^3 [rad/s^2]."""
    return -2.0 * n**2 * e * np.sin(nu) * k_factor(nu, e) ** 3


def _mean_motion(e, n):
    # Keplerian mean motion sqrt(mu / a^3) with a = p / (1 - e^2).
    return n * (1.0 - e**2) ** 1.5


def time_from_true_anomaly(nu, e, n, nu0=0.0):
    """Time [s] taken to go from true anomaly ``nu0`` to ``nu`` [rad] (both unwrapped).

    Uses Kepler's equation M = E - e sin(E) per orbit, so it is exact for any number
    of revolutions.
    """

    def mean_anomaly(v):
        v = np.asarray(v, dtype=float)
        revs = np.round(v / (2.0 * np.pi))
        v0 = v - 2.0 * np.pi * revs
        ecc_anom = 2.0 * np.arctan2(np.sqrt(1.0 - e) * np.sin(v0 / 2),
                                    np.sqrt(1.0 + e) * np.cos(v0 / 2))
        return ecc_anom - e * np.sin(ecc_anom) + 2.0 * np.pi * revs

    return (mean_anomaly(nu) - mean_anomaly(nu0)) / _mean_motion(e, n)


def true_anomaly_from_time(t, e, n, nu0=0.0):
    """Unwrapped true anomaly [rad] reached a time ``t`` [s] after true anomaly ``nu0``.

    Solves Kepler's equation by Newton's method to machine precision.
    """
    t0 = time_from_true_anomaly(nu0, e, n, 0.0)
    mean = _mean_motion(e, n) * (np.asarray(t, dtype=float) + t0)
    revs = np.round(mean / (2.0 * np.pi))
    m0 = mean - 2.0 * np.pi * revs  # in [-pi, pi]
    ecc_anom = m0 + e * np.sin(m0)
    for _ in range(50):
        delta = (ecc_anom - e * np.sin(ecc_anom) - m0) / (1.0 - e * np.cos(ecc_anom))
        ecc_anom = ecc_anom - delta
        if np.all(np.abs(delta) < 1e-15):
            break
    v0 = 2.0 * np.arctan2(np.sqrt(1.0 + e) * np.sin(ecc_anom / 2),
                          np.sqrt(1.0 - e) * np.cos(ecc_anom / 2))
    return v0 + 2.0 * np.pi * revs


def reel_rate_to_physical(nu, dlength, e, n, L0):
    """Reel rate L_dot [m/s] from l' = dl/dnu [-]."""
    return L0 * n * k_factor(nu, e) ** 2 * dlength


def reel_rate_from_physical(nu, rate, e, n, L0):
    """l' [-] from the reel rate L_dot [m/s]."""
    return rate / (L0 * n * k_factor(nu, e) ** 2)


def reel_accel_to_physical(nu, dlength, ddlength, e, n, L0):
    """Reel acceleration L_ddot [m/s^2] from l' and l'' [-]."""
    k = k_factor(nu, e)
    return L0 * n**2 * (k**4 * ddlength - 2.0 * e * np.sin(nu) * k**3 * dlength)


def reel_accel_from_physical(nu, dlength, accel, e, n, L0):
    """l'' [-] from l' [-] and the reel acceleration L_ddot [m/s^2]."""
    k = k_factor(nu, e)
    return (accel / (L0 * n**2) + 2.0 * e * np.sin(nu) * k**3 * dlength) / k**4
