"""One compiled control step for a batch of environments: physics, task, observation.

Both :class:`~tether_gym.envs.TetherLibrationEnv` (a batch of one) and
:class:`~tether_gym.envs.vector.TetherLibrationVectorEnv` step and reset through
:func:`step_rows`, so their trajectories are identical for the same inputs. For each
listed row it advances the chain (:func:`tether_gym.physics.kernels.advance_one`),
then computes the reward (:mod:`tether_gym.tasks.reward`), the failure code
(:mod:`tether_gym.tasks.termination`), the observation and the ``info`` entries
(:mod:`tether_gym.envs.layout`). The loop is compiled without reference counting
(:mod:`tether_gym.physics.jit`) and releases the GIL, so threads can run disjoint
rows at once; every array it touches comes from the caller: the batch's
:class:`Rows`, the constant :class:`StepConfig` and one :class:`RowWork` per thread.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..physics import kernels
from ..physics.jit import INLINE, LOOP
from ..physics.layout import at
from ..physics.orbit import reel_accel
from ..physics.state import P, S, mass_fraction
from ..tasks.cost import CostParams, cost_terms
from ..tasks.reference import desired_libration_jit
from ..tasks.reward import TERMS, RewardParams, reward_terms, term_sums
from ..tasks.termination import KEEP_PREVIOUS, failure_code
from .actions import next_command
from .layout import I, O
from .workers import DONE, HI, LO, call_address, next_job

__all__ = ["StepConfig", "Rows", "RowWork", "make_row_work", "step_rows"]

LENGTH_FLOOR = 1.0e-6
"""Smallest l [-] whose logarithm the observation takes (a noisy l can reach 0)."""


class StepConfig(NamedTuple):
    """Constants of one batch (from its :class:`~tether_gym.envs.config.EnvConfig`)."""

    max_reel_rate: float          # l'_cmd at |u| = 1 [-]
    incremental: bool             # action_mode "increment": u <- clip(u + gain a, -1, 1)
    increment_gain: float         # gain [-] of the increments
    substeps: kernels.Substeps    # RK4 steps per control step
    amplitude: float              # A [rad] of theta_d = A sin(w nu)
    frequency: float              # w [-]
    length_min: float             # length bounds [-]
    length_max: float
    accel_ref: float              # a_ref / (L0 n^2) [-] of the reward's acceleration term
    accel_scale: float            # L0 n^2 [m/s^2] of info["reel_accel"]
    with_eccentricity: bool       # e closes the observation
    with_masses: bool             # the mass fractions M_i follow it
    reward: RewardParams
    length_nominal: np.ndarray    # (n,) l_i,nom [-] of the length term and observation
    cost: CostParams              # thresholds of the constraint cost (tasks.cost)


class Rows(NamedTuple):
    """The batch's per-row arrays (B rows, n tethers, m = 4n)."""

    nu: np.ndarray           # (B,) true anomaly [rad]
    y: np.ndarray            # (B, m) state rows (STATE layout)
    par: np.ndarray          # (B, P) parameter rows (PARAMS layout)
    disturbance: np.ndarray  # (B, n) d on theta'' held over the step
    noise: np.ndarray        # (B, m) observation noise on the state entries
    obs: np.ndarray          # (B, obs_dim) float32 observations (OBSERVATION layout)
    reward: np.ndarray       # (B,)
    components: np.ndarray   # (B, 1 + len(TERMS))
    cost: np.ndarray         # (B, len(COST_NAMES)) the cost and its parts
    failure: np.ndarray      # (B,) int64 Failure codes
    tension_min: np.ndarray  # (B, n)
    tension: np.ndarray      # (B, n) T^ at the end of the step
    derivative: np.ndarray   # (B, m) dy/dnu at the end of the step
    info_s: np.ndarray       # (scalar entries, B) info buffers (INFO layout)
    info_v: np.ndarray       # (vector entries, B, n)
    steps: np.ndarray        # (B,) int64 control steps since the reset
    nu_end: np.ndarray       # (B,) true anomaly at which the episode is truncated [rad]
    truncated: np.ndarray    # (B,) bool: nu has reached nu_end
    command: np.ndarray      # (B, n) normalised reel-rate command u in [-1, 1] [-]


