"""A model-based safety filter for the reel commands.

The filter replaces a desired reel-rate command by the closest command (Euclidean, in
the normalised command box [-1, 1]^n) whose predicted next control step keeps every
tether taut with a margin and every length inside its bounds with a margin. The
predictor is the environment's own compiled step, :func:`tether_gym.physics.transition`
(RK4 with the reels in the loop, ``control_step / physics_step`` substeps), run on the
*nominal* model of the configuration (its e and masses, like the sliding-mode
controller; no disturbance), so over one step it is exact for the nominal system.

Constraints on a command c (normalised, l'_cmd = c * max_reel_rate), per tether j:

* tension: T^_j,min(c) >= ``margin``, with T^_j,min the smallest T^_j at the physics
  substep boundaries of the step (both ends included), as the env's slack check
  (:func:`tether_gym.tasks.termination.failure_code`) sees it;
* length: l_j,stop(c) in [l_min + ``length_margin``, l_max - ``length_margin``], where

      l_j,stop = l_j + sign(l_j') (k^2 l_j')^2 / (2 a_bound)     (state at the end of the step)

  is where the tether would come to rest if its reel braked at the acceleration limit
  from the end of the step on. Derivation: with L_dot = L0 n k^2 l' (docs/model.md,
  "Dimensionless variables"), a reel braking at the physical limit |L_ddot| = a_max
  covers L_dot^2 / (2 a_max) before it stops; divided by L0 this is
  (k^2 l')^2 / (2 a_bound) with a_bound = a_max / (L0 n^2) (the parameter row's
  ``accel_bound``; 0 without a limit). A one-step check of l alone comes too late: at
  the default limits a reel at full rate needs about 20 control steps to stop.

Both constraints are cheap to decide for the length part: tether j's reel, and so
l_j and l_j' at the end of the step, depend on its own command c_j only
(:func:`tether_gym.physics.kernels._reel`), and increase with it, so l_j,stop is
monotone in c_j and the length constraints are a box [lo, hi] found by bisection. The
tension depends on every command (T^ is affine in l'' at a given state, paper Eq. 6b,
and each reel's l'' saturates at the acceleration limit), so the closest
tension-feasible command in the box is searched numerically (lattice, then a
shrinking pattern search; see :meth:`SafetyFilter.project`).
"""

from __future__ import annotations

import math
from itertools import product
from typing import Any, NamedTuple

import numpy as np

from .envs.config import MAX_CONTROL_STEP, MIN_STEP, env_config
from .params import as_float_tuple, check_range
from .physics import kernels
from .physics.layout import at
from .physics.state import PARAMS, STATE, P

__all__ = ["SafetyFilter", "FilterResult", "DEFAULT_MARGIN", "MAX_TETHERS", "MAX_SUBSTEPS"]

DEFAULT_MARGIN = 0.5
"""Tension margin T^_min [-] when the configuration gives none: the reward's T_safe."""

BISECTION_STEPS = 14
"""Bisection steps of each length bound: resolution 2 / 2^14 ~ 1.2e-4 in the command."""
PATTERN_STEPS = 12
"""Halvings of the pattern search; the final step is the lattice spacing / 2^13."""
MAX_LATTICE = 81
"""Largest number of lattice points of the first search stage (per state)."""
MAX_TETHERS = 9
"""Most tethers a filter takes (n_bodies <= 10). The search tries 3^n - 1 directions per
stage, so its cost grows about 3.3x per tether: a filtered step of a rate-mode env
measured 0.028 s at n_bodies = 6, 0.34 s at 8, 1.2-1.5 s at 9 and 4.4 s at 10 (one core,
2026-12-08); at 12 one step outlasted a minute, and at 20 the 3^19 directions alone
would take about 240 GB (built under a 4 GB limit: a MemoryError after 11 s)."""
MAX_SUBSTEPS = round(MAX_CONTROL_STEP / MIN_STEP)
"""Most RK4 substeps per prediction: the env's most (the largest control step over the
smallest physics step, :mod:`tether_gym.envs.config`)."""


