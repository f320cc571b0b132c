"""Per-episode metrics of a libration-tracking rollout, and their aggregation.

An episode is recorded as the env's ``info`` dicts after every step. Definitions
(n tethers, steps k, true anomaly nu_k, one orbit = 2 pi rad):

* ``tracking_rms`` [rad]: RMS of theta_i - theta_d over all tethers and the steps
  after the first orbit (NaN if the episode ended before it).
* ``final_error`` [rad]: max |theta_i - theta_d| over the last orbit of the episode.
* ``converge_orbits`` [orbits]: :func:`convergence_orbits` of max_i |theta_i - theta_d|:
  the first sample of the final run of samples below 1e-3 rad (NaN if never or
  after a failure).
* ``reel_effort`` [-]: integral of sum_i |l_i'| d nu over the episode.
* ``reel_excursion`` [-]: max over tethers of (max l_i - min l_i).
* ``min_tension`` [-]: smallest T^_i at any physics substep boundary.
* ``slack``, ``tumble``, ``length``: 1 if the episode ended for that reason.
* ``success``: 1 if it ran to the time limit without failure.
* ``chattering`` [-]: total variation of the reel rates, sum_k sum_i |l_i'(k) - l_i'(k-1)|.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

__all__ = ["episode_metrics", "aggregate", "convergence_orbits", "METRICS", "CONVERGENCE_TOL"]

CONVERGENCE_TOL = 1e-3
"""Tracking tolerance of the convergence time [rad]."""
METRICS = ("tracking_rms", "final_error", "converge_orbits", "reel_effort", "reel_excursion",
           "min_tension", "slack", "tumble", "length", "success", "chattering", "return")


def convergence_orbits(orbits: np.ndarray, error: np.ndarray,
                       tol: float = CONVERGENCE_TOL) -> float | None:
    """First time [orbits] after which ``error`` stays below ``tol``; None if never.

    The time is that of the first sample of the final run of samples below ``tol``.
    """
    error = np.asarray(error, dtype=float)
    above = np.nonzero(~(error < tol))[0]
    if above.size == 0:
        return float(orbits[0])
    if above[-1] == error.shape[0] - 1:
        return None
    return float(orbits[above[-1] + 1])


def episode_metrics(infos: list[dict], rewards: list[float], nu0: float, control_step: float,
                    truncated: bool) -> dict:
    """Metrics of one episode from its per-step infos (see the module docstring)."""
    nu = np.array([i["nu"] for i in infos]) - nu0
    theta = np.array([i["theta"] for i in infos])
    ref = np.array([i["theta_ref"] for i in infos])
    err = theta - ref[:, None]
    dl = np.array([i["dlength"] for i in infos])
    length = np.array([i["length"] for i in infos])
    tmin = np.array([i["tension_min"] for i in infos])
    failure = infos[-1]["failure"]
    orbit = 2.0 * math.pi
    after = nu > orbit + 1e-9
    maxerr = np.abs(err).max(axis=1)
    last = nu > nu[-1] - orbit
    converge = None if failure is not None else convergence_orbits(nu / orbit, maxerr)
    return {
        "tracking_rms": float(np.sqrt(np.mean(err[after] ** 2))) if after.any() else math.nan,
        "final_error": float(maxerr[last].max()),
        "converge_orbits": math.nan if converge is None else converge,
        "reel_effort": float(np.abs(dl).sum() * control_step),
        "reel_excursion": float((length.max(axis=0) - length.min(axis=0)).max()),
        "min_tension": float(tmin.min()),
        "slack": float(failure == "slack"),
        "tumble": float(failure == "tumble"),
        "length": float(failure == "length"),
        "success": float(failure is None and truncated),
        "chattering": float(np.abs(np.diff(dl, axis=0)).sum()),
        "return": float(np.sum(rewards)),
    }


def aggregate(episodes: list[dict]) -> dict:
    """Mean and 95 % confidence half-width (Student t) of each metric over episodes.

    NaN entries (a metric undefined for an episode) are left out of that metric;
    ``<metric>_n`` counts the episodes used.
    """
    out = {}
    for key in METRICS:
        values = np.array([e[key] for e in episodes], dtype=float)
        values = values[np.isfinite(values)]
        n = values.size
        mean = float(values.mean()) if n else math.nan
        half = (float(stats.t.ppf(0.975, n - 1) * values.std(ddof=1) / math.sqrt(n))
                if n > 1 else (0.0 if n == 1 else math.nan))
        out[key] = mean
        out[f"{key}_ci95"] = half
        out[f"{key}_n"] = n
    return out