class RowWork(NamedTuple):
    """Scratch of one thread."""

    physics: kernels.Scratch
    command: np.ndarray   # (n,) l'_cmd [-]
    zero: np.ndarray      # (n,) zeros (no disturbance at reset)
    accel: np.ndarray     # (n,) L_ddot / a_ref
    previous: np.ndarray  # (m,) state before the step
    terms: np.ndarray     # (len(TERMS),) per-term sums


def make_row_work(n: int, n_terms: int) -> RowWork:
    """Fresh :class:`RowWork` for n tethers (plain Python: nothing to compile)."""
    return RowWork(kernels.make_scratch(n), np.empty(n), np.zeros(n), np.empty(n),
                   np.empty(4 * n), np.empty(n_terms))


def new_row_work(n: int) -> RowWork:
    """:func:`make_row_work` for the declared reward terms."""
    return make_row_work(n, len(TERMS))


@njit(**INLINE)
def anomaly_terms(nu, cfg, orbit):
    """(sin nu, cos nu, theta_d, theta_d') at true anomaly nu, computed once per row and step.

    ``orbit`` is the thread's :func:`~tether_gym.physics.kernels.sin_cos_nu` cache: the
    step's last right-hand side was evaluated at this nu.
    """
    ref, dref, _ = desired_libration_jit(nu, cfg.amplitude, cfg.frequency)
    sn, cn = kernels.sin_cos_nu(nu, orbit)
    return sn, cn, ref, dref


@njit(**INLINE)
def write_outputs(b, rows, cfg, anomaly):
    """Row b's observation and ``info`` entries from its state (layouts in envs.layout).

    ``anomaly`` is :func:`anomaly_terms` of the row's nu. The observation gets
    ``rows.noise[b]`` added to its state entries. The derived info entry is the reels'
    physical acceleration L0 n^2 (k^4 l'' - 2 e sin(nu) k^3 l') [m/s^2]
    (:func:`tether_gym.physics.orbit.reel_accel`).
    """
    y = rows.y[b]
    n = y.shape[0] // 4
    nu = rows.nu[b]
    par = rows.par[b] if rows.par.shape[0] > 1 else rows.par[0]
    sn, cn, ref, dref = anomaly
    ecc = par[at(P.eccentricity, n)]
    noise = rows.noise[b]
    out = rows.obs[b]
    out[at(O.sin_nu, n)] = sn
    out[at(O.cos_nu, n)] = cn
    for j in range(n):
        for field, state in ((O.theta, S.theta), (O.dtheta, S.dtheta), (O.length, S.length),
                             (O.dlength, S.dlength)):
            i = at(state, n) + j
            out[at(field, n) + j] = y[i] + noise[i]
    out[at(O.theta_ref, n)] = ref
    out[at(O.dtheta_ref, n)] = dref
    for j in range(n):
        out[at(O.error, n) + j] = out[at(O.theta, n) + j] - ref
        out[at(O.derror, n) + j] = out[at(O.dtheta, n) + j] - dref
        out[at(O.log_length, n) + j] = math.log(max(out[at(O.length, n) + j], LENGTH_FLOOR)
                                                / cfg.length_nominal[j])
        out[at(O.command, n) + j] = rows.command[b, j]
    if cfg.with_eccentricity:
        out[at(O.eccentricity, n)] = ecc
    if cfg.with_masses:
        for j in range(n):
            out[at(O.mass_fractions, n) + j] = mass_fraction(par, j, n)
    s = rows.info_s
    s[I.nu[0], b] = nu
    s[I.theta_ref[0], b] = ref
    s[I.dtheta_ref[0], b] = dref
    s[I.eccentricity[0], b] = ecc
    s[I.failure[0], b] = rows.failure[b]
    for c in range(rows.components.shape[1]):
        s[I.reward_tracking[0] + c, b] = rows.components[b, c]
    for c in range(rows.cost.shape[1]):
        s[I.cost[0] + c, b] = rows.cost[b, c]
    v = rows.info_v
    k = 1.0 + ecc * cn
    der = rows.derivative[b]
    dl = at(S.dlength, n)
    for j in range(n):
        v[I.theta[1], b, j] = y[at(S.theta, n) + j]
        v[I.dtheta[1], b, j] = y[at(S.dtheta, n) + j]
        v[I.length[1], b, j] = y[at(S.length, n) + j]
        v[I.dlength[1], b, j] = y[dl + j]
        v[I.ddlength[1], b, j] = der[dl + j]
        v[I.tension[1], b, j] = rows.tension[b, j]
        v[I.tension_min[1], b, j] = rows.tension_min[b, j]
        v[I.command[1], b, j] = rows.command[b, j]
        v[I.reel_accel[1], b, j] = cfg.accel_scale * reel_accel(k, sn, ecc, y[dl + j],
                                                                der[dl + j])


