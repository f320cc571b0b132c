"""Compiled kernels: the one copy of the chain's equations of motion.

Everything that moves the chain (TetherChain's public methods, the single and the
vector environment, the sliding-mode controller through ``control_affine``) calls
these functions. They work on one state at a time inside loops over a leading batch
axis, so there is no per-state Python overhead.

Model and notation (Shi, Zhu & Zhu 2019, Sec. 2; docs/model.md#equations-of-motion)
-----------------------------------------------------------------------------------
Orbital frame (e_r radial outward, e_v along-track). Tether j (j = 1..n, n = N-1)
joins body j-1 to body j; its direction is e_j = (cos th_j, sin th_j) in (e_r, e_v)
components, pointing from body j to body j-1, so body i sits at
rho_i = -sum_{k<=i} l_k e_k (paper Eq. 1). th_j > 0: body j trails body j-1.
e_j^perp = (-sin th_j, cos th_j). With phi_j = nu + th_j the inertial angle of
tether j, Newton's law for the bodies j..n (the Lagrange equations Eq. 4 with the
generalised forces of Eq. 5 reduce to exactly this, component by component) reads

    sum_{i>=j} M_i (rho_i'' - g_i) = T^_j e_j,                                  (*)

the e_j^perp component being the theta-equation (Eq. 6a) and the e_j component
the tension (Eq. 6b). Writing it in the dimensionless variables of Sec. 2
(q = 2 e sin(nu) / k, w_k = 1 + th_k', Mt_jk = sum_{i >= max(j,k)} M_i,
c_jk = cos(th_k - th_j), s_jk = sin(th_k - th_j),
lam_k = l_k'' - q l_k'  (= L_k_ddot / (nu_dot^2 L0)),
sig_k = w_k (2 l_k' - q l_k)):

    theta:   sum_k Mt_jk [ (lam_k - l_k w_k^2) s_jk + (l_k th_k'' + sig_k) c_jk ] + G^perp_j = 0
    tension: T^_j = sum_k Mt_jk [ -(lam_k - l_k w_k^2) c_jk + (l_k th_k'' + sig_k) s_jk ] - G^par_j

where G_j = sum_{i>=j} M_i g_i is the dimensionless gravity (relative to the main
satellite) of the bodies below tether j, projected on e_j^perp and e_j:

    gradient:  g_i = (2 rho_ir, -rho_iv) / k
    full:      g_i = -[(e_r + x_i) |e_r + x_i|^-3 - e_r] / (k^2 eps),  x_i = k eps rho_i,
               eps = L0 / p (expands to the gradient form for eps -> 0).

The theta-equations are A th'' + b0 + P l' + Q l'' = 0 with A_jk = Mt_jk l_k c_jk,
P_jk = Mt_jk (2 w_k c_jk - q s_jk), Q_jk = Mt_jk s_jk, hence
th'' = f + B l' + D l'' with f = -A^-1 b0, B = -A^-1 P, D = -A^-1 Q.
diag(l) A is the (symmetric positive definite) mass matrix of the angles, so the
solve needs no pivoting. For N = 2 this reduces to the single-tether
equation th'' = -2 (l'/l - e sin(nu)/k)(1 + th') - 3 sin(2 th) / (2k).

The state row y and the parameter row par are laid out as declared in
:mod:`tether_gym.physics.state` (``STATE``, ``PARAMS``); the kernels read them through
the offsets ``S`` and ``P`` derived from those declarations.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .integrators import make_rk4
from .jit import INLINE, LOOP
from .layout import at
from .orbit import coriolis, ddlength_from_accel
from .state import GRAVITY_FULL_CODE, P, S, mass_fraction

__all__ = ["Scratch", "Substeps", "StepInputs", "StepOutputs", "make_scratch", "sin_cos_nu",
           "advance_one", "controlled_rhs", "transition_rows", "accel_rows", "affine_rows"]


class Scratch(NamedTuple):
    """Work arrays of one thread: SPD solve, link terms, tensions, RK4 stages, orbit cache.

    The solve uses S and R, the link terms V, and ``orbit`` holds the last
    (nu, sin nu, cos nu) (:func:`sin_cos_nu`).
    """

    S: np.ndarray        # (n, n)
    R: np.ndarray        # (n, 1)
    V: np.ndarray        # (7, n)
    tension: np.ndarray  # (n,)
    k1: np.ndarray       # (4n,) RK4 stages, then the stage input
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray
    tmp: np.ndarray
    orbit: np.ndarray    # (3,) nu, sin nu, cos nu; nu NaN before the first evaluation


class Substeps(NamedTuple):
    """How one control step is integrated: ``number`` RK4 steps of ``h`` [rad]."""

    h: float
    number: int


class StepInputs(NamedTuple):
    """Per-chain inputs held over a step: commanded l'_cmd [-] and the Eq. 20 disturbance d."""

    command: np.ndarray      # (n,)
    disturbance: np.ndarray  # (n,) added to theta''


