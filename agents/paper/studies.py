"""Paper reproduction: the studies, each a set of env runs and the numbers taken from them.

Every study returns the trajectories its figures need beside a JSON-ready dict of
numbers for the table (see the package docstring for the settings).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tether_gym.physics import TetherChain
from tether_gym.tasks.reference import (
    desired_libration,
    periodic_length_small_amplitude,
    periodic_reel_rate,
    tension_positivity_polynomial,
)

from .measures import smc_metrics, swing
from .runs import Trajectory, make_env, run_periodic, run_smc, run_zero_state
from .settings import (
    DEFAULT_SMC_SETTINGS,
    FIG5_AMPLITUDES,
    FIG6_AMPLITUDES,
    FIG6_ECCENTRICITY,
    ORBIT,
    TABLE1_LENGTH,
)

__all__ = ["Fig6Runs", "zero_state_study", "fig5_study", "fig6_study", "swing_scan",
           "positivity_study", "smc_study", "l0_sweep"]

_NU_ORBIT = np.linspace(0.0, ORBIT, 4001)
"""One orbit of true anomaly [rad] on which the closed forms and quadratures are evaluated."""

L0_SWEEP = ((1.0, "15.5"), (10.0, "1.55"), (20.0, "0.78"), (30.0, "—"))
"""(L0 [km], docs/model.md's accel bound as quoted in the table) of the L0 sweep."""


class Fig6Runs(NamedTuple):
    """The Fig. 6 study's runs and reference curves, keyed by amplitude A [rad]."""

    runs: dict
    """A -> env :class:`Trajectory` (which may end early on slack)."""
    quadrature: dict
    """A -> (nu [rad], l [-]): Eq. 10 integrated over one orbit (no env)."""
    numbers: dict
    """The table's numbers, keyed by ``f"{A:g}"``."""


def zero_state_study(orbits: float) -> tuple[Trajectory, dict]:
    """Eq. 7 from the zero state (Figs. 2-4) and its numbers.

    Parameters
    ----------
    orbits : float
        Run duration [orbits].

    Returns
    -------
    traj : Trajectory
        The run.
    numbers : dict
        Peak length and its true anomaly, angles, and the tension ranges of the env,
        of the paper's procedure (backward-difference l'') and of the closed form.
    """
    traj = run_zero_state(orbits)
    e = traj.settings["eccentricity"]
    i_peak = int(np.argmax(traj.length[:, 0]))
    first = traj.orbits <= 1.0 + 1e-9
    # Tension as the paper forms it: the model's T^ with the backward difference
    # (l'(nu) - l'(nu - h)) / h for l'' (Sec. 4.3), on the env's recorded states.
    chain = TetherChain((1.0, 2.0), e)
    h = np.diff(traj.nu)[:, None]
    ddl = np.diff(traj.dlength, axis=0) / h
    t_paper = chain.tension(traj.nu[1:], traj.theta[1:], traj.dtheta[1:], traj.length[1:],
                            traj.dlength[1:], ddl)
    k = 1.0 + e * np.cos(traj.nu)
    exact = np.stack([3.0 / k**2, 2.4 / k**2], axis=1)
    end_idx = int(np.argmin(np.abs(traj.orbits - 1.0)))
    settle = 10.0 * traj.settings["reel_time_constant"]
    settled = traj.nu - traj.nu[0] >= settle
    out = {
        "failure": traj.failure,
        "duration_orbits": traj.duration,
        "max_abs_theta": float(np.abs(traj.theta).max()),
        "peak_length": float(traj.length[first, 0].max()) if first.any() else None,
        "peak_nu": float(traj.nu[i_peak]),
        "peak_increase": float(traj.length[first, 0].max() / TABLE1_LENGTH - 1.0),
        "length_after_one_orbit_rel": (float(traj.length[end_idx, 0] / TABLE1_LENGTH - 1.0)
                                       if traj.duration >= 1.0 - 1e-9 else None),
        "tension_range_env": [[float(traj.tension[settled, j].min()),
                               float(traj.tension[settled, j].max())] for j in range(2)],
        "tension_range_paper_procedure": [[float(t_paper[settled[1:], j].min()),
                                           float(t_paper[settled[1:], j].max())]
                                          for j in range(2)],
        "tension_range_closed_form": [[float(exact[:, j].min()), float(exact[:, j].max())]
                                      for j in range(2)],
        # after the reel's start-up (10 tau): the reels start from l'' = 0, where T^ is
        # 6.7 % above the closed form (the law's l''(0) = e l0 / (1 + e)^2 is missing)
        "tension_closed_form_max_rel_dev_env": float(
            np.abs(traj.tension[settled] / exact[settled] - 1.0).max()),
        "tension_closed_form_max_rel_dev_paper_procedure": float(
            np.abs(t_paper[settled[1:]] / exact[1:][settled[1:]] - 1.0).max()),
        "tension_start_rel_dev_env": float(np.abs(traj.tension[0] / exact[0] - 1.0).max()),
        "settle_nu": float(settle),
        "min_tension": float(traj.tension_min.min()),
    }
    return traj, out


def fig5_study(orbits: float) -> tuple[dict, dict]:
    """Eq. 10 at e = 0.2 for the amplitudes of Fig. 5, with the Eq. 11a swing beside.

    Parameters
    ----------
    orbits : float
        Run duration [orbits].

    Returns
    -------
    runs : dict
        A [rad] -> :class:`Trajectory`.
    numbers : dict
        ``f"{A:g}"`` -> swing, peak reel-out and half the peak-to-peak of l over the
        first orbit, the Eq. 11a swing, the max tracking error and the failure.
    """
    runs: dict = {}
    numbers: dict = {}
    for a in FIG5_AMPLITUDES:
        traj = run_periodic(0.2, a, orbits)
        one = traj.orbits <= 1.0 + 1e-9
        sw = swing(traj.length[one], TABLE1_LENGTH)
        runs[a] = traj
        closed = periodic_length_small_amplitude(_NU_ORBIT, TABLE1_LENGTH, 0.2, a)
        numbers[f"{a:g}"] = {
            "swing": float(sw.max()),
            "peak_out": float(traj.length[one].max() / TABLE1_LENGTH - 1.0),
            "half_swing_abs": float(0.5 * (traj.length[one].max() - traj.length[one].min())),
            "eq11a_swing": float(np.ptp(closed) / TABLE1_LENGTH),
            "max_tracking_error": float(traj.tracking_error.max()),
            "failure": traj.failure, "duration_orbits": traj.duration}
    return runs, numbers


def fig6_study(orbits: float) -> Fig6Runs:
    """Eq. 10 at e = 0.7, p = 7100 (1 + e) km for the amplitudes of Fig. 6.

    Parameters
    ----------
    orbits : float
        Run duration [orbits] (the runs may end earlier on slack).

    Returns
    -------
    Fig6Runs
        The env runs, the Eq. 10 quadratures over one orbit and the table's numbers
        (swing and deviation of the quadrature, env swing, env vs quadrature, min T^).
    """
    from scipy.integrate import cumulative_trapezoid

    e6 = FIG6_ECCENTRICITY
    nu_q = _NU_ORBIT
    found = Fig6Runs({}, {}, {})
    for a in FIG6_AMPLITUDES:
        traj = run_periodic(e6, a, orbits, semi_latus_rectum=7.1e6 * (1.0 + e6))
        th, dth, _ = desired_libration(nu_q, a, 1.0)
        rate = periodic_reel_rate(nu_q, th, dth, 1.0, e6, a)
        quad = TABLE1_LENGTH * np.exp(cumulative_trapezoid(rate, nu_q, initial=0.0))
        found.runs[a] = traj
        found.quadrature[a] = (nu_q, quad)
        found.numbers[f"{a:g}"] = {
            "failure": traj.failure, "duration_orbits": traj.duration,
            "env_swing_abs": float(np.ptp(traj.length[:, 0])),
            "swing_abs_quadrature": float(np.ptp(quad)),
            "max_dev_abs_quadrature": float(np.abs(quad - TABLE1_LENGTH).max()),
            "env_vs_quadrature_max_dev": float(np.abs(
                traj.length[:, 0] - np.interp(traj.nu, nu_q, quad)).max()),
            "min_tension": float(traj.tension_min.min())}
    return found


def _swing_of(e: float, amplitude: float, orbits: float, p: float | None = None) -> tuple:
    traj = run_periodic(e, amplitude, orbits, p)
    one = traj.orbits <= 1.0 + 1e-9
    sw = float(swing(traj.length[one], TABLE1_LENGTH).max())
    return sw, traj


def swing_scan(e: float, grid: np.ndarray, orbits: float, refine: bool) -> dict:
    """Swing over one orbit vs A; the minimiser by grid then golden section.

    Parameters
    ----------
    e : float
        Eccentricity [-].
    grid : numpy.ndarray
        Amplitudes A [rad] of the scan, increasing.
    orbits : float
        Run duration [orbits] (the swing is taken over the first orbit).
    refine : bool
        Refine the grid's minimiser with a bounded scalar minimisation.

    Returns
    -------
    dict
        The grid and its swings [-], the minimiser and its swing, the number of runs,
        and the Eq. 11a closed form's minimiser and curve (every 50th of 2001 points).
    """
    from scipy.optimize import minimize_scalar

    values = [_swing_of(e, float(a), orbits)[0] for a in grid]
    i = int(np.argmin(values))
    best, best_val, evals = float(grid[i]), float(values[i]), len(grid)
    if refine and 0 < i < len(grid) - 1:
        res = minimize_scalar(lambda a: _swing_of(e, float(a), orbits)[0],
                              bounds=(float(grid[i - 1]), float(grid[i + 1])), method="bounded",
                              options={"xatol": 5e-4})
        evals += int(res.nfev)
        if res.fun <= best_val:
            best, best_val = float(res.x), float(res.fun)
    # the paper's closed form (Eq. 11a) on a fine grid, for comparison
    nu = np.linspace(0.0, ORBIT, 4001)
    fine = np.linspace(grid[0], grid[-1], 2001)
    closed = [float(np.ptp(periodic_length_small_amplitude(nu, 1.0, e, a))) for a in fine]
    return {"eccentricity": e, "grid": [float(a) for a in grid], "swing": values,
            "argmin": best, "min_swing": best_val, "evaluations": evals,
            "eq11a_argmin": float(fine[int(np.argmin(closed))]),
            "eq11a_grid": [float(a) for a in fine[::50]], "eq11a_swing": closed[::50]}


def _model_min_tension(e: float, amplitude: float) -> float:
    """Min over one orbit of T^ along the exact reference with the exact Eq. 10 reels.

    A cross-check of the env runs (the model, no env): l from the quadrature of
    Eq. 10, l'' by differentiating l' on a fine grid.
    """
    from scipy.integrate import cumulative_trapezoid

    nu = np.linspace(0.0, ORBIT, 20001)
    th, dth, _ = desired_libration(nu, amplitude, 1.0)
    rate = periodic_reel_rate(nu, th, dth, 1.0, e, amplitude)
    ell = TABLE1_LENGTH * np.exp(cumulative_trapezoid(rate, nu, initial=0.0))
    dl = rate * ell
    ddl = np.gradient(dl, nu)
    two = [np.stack([x, x], axis=1) for x in (th, dth, ell, dl, ddl)]
    tension = TetherChain((1.0, 2.0), e).tension(nu, *two)
    return float(tension.min())


def _bisect(fun, low: float, high: float, tol: float) -> float | None:
    """Root of a decreasing-sign function on [low, high] (None if not bracketed)."""
    f_low, f_high = fun(low), fun(high)
    if not (f_low > 0.0 >= f_high):
        return None
    while high - low > tol:
        mid = 0.5 * (low + high)
        if fun(mid) > 0.0:
            low = mid
        else:
            high = mid
    return 0.5 * (low + high)


def positivity_study(eccs, amps, orbits: float, boundary: bool) -> dict:
    """Sign of Sec. 3.2's polynomial vs the min tension of the env runs.

    Parameters
    ----------
    eccs : sequence of float
        Eccentricities e [-].
    amps : sequence of float
        Amplitudes A [rad]; every (e, A) pair is run.
    orbits : float
        Run duration [orbits].
    boundary : bool
        Also locate, per e, the largest A without slack: the polynomial's root, the
        env's (bisection of env runs) and the model's on the exact reference.

    Returns
    -------
    dict
        ``cases`` (one per pair), ``roots`` (one per e, empty without ``boundary``) and
        ``agreement`` ("k/n" pairs where the polynomial's sign matches the env's).
    """
    cases = []
    for e in eccs:
        for a in amps:
            traj = run_periodic(e, a, orbits)
            tmin = float(traj.tension_min.min())
            poly = float(tension_positivity_polynomial(e, a))
            cases.append({"e": e, "A": a, "polynomial": poly, "env_min_tension": tmin,
                          "env_failure": traj.failure, "env_duration_orbits": traj.duration,
                          "model_min_tension": _model_min_tension(e, a),
                          "agree": bool((poly > 0) == (tmin > 0))})
    roots = []
    if boundary:
        for e in eccs:
            grid = np.linspace(0.0, 1.0, 100001)
            poly = tension_positivity_polynomial(e, grid)
            a_poly = float(grid[np.nonzero(np.diff(np.sign(poly)))[0][0]])

            def env_tmin(a, e=e):
                return float(run_periodic(e, a, orbits).tension_min.min())

            roots.append({"e": e, "polynomial_root": a_poly,
                          "env_root": _bisect(env_tmin, 0.55, 0.75, 2e-3),
                          "model_root": _bisect(lambda a, e=e: _model_min_tension(e, a),
                                                0.55, 0.75, 5e-4)})
    return {"cases": cases, "roots": roots,
            "agreement": f"{sum(c['agree'] for c in cases)}/{len(cases)}"}


def smc_study(orbits: float, settings: dict) -> tuple[Trajectory, dict]:
    """The sliding-mode run (Figs. 7-9) at the given env settings and its numbers.

    Parameters
    ----------
    orbits : float
        Run duration [orbits].
    settings : dict
        Env arguments (:data:`~.settings.PAPER_SMC_SETTINGS` or
        :data:`~.settings.DEFAULT_SMC_SETTINGS`).

    Returns
    -------
    traj : Trajectory
        The run.
    numbers : dict
        :func:`~.measures.smc_metrics` of the run, plus the run's ``settings``.
    """
    traj = run_smc(orbits, settings)
    numbers = smc_metrics(traj)
    numbers["settings"] = traj.settings
    return traj, numbers


def l0_sweep(orbits: float) -> list:
    """The sliding mode at the env's default step for several L0 (docs/model.md's L0).

    Parameters
    ----------
    orbits : float
        Run duration [orbits].

    Returns
    -------
    list of dict
        Per L0 of :data:`L0_SWEEP`: the accel bound a_max / (L0 n^2) [-], the mean
        l_1 + l_2 after orbit 1, convergence, min length and failure.
    """
    sweep = []
    for l0_km, notes_bound in L0_SWEEP:
        traj = run_smc(orbits, DEFAULT_SMC_SETTINGS, total_tether_length=l0_km * 1e3)
        env = make_env(1.0, total_tether_length=l0_km * 1e3)
        cfg = env.unwrapped.config
        env.close()
        m = smc_metrics(traj)
        sweep.append({"L0_km": l0_km, "notes_bound": notes_bound,
                      "accel_bound": cfg.scales.accel_bound(cfg.accel_limit),
                      "mean_total_length": m["mean_total_length_after_orbit_1"],
                      "convergence_orbits": m["convergence_orbits"],
                      "min_length": m["min_length"], "failure": m["failure"],
                      "duration_orbits": m["duration_orbits"]})
    return sweep