class FilterResult(NamedTuple):
    """The filter's answer for a batch of B states (n tethers)."""

    command: np.ndarray
    """(B, n) filtered normalised reel-rate commands in [-1, 1] [-]."""
    active: np.ndarray
    """(B,) bool: the command differs from the desired one (after clipping to [-1, 1])."""
    correction: np.ndarray
    """(B,) Euclidean distance |command - desired| [-] (desired clipped to [-1, 1])."""
    feasible: np.ndarray
    """(B,) bool: the returned command satisfies every constraint (predicted)."""
    tension_min: np.ndarray
    """(B, n) predicted smallest T^ over the step under the returned command [-]."""


class SafetyFilter:
    """Projection of reel-rate commands onto the predicted-safe set of the next step.

    It guards exactly two constraints per tether j, predicted for the next control
    step on the *nominal* model without disturbance (formulas in the module
    docstring):

    * tension: the smallest T^_j at the physics substep boundaries of the step is
      >= ``margin`` (the env fails with ``slack`` at T^_j <= 0);
    * length: the braking-stop length l_j,stop at the end of the step lies in
      [l_min + ``length_margin``, l_max - ``length_margin``] (the env fails with
      ``length`` outside [l_min, l_max]).

    Nothing else: not tumbling (|theta_j| >= pi/2), the reference tracking, the reel
    effort or any step after the next (only the braking distance looks further). A
    one-step projection cannot guard the libration bound: the reels act on theta
    through theta'' (the Coriolis term -2 (l'/l)(1 + theta') of reeling,
    docs/model.md, "Check: a single tether"), so over the whole command box the
    predicted theta at the end of a step moves by a median 2.5e-4 rad (max 3.1e-3)
    while theta itself drifts by a median 8.8e-3 rad per step (6791 states of random
    rate policies, ``experiments/issue24/filter_outcomes.py``). Keeping tension by
    refusing fast reel-outs can therefore trade slack for tumble: uniform random
    commands, 30 episodes, end 26 slack / 0 tumble / 4 survived unfiltered and 6 slack
    / 18 tumble / 6 survived filtered. Guarding both needs a horizon of several steps
    (a model-predictive controller). When no command meets both constraints, the
    returned command is the best effort described in :meth:`project`,
    ``FilterResult.feasible`` is False, and :class:`tether_gym.wrappers.FilterInTheLoop`
    warns once and counts it. The prediction knows neither the disturbance nor the
    observation noise, nor the true e and masses when they differ from the nominal
    ones, and it starts from the state it is given (true or observed: the caller's choice,
    :class:`tether_gym.wrappers.FilterInTheLoop`).

    Parameters
    ----------
    params : ndarray, shape (P,)
        Parameter row of the nominal model with its reel limits
        (``EnvConfig.param_rows``, :data:`tether_gym.physics.PARAMS`).
    n_tethers : int
        n = N - 1, >= 1.
    max_reel_rate : float
        l'_cmd at |command| = 1 [-], > 0.
    physics_step : float
        RK4 step [rad], > 0.
    substeps : int
        RK4 steps per control step, >= 1.
    length_bounds : tuple of float
        (l_min, l_max) [-] of the task, 0 <= l_min < l_max.
    margin : float
        Smallest predicted tension T^ [-] allowed, > 0 (default: the reward's T_safe,
        see :meth:`for_env`).
    length_margin : float
        Distance [-] kept from each length bound, >= 0 and < (l_max - l_min) / 2.

    Notes
    -----
    Deterministic: the same inputs give bitwise the same outputs, for any batch size
    (each row is searched on its own; the candidates are fixed lattices). One filter
    holds one scratch buffer of the compiled step: do not share it between threads.
    """

    def __init__(self, params, n_tethers: int, max_reel_rate: float, physics_step: float,
                 substeps: int, length_bounds: tuple[float, float],
                 margin: float = DEFAULT_MARGIN, length_margin: float = 0.0):
        self.n = _count("n_tethers", n_tethers)
        if self.n > MAX_TETHERS:
            raise ValueError(f"n_tethers={n_tethers!r} must be at most {MAX_TETHERS} "
                             f"(n_bodies <= {MAX_TETHERS + 1}): the filter's search tries "
                             "3^n - 1 directions, about 4.4 s per filtered step at "
                             "n_bodies=10 and 3.3x more per added tether")
        par = np.ascontiguousarray(_reals("params", params, "a parameter row (P,) of real "
                                          "numbers, EnvConfig.param_rows").reshape(1, -1))
        if par.shape[1] != PARAMS.size(self.n):
            raise ValueError(f"params of shape {np.shape(params)} do not fit {self.n} tethers "
                             f"(need ({PARAMS.size(self.n)},), a row of EnvConfig.param_rows)")
        self.par = par
        self.max_reel_rate = check_range("max_reel_rate", max_reel_rate, 0.0, low_open=True)
        self.physics_step = check_range("physics_step", physics_step, 0.0, low_open=True)
        self.substeps = _count("substeps", substeps)
        if self.substeps > MAX_SUBSTEPS:
            raise ValueError(f"substeps={substeps!r} must be at most {MAX_SUBSTEPS} (the "
                             f"env's most: control_step <= {MAX_CONTROL_STEP:g} over "
                             f"physics_step >= {MIN_STEP:g})")
        lo, hi = as_float_tuple("length_bounds", length_bounds, 2)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
            raise ValueError(f"length_bounds={length_bounds!r} must be finite with "
                             "0 <= low < high")
        self.length_bounds = (lo, hi)
        self.margin = check_range("margin", margin, 0.0, low_open=True)
        self.length_margin = check_range("length_margin", length_margin, 0.0, 0.5 * (hi - lo),
                                         high_open=True)  # half the length range
        self.accel_bound = float(par[0, at(P.accel_bound, self.n)])
        self.eccentricity = float(par[0, at(P.eccentricity, self.n)])
        self._substeps = kernels.Substeps(self.physics_step, self.substeps)
        self._work = kernels.make_scratch(self.n)
        self._lattice = _lattice_size(self.n)
        self._pattern = np.array([p for p in product((-1.0, 0.0, 1.0), repeat=self.n)
                                  if any(p)])  # the 3^n - 1 moves of the pattern search

    @classmethod
    def for_env(cls, env: Any, margin: float | None = None,
                length_margin: float | None = None, eccentricity: float | None = None,
                masses=None, reel_time_constant: float | None = None,
                accel_limit: float | None = None) -> SafetyFilter:
        """Build for a TetherLibration env (wrapped or not, single or vector).

        Parameters
        ----------
        env : gymnasium.Env or VectorEnv
            Its ``unwrapped.config`` gives the nominal model, reel limits, steps and
            length bounds.
        margin : float or None
            Tension margin [-]; None takes the task's own safe tension, the reward's
            T_safe (``reward_weights.safe_tension``, 0.5 by default): the reward already
            calls a tension below it "close to slack", so the filter keeps the predicted
            tension out of the region the task penalises.
        length_margin : float or None
            Distance [-] kept from the length bounds; None takes the distance a reel
            covers in one control step at full rate, ``max_reel_rate * control_step``
            (0.0125 by default): one step of travel that the prediction's one-step
            horizon and the command's one-step hold could add to the braking distance.
        eccentricity, masses : float, sequence of float, or None
            Nominal e [-] and subsatellite masses (any common unit) of the predicting
            model when they differ from the env's (model-mismatch studies); None takes
            the env's configured ones.
        reel_time_constant, accel_limit : float or None
            Nominal reel lag tau [rad] (> 0) and acceleration limit [m/s^2] (> 0) of the
            predicting model (the env's arguments of those names); None takes the env's.
        """
        cfg = env_config(env)
        par = cfg.nominal_params(eccentricity, masses, reel_time_constant, accel_limit)
        if margin is None:
            margin = float(cfg.reward_weights.safe_tension)
        if length_margin is None:
            length_margin = float(cfg.max_reel_rate) * float(cfg.control_step)
        return cls(par, cfg.n_tethers, cfg.max_reel_rate, cfg.physics_step, cfg.n_substeps,
                   cfg.length_bounds, margin=margin, length_margin=length_margin)

    def __repr__(self) -> str:
        return (f"SafetyFilter(n_tethers={self.n}, margin={self.margin}, "
                f"length_margin={self.length_margin}, length_bounds={self.length_bounds})")

    # ------------------------------------------------------------------ #
    def _predict(self, nu: np.ndarray, y: np.ndarray, cmd: np.ndarray):
        """(tension_min (R, n), l_stop (R, n)) of every row under commands cmd (R, n)."""
        # the compiled step of :func:`tether_gym.physics.transition`, called directly:
        # the inputs are validated once in project() and the wrapper's checks and
        # copies cost more than the step itself here
        rows, n = cmd.shape
        nu_end = np.array(nu, dtype=float)
        state = np.array(y, dtype=float)
        out = kernels.StepOutputs(np.empty((rows, n)), np.empty((rows, 4 * n)),
                                  np.empty((rows, n)))
        kernels.transition_rows(nu_end, state,
                                kernels.StepInputs(np.ascontiguousarray(cmd * self.max_reel_rate),
                                                   np.zeros((rows, n))),
                                self.par, self._substeps, out, self._work)
        sl = STATE.slices(n)
        length = state[:, sl["length"]]
        rate = state[:, sl["dlength"]]
        if math.isinf(self.accel_bound):
            stop = length
        else:
            k = 1.0 + self.eccentricity * np.cos(nu_end)[:, None]
            v = k * k * rate
            stop = length + np.sign(v) * v * v / (2.0 * self.accel_bound)
        tension = out.tension_min
        bad = ~(np.isfinite(tension).all(axis=1) & np.isfinite(stop).all(axis=1))
        if bad.any():  # a diverged prediction is unsafe, never NaN downstream
            tension = np.where(bad[:, None], -np.inf, tension)
            stop = np.where(bad[:, None], np.nan_to_num(stop, nan=0.0), stop)
        return tension, stop

    def _slack(self, tension, stop):
        """(tension slack, length slack), each the worst over tethers (R,) [-]."""
        lo = self.length_bounds[0] + self.length_margin
        hi = self.length_bounds[1] - self.length_margin
        return (tension.min(axis=1) - self.margin,
                np.minimum(stop - lo, hi - stop).min(axis=1))

    def _check(self, nu, state, command):
        nu = _reals("nu", nu, "a true anomaly [rad] or one per state")
        y = _reals("state", state, "state rows (B, 4n) [STATE layout]")
        c = _reals("command", command, "normalised commands (B, n)")
        m = STATE.size(self.n)
        if y.ndim != 2 or y.shape[1] != m:
            raise ValueError(f"state must have shape (B, {m}) for {self.n} tethers, got "
                             f"{y.shape}")
        b = y.shape[0]
        if c.shape != (b, self.n):
            raise ValueError(f"command must have shape ({b}, {self.n}), got {c.shape}")
        if nu.shape not in ((), (b,)):
            raise ValueError(f"nu must be a scalar or have shape ({b},), got {nu.shape}")
        for name, value in (("nu", nu), ("state", y), ("command", c)):
            if not np.all(np.isfinite(value)):
                raise ValueError(f"{name}={value!r} must be finite (no NaN or inf)")
        length = y[:, STATE.slices(self.n)["length"]]
        if np.any(length <= 0.0):
            raise ValueError(f"state lengths {length!r} must be > 0 (l = L / L0 [-])")
        return (np.ascontiguousarray(np.broadcast_to(nu, (b,))), np.ascontiguousarray(y),
                np.clip(c, -1.0, 1.0))

    def project(self, nu, state, command) -> FilterResult:
        """The closest predicted-safe command to ``command`` for each state.

        Parameters
        ----------
        nu : float or ndarray, shape (B,)
            True anomaly [rad].
        state : ndarray, shape (B, 4n)
            State rows ``[theta, theta', l, l']`` (:data:`tether_gym.physics.STATE`).
        command : ndarray, shape (B, n)
            Desired normalised reel-rate commands [-], finite; clipped to [-1, 1] first,
            as the env does.

        Returns
        -------
        FilterResult
            A row whose desired command is predicted safe gets it back bit for bit
            (``active`` False). Otherwise the command is the closest (Euclidean) one in
            [-1, 1]^n found to satisfy every constraint (module docstring), searched in
            three stages: (1) the length box [lo, hi] by bisection and the clipped
            command c0 = clip(c, lo, hi), exact when it is tension-feasible (the
            Euclidean projection onto a box is the clip), and a lattice over the box (9
            points per axis for n = 2); (2) the first safe point, by bisection, on each
            of the 3^n - 1 lines from c0 towards a face or corner of the box (each
            coordinate kept, or sent to lo or hi): the feasible set is not convex (e.g.
            "c_1 <= a or c_2 <= b"), and these lines reach each of its branches; (3) a
            pattern search on {-h, 0, h}^n around the best point so far, halving h 12
            times, moving only to feasible points closer to the desired command. The
            search is local: tests/test_safety.py checks it against a 41 x 41 grid.

            When no candidate satisfies every constraint, ``feasible`` is False and the
            command is the best effort: inside the length box (so the lengths are kept
            whenever that alone is possible; the length constraints are separable and
            cheap to meet, and a length violation ends an episode as surely as slack),
            the candidate of the same search with the largest worst predicted tension
            margin min_j T^_j,min - ``margin``.

        Raises
        ------
        ValueError
            For shapes that do not fit, NaN or inf entries, or non-positive lengths.
        """
        nu, y, desired = self._check(nu, state, command)
        tension, stop = self._predict(nu, y, desired)
        t_slack, l_slack = self._slack(tension, stop)
        safe = (t_slack >= 0.0) & (l_slack >= 0.0)
        out = desired.copy()
        feasible = safe.copy()
        tmin = tension.copy()
        rows = np.flatnonzero(~safe)
        if rows.size:
            cmd, ok, tm = self._search(nu[rows], y[rows], desired[rows])
            out[rows] = cmd
            feasible[rows] = ok
            tmin[rows] = tm
        correction = np.sqrt(((out - desired) ** 2).sum(axis=1))
        active = np.any(out != desired, axis=1)
        return FilterResult(out, active, correction, feasible, tmin)

    # ------------------------------------------------------------------ #
    def _length_box(self, nu, y, desired):
        """Per row and tether, [lo, hi] of commands that keep l_stop inside its bounds.

        l_stop of tether j increases with c_j only, so both bounds are found by one
        bisection for all tethers at once (rows [lower, upper] per state). When no
        command meets a bound, it is set to the command closest to meeting it (+1 for
        the lower bound, -1 for the upper one); crossed bounds meet at their midpoint.
        """
        u, n = desired.shape
        lo_b = self.length_bounds[0] + self.length_margin
        hi_b = self.length_bounds[1] - self.length_margin
        nu2 = np.repeat(nu, 2)
        y2 = np.repeat(y, 2, axis=0)
        ends = np.empty((2 * u, n))
        ends[0::2] = -1.0
        ends[1::2] = 1.0
        _, stop = self._predict(nu2, y2, ends)
        s_min, s_max = stop[0::2], stop[1::2]
        # lower bound: smallest c with stop(c) >= lo_b; bracket (bad, good)
        lo_bad, lo_good = np.full((u, n), -1.0), np.ones((u, n))
        # upper bound: largest c with stop(c) <= hi_b; bracket (good, bad)
        hi_good, hi_bad = -np.ones((u, n)), np.ones((u, n))
        for _ in range(BISECTION_STEPS):
            mid = np.empty((2 * u, n))
            mid[0::2] = 0.5 * (lo_bad + lo_good)
            mid[1::2] = 0.5 * (hi_good + hi_bad)
            _, s = self._predict(nu2, y2, mid)
            ok_lo = s[0::2] >= lo_b
            lo_good = np.where(ok_lo, mid[0::2], lo_good)
            lo_bad = np.where(ok_lo, lo_bad, mid[0::2])
            ok_hi = s[1::2] <= hi_b
            hi_good = np.where(ok_hi, mid[1::2], hi_good)
            hi_bad = np.where(ok_hi, hi_bad, mid[1::2])
        lo = np.where(s_min >= lo_b, -1.0, lo_good)   # -1 already meets it; +1 if none does
        hi = np.where(s_max <= hi_b, 1.0, hi_good)
        hi = np.where(s_min > hi_b, -1.0, hi)
        crossed = lo > hi
        mid = 0.5 * (lo + hi)
        return np.where(crossed, mid, lo), np.where(crossed, mid, hi)

    def _score(self, nu, y, cand, desired):
        """(feasible, distance to desired, tension slack, tension_min) of candidates."""
        tension, stop = self._predict(nu, y, cand)
        t_slack, l_slack = self._slack(tension, stop)
        ok = (t_slack >= 0.0) & (l_slack >= 0.0)
        dist = ((cand - desired) ** 2).sum(axis=1)
        return ok, dist, t_slack, tension

    def _search(self, nu, y, desired):
        """Stages 1-3 of :meth:`project` for the rows whose desired command is unsafe."""
        u, n = desired.shape
        lo, hi = self._length_box(nu, y, desired)
        # stage 1: the clipped command and a lattice over the box, evaluated together
        g = self._lattice
        t = np.linspace(0.0, 1.0, g)
        unit = np.array(list(product(t, repeat=n)))             # (G^n, n)
        cands = np.concatenate([np.clip(desired, lo, hi)[:, None, :],
                                lo[:, None, :] + unit[None] * (hi - lo)[:, None, :]], axis=1)
        lattice = cands
        # stage 2: along every line from the clipped command c0 towards a face or corner
        # of the box (each coordinate kept, or sent to lo or hi), the first safe point
        c0 = lattice[:, 0]
        targets = np.where(self._pattern[None] < 0, lo[:, None, :],
                           np.where(self._pattern[None] > 0, hi[:, None, :], c0[:, None, :]))
        lines = self._first_safe(nu, y, c0, targets)
        best, ok, tmin, slack = self._pick(nu, y, desired,
                                           np.concatenate([lattice, lines], axis=1))
        # stage 3: pattern search around the best point, step halving
        h = (hi - lo) / (2.0 * max(g - 1, 1))
        for _ in range(PATTERN_STEPS):
            moves = np.clip(best[:, None, :] + self._pattern[None] * h[:, None, :],
                            lo[:, None, :], hi[:, None, :])
            cands = np.concatenate([best[:, None, :], moves], axis=1)  # incumbent first
            best, ok, tmin, slack = self._pick(nu, y, desired, cands)
            h = 0.5 * h
        return best, ok, tmin

    def _first_safe(self, nu, y, start, targets):
        """Per row and line start -> target (U, L, n), the first safe point found.

        Bisection on t in [0, 1] of start + t (target - start), assuming one crossing;
        a line whose target is unsafe returns its target (the pick then passes it over).
        """
        u, lines, n = targets.shape
        rep_nu = np.repeat(nu, lines)
        rep_y = np.repeat(y, lines, axis=0)
        step = (targets - start[:, None, :]).reshape(u * lines, n)
        base = np.repeat(start, lines, axis=0)
        bad = np.zeros(u * lines)
        good = np.ones(u * lines)
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (bad + good)
            tension, stop = self._predict(rep_nu, rep_y, base + mid[:, None] * step)
            t_slack, l_slack = self._slack(tension, stop)
            safe = (t_slack >= 0.0) & (l_slack >= 0.0)
            good = np.where(safe, mid, good)
            bad = np.where(safe, bad, mid)
        return (base + good[:, None] * step).reshape(u, lines, n)

    def _pick(self, nu, y, desired, cands):
        """Best candidate per row: the closest feasible one, else the largest tension slack.

        ``cands`` is (U, C, n); ties go to the lowest candidate index (deterministic).
        """
        u, c, n = cands.shape
        flat = cands.reshape(u * c, n)
        ok, dist, slack, tension = self._score(np.repeat(nu, c), np.repeat(y, c, axis=0),
                                               flat, np.repeat(desired, c, axis=0))
        ok = ok.reshape(u, c)
        dist = dist.reshape(u, c)
        slack = slack.reshape(u, c)
        any_ok = ok.any(axis=1)
        key = np.where(ok, dist, np.inf)
        i_ok = np.argmin(key, axis=1)
        i_best = np.argmax(np.where(np.isfinite(slack), slack, -np.inf), axis=1)
        idx = np.where(any_ok, i_ok, i_best)
        r = np.arange(u)
        tension = tension.reshape(u, c, n)
        return cands[r, idx], any_ok, tension[r, idx], slack[r, idx]


def _reals(name: str, value, what: str) -> np.ndarray:
    """``value`` as a float array.

    Raises TypeError naming ``name``, the value and ``what`` it must be unless it holds
    real numbers (no bools, strings, None or complex numbers).
    """
    try:
        raw = np.asarray(value)
    except ValueError:  # ragged nesting
        raw = np.asarray(None, dtype=object)
    if raw.dtype.kind not in "iuf":
        raise TypeError(f"{name}={value!r} must be {what}, got dtype {raw.dtype}")
    return raw.astype(float)


def _count(name: str, value) -> int:
    """``int(value)`` after checking it is an int >= 1 (ValueError naming it otherwise)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name}={value!r} must be an int >= 1")
    return int(value)


def _lattice_size(n: int) -> int:
    """Points per axis of the first search stage: at most MAX_LATTICE in all, >= 3."""
    return max(3, min(17, int(math.floor(MAX_LATTICE ** (1.0 / n) + 1e-9))))