class StepOutputs(NamedTuple):
    """Per-chain results of :func:`advance_one` besides the new state."""

    tension_min: np.ndarray  # (n,) smallest T^ over the substep boundaries
    derivative: np.ndarray   # (4n,) dy/dnu at the final state (holds theta'', l'')
    tension: np.ndarray      # (n,) T^ at the final state


def make_scratch(n: int) -> Scratch:
    """Fresh :class:`Scratch` for n tethers (one per thread).

    Plain Python: a compiled allocator would add to the compile time of every cold
    start.
    """
    m = 4 * n
    return Scratch(np.empty((n, n)), np.empty((n, 1)), np.empty((7, n)), np.empty(n),
                   np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
                   np.full(3, np.nan))


# --------------------------------------------------------------------------- #
# equations of motion
# --------------------------------------------------------------------------- #
# Hot helpers are inlined (inline="always") and index one state row
# y = [theta, theta', l, l'] with offsets instead of slicing it: a call or a view
# passes arrays as structs, which cost more than the arithmetic of a short chain (and,
# with numba's reference counting, atomic operations: the loops that inline them are
# compiled without it, see jit.py). The right-hand side and the step built from it
# (controlled_rhs, advance_one) are compiled as functions of their own instead: numba's
# IR-level inlining deep-copies the callee's IR at every level, and inlining these two
# made up a large share of the cold start (figures: bench/README.md), while compiling
# them apart keeps the trajectories bitwise identical. The small
# sin_cos_nu, called from two files, is compiled with LOOP and left to LLVM to inline,
# like physics.layout.at.
@njit(**LOOP)
def sin_cos_nu(nu, orbit):
    """(sin nu, cos nu), computed only when nu differs from the last call's (``orbit``).

    A step evaluates the right-hand side at 9 true anomalies of which 5 differ (RK4's
    two middle stages share one, a substep's end is the next one's start, and the
    step's last evaluation is at its end), and the observation reads the end's again.
    ``orbit`` = (nu, sin nu, cos nu) of the last computation, per thread.
    """
    if nu != orbit[0]:
        orbit[0] = nu
        orbit[1] = math.sin(nu)
        orbit[2] = math.cos(nu)
    return orbit[1], orbit[2]


