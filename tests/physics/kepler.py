"""Kepler's equation as a time <-> true anomaly map (a reference for the tests only).

The package works in true anomaly throughout; the tests use this map to check
formulas stated per second (reel rates and accelerations, the reel limits) against
finite differences in time.
"""

from __future__ import annotations

import numpy as np


def _mean_motion(e, n):
    # Keplerian mean motion sqrt(mu / a^3) with a = p / (1 - e^2) and n = sqrt(mu / p^3).
    return n * (1.0 - e**2) ** 1.5


def time_from_true_anomaly(nu, e, n, nu0=0.0):
    """Time [s] from true anomaly ``nu0`` to ``nu`` [rad] (both unwrapped), any number of orbits."""

    def mean_anomaly(v):
        v = np.asarray(v, dtype=float)
        revs = np.round(v / (2.0 * np.pi))
        v0 = v - 2.0 * np.pi * revs
        ecc_anom = 2.0 * np.arctan2(np.sqrt(1.0 - e) * np.sin(v0 / 2),
                                    np.sqrt(1.0 + e) * np.cos(v0 / 2))
        return ecc_anom - e * np.sin(ecc_anom) + 2.0 * np.pi * revs

    return (mean_anomaly(nu) - mean_anomaly(nu0)) / _mean_motion(e, n)


def true_anomaly_from_time(t, e, n, nu0=0.0):
    """Unwrapped true anomaly [rad] a time ``t`` [s] after ``nu0`` (Newton on Kepler's equation)."""
    t0 = time_from_true_anomaly(nu0, e, n, 0.0)
    mean = _mean_motion(e, n) * (np.asarray(t, dtype=float) + t0)
    revs = np.round(mean / (2.0 * np.pi))
    m0 = mean - 2.0 * np.pi * revs
    ecc_anom = m0 + e * np.sin(m0)
    for _ in range(50):
        delta = (ecc_anom - e * np.sin(ecc_anom) - m0) / (1.0 - e * np.cos(ecc_anom))
        ecc_anom = ecc_anom - delta
        if np.all(np.abs(delta) < 1e-15):
            break
    v0 = 2.0 * np.arctan2(np.sqrt(1.0 + e) * np.sin(ecc_anom / 2),
                          np.sqrt(1.0 - e) * np.cos(ecc_anom / 2))
    return v0 + 2.0 * np.pi * revs