@njit(**INLINE)
def _task(b, cfg, work, rows, anomaly):
    """Failure code, reward, its components and the cost of row b after its step.

    The cost is computed after a non-finite or diverged step has been replaced by the
    last healthy state, from the tensions set to 0 there: such a step costs
    ``cost_slack`` = 1 at least.
    """
    y = rows.y[b]
    n = y.shape[0] // 4
    par = rows.par[b] if rows.par.shape[0] > 1 else rows.par[0]
    code = failure_code(y, rows.tension_min[b], cfg.length_min, cfg.length_max)
    rows.failure[b] = code
    if code == KEEP_PREVIOUS[0] or code == KEEP_PREVIOUS[1]:
        # non-finite or diverged: keep the last healthy state, lowest reward
        for i in range(y.shape[0]):
            y[i] = work.previous[i]
        for c in range(rows.components.shape[1]):
            rows.components[b, c] = 0.0
        rows.reward[b] = 0.0
        for j in range(n):
            if not math.isfinite(rows.tension[b, j]):
                rows.tension[b, j] = 0.0
            if not math.isfinite(rows.tension_min[b, j]):
                rows.tension_min[b, j] = 0.0
        for i in range(y.shape[0]):
            if not math.isfinite(rows.derivative[b, i]):
                rows.derivative[b, i] = 0.0
        cost_terms(y, n, rows.tension_min[b], cfg.cost, rows.cost[b])
        return
    cost_terms(y, n, rows.tension_min[b], cfg.cost, rows.cost[b])
    sn, cn, ref, dref = anomaly
    ecc = par[at(P.eccentricity, n)]
    k = 1.0 + ecc * cn
    dl = at(S.dlength, n)
    for j in range(n):
        work.accel[j] = reel_accel(k, sn, ecc, y[dl + j], rows.derivative[b, dl + j]) \
            / cfg.accel_ref
    term_sums(y, n, rows.command[b], work.accel, rows.tension_min[b], cfg.length_nominal,
              cfg.reward, work.terms)
    rows.reward[b] = reward_terms(y, n, ref, dref, cfg.reward, work.terms, rows.components[b])


@njit(**INLINE)
def first_bad_action(index, lo, hi, action, n):
    """The first of the rows ``index[lo:hi]`` whose action is NaN or inf, or -1."""
    for i in range(lo, hi):
        for j in range(n):
            if not math.isfinite(action[index[i], j]):
                return index[i]
    return -1