@njit(**INLINE)
def _links(nu, y, n, par, work):
    """Link trigonometry and the projected tail gravity; returns (q, sin nu, k).

    ``work.V`` rows: 0 cos th, 1 sin th, 2 w = 1 + th', 3 G^perp, 4 G^par, 5..6 scratch.
    """
    V = work.V
    ecc = par[at(P.eccentricity, n)]
    sn, cn = sin_cos_nu(nu, work.orbit)
    k = 1.0 + ecc * cn
    q = 2.0 * ecc * sn / k
    th = at(S.theta, n)
    dth = at(S.dtheta, n)
    ln = at(S.length, n)
    for i in range(n):
        # one load of theta_i: the compiler then pairs cos and sin into one sincos call
        # (with two loads it must assume the store to V may have changed y)
        angle = y[th + i]
        V[0, i] = math.cos(angle)
        V[1, i] = math.sin(angle)
        V[2, i] = 1.0 + y[dth + i]
    # body positions rho_i and their gravity g_i (relative to the main satellite)
    rr = 0.0
    rv = 0.0
    full = par[at(P.gravity, n)] == GRAVITY_FULL_CODE
    eps = par[at(P.length_ratio, n)]
    for i in range(n):
        rr -= y[ln + i] * V[0, i]
        rv -= y[ln + i] * V[1, i]
        if full:
            xr = k * eps * rr
            xv = k * eps * rv
            qq = 2.0 * xr + xr * xr + xv * xv
            fm = math.expm1(-1.5 * math.log1p(qq))  # |e_r + x|^-3 - 1
            scale = -1.0 / (k * k * eps)
            V[5, i] = scale * (fm + xr * (1.0 + fm))
            V[6, i] = scale * (xv * (1.0 + fm))
        else:
            V[5, i] = 2.0 * rr / k
            V[6, i] = -rv / k
    # tail sums G_j = sum_{i>=j} M_i g_i, projected on e_j^perp and e_j
    Gr = 0.0
    Gv = 0.0
    for j in range(n - 1, -1, -1):
        mass = mass_fraction(par, j, n)
        Gr += mass * V[5, j]
        Gv += mass * V[6, j]
        V[3, j] = -Gr * V[1, j] + Gv * V[0, j]
        V[4, j] = Gr * V[0, j] + Gv * V[1, j]
    return q, sn, k


@njit(**INLINE)
def _coefficients(j, kk, y, n, par, V, q):
    """Entries (j, k) of the theta-equations: (diag(l) A, P, Q, b0 term) (module doc)."""
    mt = par[at(P.tail_mass, n) + max(j, kk)]
    c = V[0, kk] * V[0, j] + V[1, kk] * V[1, j]
    s = V[1, kk] * V[0, j] - V[0, kk] * V[1, j]
    ln = at(S.length, n)
    lk = y[ln + kk]
    wk = V[2, kk]
    return (mt * y[ln + j] * lk * c,
            mt * (2.0 * wk * c - q * s),
            mt * s,
            -mt * lk * wk * (wk * s + q * c))


@njit(**INLINE)
def _solve_spd(S_, R):
    """R <- S^-1 R for symmetric positive definite S (destroyed), R of shape (n, m)."""
    n = S_.shape[0]
    m = R.shape[1]
    for p in range(n):
        inv = 1.0 / S_[p, p]
        for i in range(p + 1, n):
            fac = S_[i, p] * inv
            if fac != 0.0:
                for j in range(p + 1, n):
                    S_[i, j] -= fac * S_[p, j]
                for c in range(m):
                    R[i, c] -= fac * R[p, c]
    for p in range(n - 1, -1, -1):
        for c in range(m):
            acc = R[p, c]
            for j in range(p + 1, n):
                acc -= S_[p, j] * R[j, c]
            R[p, c] = acc / S_[p, p]


@njit(**INLINE)
def _theta_ddot(y, n, ddl, ddl_off, par, work, q, out, out_off):
    """theta'' into out[out_off:] from work.V (after :func:`_links`); l'' = ddl[ddl_off:]."""
    S_, R, V = work.S, work.R, work.V
    ln = at(S.length, n)
    dl = at(S.dlength, n)
    for j in range(n):
        b = V[3, j]
        for kk in range(n):
            s_jk, p_jk, q_jk, b_jk = _coefficients(j, kk, y, n, par, V, q)
            S_[j, kk] = s_jk
            b += b_jk + p_jk * y[dl + kk] + q_jk * ddl[ddl_off + kk]
        R[j, 0] = -y[ln + j] * b
    _solve_spd(S_, R)
    for j in range(n):
        out[out_off + j] = R[j, 0]


