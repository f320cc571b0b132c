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
* ``cost_per_step`` [-]: the episode's mean constraint cost per control step,
  sum_k c_k / K over its K steps (c_k = ``info["cost"]`` of step k, in {0, 1, 2, 3},
  :mod:`tether_gym.tasks.cost`; the reset sample is no step; a failed episode's steps
  run up to and including the failing one, which costs at least 1).
* ``over_limit``: 1 if ``cost_per_step`` > the cost limit (:data:`COST_LIMIT`,
  ``tether_gym.tasks.cost.COST_LIMIT``), else 0.
* ``cost_slack_per_step``, ``cost_length_per_step``, ``cost_tumble_per_step`` [-]: the
  same mean of each part ``info["cost_<part>"]`` (their sum is ``cost_per_step``).
  All cost metrics are NaN for a trajectory recorded without cost.
* ``filter_rate`` [-]: fraction of the steps whose action a safety filter changed; only
  for filtered policies (``traj.filter_active`` set), and not in :data:`METRICS`.

The benchmark (:mod:`tether_gym_agents.evaluation.benchmark`) and the paper reproduction
(:mod:`tether_gym_agents.paper`) both compute these from the same trajectories;
statistics over episodes and training runs are in :mod:`tether_gym_agents.evaluation.stats`.
"""

from __future__ import annotations

import math

import numpy as np

from tether_gym.tasks.cost import COST_LIMIT, COST_PARTS

__all__ = ["episode_metrics", "convergence_orbits", "after_first_orbit", "METRICS",
           "HIGHER_IS_BETTER", "LOWER_IS_BETTER", "FAILURES", "CONVERGENCE_TOL", "COST_LIMIT",
           "COST_METRICS", "COST_PART_METRICS", "cost_metrics"]

CONVERGENCE_TOL = 1e-3
"""Tracking tolerance of the convergence time [rad]."""
COST_PART_METRICS = tuple(f"cost_{part}_per_step" for part in COST_PARTS)
"""Mean of each cost part per step, in the order of ``tether_gym.tasks.cost.COST_PARTS``."""
COST_METRICS = ("cost_per_step", "over_limit") + COST_PART_METRICS
"""The cost metrics of :func:`episode_metrics`."""
METRICS = ("tracking_rms", "final_error", "converge_orbits", "reel_effort", "reel_excursion",
           "min_tension", "slack", "tumble", "length", "success", "chattering",
           "return") + COST_METRICS
"""Every metric of :func:`episode_metrics`."""
HIGHER_IS_BETTER = frozenset({"success", "min_tension", "return"})
"""Metrics where a larger value is better (the probability of improvement counts a larger
value as the better one for these, a smaller one for all others)."""
LOWER_IS_BETTER = frozenset({"tracking_rms", "final_error", "converge_orbits", "reel_effort",
                             "reel_excursion", "slack", "tumble", "length", "chattering",
                             *COST_METRICS})
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


def episode_metrics(traj, cost_limit: float = COST_LIMIT) -> dict:
    """Metrics of one episode (see the module docstring).

    Parameters
    ----------
    traj : Trajectory
        The recorded episode (:func:`tether_gym_agents.evaluation.rollout.rollout`).
    cost_limit : float
        Limit on the mean cost per step [-] above which ``over_limit`` is 1.

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
    out.update(cost_metrics(traj, cost_limit))
    active = getattr(traj, "filter_active", None)
    if active is not None:
        out["filter_rate"] = float(np.mean(active)) if len(active) else math.nan
    return out


def cost_metrics(traj, cost_limit: float = COST_LIMIT) -> dict:
    """The cost metrics of one episode (:data:`COST_METRICS`; module docstring).

    The mean over the K step rows (1..K) of ``traj.cost`` and of each part; NaN for every
    one when ``traj`` carries no cost.
    """
    cost = getattr(traj, "cost", None)
    if cost is None or len(cost) < 2:
        return dict.fromkeys(COST_METRICS, math.nan)
    per_step = float(np.mean(cost[1:]))
    out = {"cost_per_step": per_step, "over_limit": float(per_step > cost_limit)}
    for part, name in zip(COST_PARTS, COST_PART_METRICS, strict=True):
        values = getattr(traj, f"cost_{part}", None)
        out[name] = math.nan if values is None else float(np.mean(values[1:]))
    return out