@njit(**INLINE)
def step_row(b, action, rows, cfg, work, reset):
    """One control step of row b in place (or, with ``reset``, its evaluation at reset).

    The row code of :func:`step_rows`, which documents it; ``work`` is the calling
    thread's scratch. Also compiled for a CUDA GPU by numba-cuda, one row per thread
    (``bench/numba_cuda_ptx.py``).
    """
    m = rows.y.shape[1]
    n = m // 4
    yb = rows.y[b]
    pb = rows.par[0] if rows.par.shape[0] == 1 else rows.par[b]
    out = kernels.StepOutputs(rows.tension_min[b], rows.derivative[b], rows.tension[b])
    if reset:  # evaluate only: the reels hold their rate, no disturbance
        for j in range(n):
            work.command[j] = yb[at(S.dlength, n) + j]
            rows.command[b, j] = min(max(work.command[j] / cfg.max_reel_rate, -1.0), 1.0)
        inputs = kernels.StepInputs(work.command, work.zero)
        substeps = kernels.Substeps(cfg.substeps.h, 0)
    else:
        for k in range(m):
            work.previous[k] = yb[k]
        for j in range(n):
            a = next_command(rows.command[b, j], action[b, j], cfg.incremental,
                             cfg.increment_gain)
            rows.command[b, j] = a
            work.command[j] = a * cfg.max_reel_rate
        inputs = kernels.StepInputs(work.command, rows.disturbance[b])
        substeps = cfg.substeps
    rows.nu[b] = kernels.advance_one(rows.nu[b], yb, inputs, pb, substeps,
                                     work.physics, out)
    anomaly = anomaly_terms(rows.nu[b], cfg, work.physics.orbit)
    if reset:
        rows.steps[b] = 0
    else:
        rows.steps[b] += 1
        _task(b, cfg, work, rows, anomaly)
    rows.truncated[b] = rows.nu[b] >= rows.nu_end[b] - 1e-9
    write_outputs(b, rows, cfg, anomaly)


@njit(nogil=True, **LOOP)
def step_rows(index, action, rows, cfg, work, reset, relay):
    """One control step of the rows listed in ``index`` (int64), in place; others untouched.

    ``action`` (B, n) holds the actions; they set the normalised command u
    (``rows.command``) by :func:`~tether_gym.envs.actions.next_command`: u = clip(action,
    -1, 1), or u <- clip(u + gain * clip(action, -1, 1), -1, 1) with ``cfg.incremental``;
    l'_cmd = u * max_reel_rate. Returns -1, or, before
    anything is stepped, the first listed row whose action is NaN or inf (then no row
    is touched). With ``reset`` True the listed rows, whose ``nu``, ``y``, ``par``,
    ``noise`` and ``nu_end`` were just set, are not stepped: they get dy/dnu and T^ at
    their initial state with the reels holding their rate (the state the first step
    starts from), their observation and info entries, zero steps and the command u =
    clip(l' / max_reel_rate, -1, 1) (the reels' rate); their failure code, reward and
    reward components must be zero.

    A row whose state turns non-finite keeps its previous state (so nothing
    non-finite reaches the observation) and gets failure code 1 and reward 0.

    ``relay`` (:class:`~tether_gym.envs.workers.Relay`): with ``polls`` 0 (every call
    but a worker thread's) the listed rows are stepped once. With ``polls`` > 0 the call
    serves the worker thread of ``relay.ctl`` instead (:mod:`.workers`): it steps
    ``index[LO:HI]`` of each job posted there, sets ``DONE`` after each, and returns -1
    when no job came for ``polls`` polls or ``STOP`` is set. Serving lives here, around
    the one copy of the row code, so that the step is compiled once.
    """
    n = rows.y.shape[1] // 4
    ctl = relay.ctl
    serving = relay.polls > 0
    seen = ctl[DONE]
    lo = 0
    hi = index.shape[0]
    while True:
        job = seen
        if serving:
            job = next_job(relay, seen)
            if job < 0:
                return -1
            lo = ctl[LO]
            hi = ctl[HI]
        bad = -1 if reset else first_bad_action(index, lo, hi, action, n)
        for i in range(lo, hi if bad < 0 else lo):
            step_row(index[i], action, rows, cfg, work, reset)
        if not serving:
            return bad
        call_address(relay.give_up)  # a compiler barrier: the rows are written before DONE
        ctl[DONE] = job
        seen = job