@njit(**INLINE)
def _tension(y, n, ddl, ddl_off, ddth, ddth_off, par, V, q, tension):
    """T^ from the e_j components of (*) (module docstring)."""
    ln = at(S.length, n)
    dl = at(S.dlength, n)
    for j in range(n):
        acc = -V[4, j]
        for kk in range(n):
            mt = par[at(P.tail_mass, n) + max(j, kk)]
            c = V[0, kk] * V[0, j] + V[1, kk] * V[1, j]
            s = V[1, kk] * V[0, j] - V[0, kk] * V[1, j]
            lk = y[ln + kk]
            dlk = y[dl + kk]
            wk = V[2, kk]
            lam = ddl[ddl_off + kk] - q * dlk
            sig = wk * (2.0 * dlk - q * lk)
            acc += mt * (-(lam - lk * wk * wk) * c + (lk * ddth[ddth_off + kk] + sig) * s)
        tension[j] = acc


# --------------------------------------------------------------------------- #
# reel actuator
# --------------------------------------------------------------------------- #
@njit(**INLINE)
def _reel(k, sn, dlength, command, ecc, par, n):
    """Actual l'' [-] of one reel given its rate l' and the commanded rate l'_cmd.

    The reel follows the command as a first-order lag in l' with time constant tau
    [rad], l''_des = (l'_cmd - l') / tau, and its physical acceleration
    L_ddot / (L0 n^2) = k^4 l'' - 2 e sin(nu) k^3 l' (:func:`~.orbit.reel_accel`) is
    saturated at +-a_bound; the command is first clipped to the speed bound
    |L_dot| / (L0 n) = k^2 |l'| <= v_bound (bounds from the parameter row).
    """
    a_bound = par[at(P.accel_bound, n)]
    v_bound = par[at(P.speed_bound, n)]
    tau = par[at(P.time_constant, n)]
    k2 = k * k
    k4 = k2 * k2
    cmd = command
    if v_bound < math.inf:
        cap = v_bound / k2
        cmd = min(max(cmd, -cap), cap)
    cor = coriolis(k, sn, ecc, dlength)
    a = k4 * (cmd - dlength) / tau - cor
    a = min(max(a, -a_bound), a_bound)
    return ddlength_from_accel(k4, cor, a)


class RhsArgs(NamedTuple):
    """Everything the controlled right-hand side needs besides (nu, y)."""

    inputs: StepInputs
    par: np.ndarray
    work: Scratch
    tension_min: np.ndarray  # (n,) running minimum of T^ over the grid nodes


@njit(**LOOP)
def controlled_rhs(nu, y, args, dy, node):
    """dy/dnu of the chain with its reels (:class:`RhsArgs`), the integrator's ``fun``.

    The reels follow the commanded rates l'_cmd (:func:`_reel`); the disturbance d is
    added to theta'' (paper Eq. 20, f_d = f + d). At a grid node (``node``) the
    tension T^ at (nu, y) is computed too, into ``work.tension``, and folded into
    ``args.tension_min``: it depends on theta'' but not the other way round, so it
    is computed only where it is used.
    """
    inputs, par, work = args.inputs, args.par, args.work
    cmd = inputs.command
    n = cmd.shape[0]
    q, sn, k = _links(nu, y, n, par, work)
    ecc = par[at(P.eccentricity, n)]
    th = at(S.theta, n)
    dth = at(S.dtheta, n)
    ln = at(S.length, n)
    dlo = at(S.dlength, n)
    for j in range(n):
        dl = y[dlo + j]
        dy[th + j] = y[dth + j]
        dy[ln + j] = dl
        dy[dlo + j] = _reel(k, sn, dl, cmd[j], ecc, par, n)
    _theta_ddot(y, n, dy, dlo, par, work, q, dy, dth)
    if node:
        _tension(y, n, dy, dlo, dy, dth, par, work.V, q, work.tension)
        for j in range(n):
            args.tension_min[j] = min(args.tension_min[j], work.tension[j])
    dist = inputs.disturbance
    for j in range(n):
        dy[dth + j] += dist[j]


