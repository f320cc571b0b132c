"""Paper reproduction: metrics (pure functions of recorded trajectories).

The numbers the benchmark also reports (convergence time, RMS error after orbit 1,
minimum tension) come from :func:`tether_gym_agents.evaluation.metrics.episode_metrics`, the one
definition shared with ``evaluate.py``; this module adds the paper table's own measures.
"""

from __future__ import annotations

import math

import numpy as np

from ..evaluation.metrics import after_first_orbit, convergence_orbits, episode_metrics
from ..evaluation.rollout import Trajectory

__all__ = ["swing", "chattering", "smc_metrics", "convergence_orbits"]


def swing(length: np.ndarray, length0: float) -> np.ndarray:
    """(max l - min l) / l(0) per tether over the samples given [-]."""
    length = np.asarray(length, dtype=float)
    return (length.max(axis=0) - length.min(axis=0)) / length0


def chattering(orbits: np.ndarray, command: np.ndarray, start: float,
               window: float = 0.02) -> dict | None:
    """Chattering measures of the commands ``command[k]`` applied from ``orbits[k]``.

    Over the steps from ``start`` [orbits] on, per tether (the table reports the max):

    * ``tv_per_orbit``: total variation sum_k |u_{k+1} - u_k| per orbit [-];
    * ``hf_fraction``: total variation of u minus its centred moving average over
      ``window`` orbits, over the total variation of u on the same steps [-]: about
      (window * 2 pi)^2 / 24 times the squared frequency content (~0.003) for a smooth
      once- or twice-per-orbit signal, near 1 when step-to-step switching dominates;
    * ``extrema_per_orbit``: local extrema of u per orbit (2 or 4 for a smooth signal
      with one or two humps per orbit, of order 1 / control_step with chattering).

    None when less than a quarter orbit (or fewer than two windows) is available.
    """
    t = np.asarray(orbits, dtype=float)[:command.shape[0]]
    keep = t >= start
    u = np.asarray(command, dtype=float)[keep]
    if u.shape[0] < 3:
        return None
    dt = t[1] - t[0]
    span = t[keep][-1] - t[keep][0] + dt
    w = max(3, int(round(window / dt)) // 2 * 2 + 1)
    if span < 0.25 or u.shape[0] < 2 * w:
        return None
    du = np.diff(u, axis=0)
    tv = np.abs(du).sum(axis=0)
    kernel = np.full(w, 1.0 / w)
    tiny = 1e-12 * max(1.0, float(np.abs(u).max()))
    hf = np.zeros(u.shape[1])
    extrema = np.zeros(u.shape[1])
    for i in range(u.shape[1]):
        mean = np.convolve(u[:, i], kernel, mode="valid")
        mid = u[w // 2:w // 2 + mean.shape[0], i]
        tv_mid = np.abs(np.diff(mid)).sum()
        hf[i] = np.abs(np.diff(mid - mean)).sum() / tv_mid if tv_mid > 0 else 0.0
        sgn = np.sign(np.where(np.abs(du[:, i]) > tiny, du[:, i], 0.0))
        sgn = sgn[sgn != 0]
        extrema[i] = np.count_nonzero(sgn[1:] != sgn[:-1])
    return {"tv_per_orbit": float((tv / span).max()), "hf_fraction": float(hf.max()),
            "extrema_per_orbit": float((extrema / span).max()), "from_orbit": float(start),
            "span_orbits": float(span), "window_orbits": float(w * dt)}


def smc_metrics(traj: Trajectory) -> dict:
    """The table's sliding-mode numbers for one run.

    ``convergence_orbits``, ``rms_error_after_orbit_1`` and ``min_tension`` are the
    benchmark's ``converge_orbits``, ``tracking_rms`` and ``min_tension``
    (:func:`~tether_gym_agents.evaluation.metrics.episode_metrics`), None where undefined.
    """
    bench = episode_metrics(traj)

    def defined(x):
        return None if x is None or not math.isfinite(x) else float(x)

    conv = defined(bench["converge_orbits"])
    after = after_first_orbit(traj)
    err = traj.tracking_error[1:][after]
    total = traj.length[1:].sum(axis=1)[after]
    has_after = bool(after.any())
    start = conv if conv is not None else 1.0
    ends = [float(k) for k in range(1, int(math.floor(traj.duration + 1e-9)) + 1)]
    lengths_at = {f"{k:g}": traj.length[np.argmin(np.abs(traj.orbits - k))].tolist() for k in ends}
    limit = traj.settings.get("accel_limit")
    return {
        "failure": traj.failure,
        "duration_orbits": traj.duration,
        "convergence_orbits": conv,
        "max_error_after_orbit_1": float(err.max()) if has_after else None,
        "rms_error_after_orbit_1": defined(bench["tracking_rms"]),
        "mean_total_length_after_orbit_1": float(total.mean()) if has_after else None,
        "total_length_range_after_orbit_1": ([float(total.min()), float(total.max())]
                                             if has_after else None),
        "min_tension": bench["min_tension"],
        "min_length": float(traj.length.min()),
        "lengths_at_orbit_end": lengths_at,
        "saturated_command_steps": int(np.count_nonzero(np.any(
            np.abs(traj.command) >= (1.0 - 1e-6) * traj.settings["max_reel_rate"], axis=1))),
        "max_reel_accel_over_limit": (float(np.abs(traj.reel_accel).max() / limit)
                                      if limit else None),
        "chattering": chattering(traj.orbits, traj.command, start),
    }
