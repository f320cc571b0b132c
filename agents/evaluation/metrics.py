"""Per-episode metrics of a libration-tracking rollout: the one definition of each.

An episode is a :class:`~tether_gym_agents.evaluation.rollout.Trajectory` (row 0: the reset state;
rows 1..K: after every control step). Definitions (n tethers, steps k = 1..K, true
anomaly nu_k counted from the reset, one orbit = 2 pi rad), on the step rows:

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
* ``return`` [-]: sum of the rewards.
* ``filter_rate`` [-]: fraction of the steps whose action a safety filter changed; only
  for filtered policies (``traj.filter_active`` set), and not in :data:`METRICS`.

The benchmark (:mod:`tether_gym_agents.evaluation.benchmark`) and the paper reproduction
(:mod:`tether_gym_agents.paper`) both compute these from the same trajectories;
statistics over episodes and training runs are in :mod:`tether_gym_agents.evaluation.stats`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["episode_metrics", "convergence_orbits", "after_first_orbit", "METRICS",
           "HIGHER_IS_BETTER", "LOWER_IS_BETTER", "FAILURES", "CONVERGENCE_TOL"]

CONVERGENCE_TOL = 1e-3
"""Tracking tolerance of the convergence time [rad]."""
METRICS = ("tracking_rms", "final_error", "converge_orbits", "reel_effort", "reel_excursion",
           "min_tension", "slack", "tumble", "length", "success", "chattering", "return")
"""Every metric of :func:`episode_metrics`, in table order."""
HIGHER_IS_BETTER = frozenset({"success", "min_tension", "return"})
"""Metrics where a larger value is better (the probability of improvement counts a larger
value as the better one for these, a smaller one for all others)."""
LOWER_IS_BETTER = frozenset({"tracking_rms", "final_error", "converge_orbits", "reel_effort",
                             "reel_excursion", "slack", "tumble", "length", "chattering"})
"""Metrics where a smaller value is better. Every metric of :data:`METRICS` is in exactly
one of the two sets (a test checks it), so a new metric is classified on purpose."""
FAILURES = ("slack", "tumble", "length")
"""Failure metrics (1 when the episode ended for that reason)."""


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


def after_first_orbit(traj) -> np.ndarray:
    """Mask of the step rows (1..K) of ``traj`` that lie after the first orbit.

    The step after which nu - nu(0) > 2 pi (+ 1e-9 rad); used by ``tracking_rms`` here
    and by the paper table's "after orbit 1" numbers.
    """
    return traj.nu[1:] - traj.nu[0] > 2.0 * math.pi + 1e-9


def episode_metrics(traj) -> dict:
    """Metrics of one episode (see the module docstring).

    Parameters
    ----------
    traj : Trajectory
        The recorded episode (:func:`tether_gym_agents.evaluation.rollout.rollout`).

    Returns
    -------
    dict
        ``{metric: float}`` for every name in :data:`METRICS`, plus ``filter_rate`` for
        filtered policies; NaN where undefined.
    """
    orbit = 2.0 * math.pi
    nu = traj.nu[1:] - traj.nu[0]
    err = traj.theta[1:] - traj.theta_ref[1:, None]
    dl = traj.dlength[1:]
    length = traj.length[1:]
    failure = traj.failure
    after = after_first_orbit(traj)
    maxerr = np.abs(err).max(axis=1)
    last = nu > nu[-1] - orbit
    converge = None if failure is not None else convergence_orbits(nu / orbit, maxerr)
    out = {
        "tracking_rms": float(np.sqrt(np.mean(err[after] ** 2))) if after.any() else math.nan,
        "final_error": float(maxerr[last].max()),
        "converge_orbits": math.nan if converge is None else converge,
        "reel_effort": float(np.abs(dl).sum() * traj.settings["control_step"]),
        "reel_excursion": float((length.max(axis=0) - length.min(axis=0)).max()),
        "min_tension": float(traj.tension_min[1:].min()),
        "slack": float(failure == "slack"),
        "tumble": float(failure == "tumble"),
        "length": float(failure == "length"),
        "success": float(failure is None and traj.truncated),
        "chattering": float(np.abs(np.diff(dl, axis=0)).sum()),
        "return": float(np.sum(traj.reward)),
    }
    active = getattr(traj, "filter_active", None)
    if active is not None:
        out["filter_rate"] = float(np.mean(active)) if len(active) else math.nan
    return out