integrate = make_rk4(controlled_rhs)


@njit(**LOOP)
def advance_one(nu, y, inputs, par, substeps, work, out):
    """Advance one state (nu, y) by ``substeps`` (RK4 steps of size h [rad]); y in place.

    Returns the final true anomaly. ``out`` (:class:`StepOutputs`) receives the
    minimum T^ over the substep boundaries (both ends included), dy/dnu at the
    final state (it holds theta'' and l'') and T^ at the final state. With
    ``substeps.number == 0`` only the derivative and tension at (nu, y) are evaluated.
    """
    n = inputs.command.shape[0]
    for j in range(n):
        out.tension_min[j] = math.inf
    args = RhsArgs(inputs, par, work, out.tension_min)
    t = integrate(nu, y, substeps.h, substeps.number, args,
                  (work.k1, work.k2, work.k3, work.k4, work.tmp), out.derivative)
    for j in range(n):
        out.tension[j] = work.tension[j]
    return t


# --------------------------------------------------------------------------- #
# batched entry points (the public face is tether_gym.physics.dynamics)
# --------------------------------------------------------------------------- #
@njit(**LOOP)
def transition_rows(nu, y, inputs, par, substeps, out, work):
    """:func:`advance_one` for every row of (nu (B,), y (B, 4n)), in place.

    ``inputs`` and ``out`` hold (B, ...) arrays; ``par`` is (B, P) or (1, P) (shared).
    """
    shared = par.shape[0] == 1
    for b in range(y.shape[0]):
        pb = par[0] if shared else par[b]
        nu[b] = advance_one(nu[b], y[b], StepInputs(inputs.command[b], inputs.disturbance[b]),
                            pb, substeps,
                            work, StepOutputs(out.tension_min[b], out.derivative[b],
                                              out.tension[b]))


@njit(**LOOP)
def accel_rows(nu, y, ddlength, par, ddtheta, tension, work):
    """theta'' and T^ for every state row y (B, 4n) and its l'' (B, n)."""
    n = ddlength.shape[1]
    shared = par.shape[0] == 1
    for b in range(y.shape[0]):
        pb = par[0] if shared else par[b]
        q, sn, k = _links(nu[b], y[b], n, pb, work)
        _theta_ddot(y[b], n, ddlength[b], 0, pb, work, q, ddtheta[b], 0)
        _tension(y[b], n, ddlength[b], 0, ddtheta[b], 0, pb, work.V, q, tension[b])


@njit(**LOOP)
def affine_rows(nu, y, par, f, Bmat, Dmat, work, R):
    """(f, B, D) of theta'' = f + B l' + D l'' for every state row (its l' is not used).

    ``R`` is (n, 1 + 2n) scratch beside ``work``.
    """
    n = f.shape[1]
    ln = at(S.length, n)
    shared = par.shape[0] == 1
    for b in range(y.shape[0]):
        pb = par[0] if shared else par[b]
        yb = y[b]
        q, sn, k = _links(nu[b], yb, n, pb, work)
        S_ = work.S
        for j in range(n):
            b0 = work.V[3, j]
            for kk in range(n):
                s_jk, p_jk, q_jk, b_jk = _coefficients(j, kk, yb, n, pb, work.V, q)
                S_[j, kk] = s_jk
                lj = yb[ln + j]
                R[j, 1 + kk] = -lj * p_jk
                R[j, 1 + n + kk] = -lj * q_jk
                b0 += b_jk
            R[j, 0] = -yb[ln + j] * b0
        _solve_spd(S_, R)
        for j in range(n):
            f[b, j] = R[j, 0]
            for kk in range(n):
                Bmat[b, j, kk] = R[j, 1 + kk]
                Dmat[b, j, kk] = R[j, 1 + n + kk]
