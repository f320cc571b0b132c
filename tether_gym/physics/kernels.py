"""Compiled kernels: the one copy of the chain's equations of motion.

Everything that moves the chain (TetherChain's public methods, the single and the
vector environment, the sliding-mode controller through ``control_affine``) calls
these functions. They work on one state at a time inside loops over a leading batch
axis, so there is no per-state Python overhead.

Model and notation (Shi, Zhu & Zhu 2019, Sec. 2; shared/paper/NOTES.md)
-----------------------------------------------------------------------
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
solve needs no pivoting. For N = 2 this reduces to NOTES.md's single-tether
equation th'' = -2 (l'/l - e sin(nu)/k)(1 + th') - 3 sin(2 th) / (2k).

Parameter row layout (``par``; built by :func:`pack_params`):
``[e, gravity (0 gradient, 1 full), eps = L0/p, a_bound, v_bound, tau, Mt_1..Mt_n]``
with a_bound = a_max / (L0 n^2) and v_bound = v_max / (L0 n) (inf for no limit).
State row layout (``y``): ``[th_1..th_n, th_1'..th_n', l_1..l_n, l_1'..l_n']``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .integrators import make_rk4
from .jit import INLINE, KERNEL, LOOP

P_ECC, P_GRAV, P_EPS, P_ABOUND, P_VBOUND, P_TAU, P_TAIL = range(7)
GRAVITY_GRADIENT = 0
GRAVITY_FULL = 1
LANE_STRIDE = 8
"""Lane c of the scratch arrays is slot c * LANE_STRIDE: with the slots between left
unused, two threads never write to the same 64-byte cache line (no false sharing)."""


def pack_params(eccentricity, tail_masses, gravity=GRAVITY_GRADIENT, length_ratio=0.0,
                accel_bound=math.inf, speed_bound=math.inf, time_constant=1.0):
    """Pack one parameter row (see the module docstring) as a float64 array."""
    tail = np.asarray(tail_masses, dtype=float)
    head = [eccentricity, float(gravity), length_ratio, accel_bound, speed_bound, time_constant]
    return np.concatenate([np.asarray(head, dtype=float), tail])


# --------------------------------------------------------------------------- #
# equations of motion
# --------------------------------------------------------------------------- #
# Hot helpers are inlined (inline="always") and index one state row
# y = [theta, theta', l, l'] with offsets instead of slicing it: a call or a view
# passes arrays as structs, which cost more than the arithmetic of a short chain (and,
# with numba's reference counting, atomic operations: the loops that inline them are
# compiled without it, see jit.py).
@njit(**INLINE)
def _links(nu, y, n, par, V):
    """Link trigonometry and the projected tail gravity; returns (q, sin nu, k).

    V rows: 0 cos th, 1 sin th, 2 w = 1 + th', 3 G^perp, 4 G^par, 5..6 scratch.
    """
    ecc = par[P_ECC]
    sn = math.sin(nu)
    k = 1.0 + ecc * math.cos(nu)
    q = 2.0 * ecc * sn / k
    for i in range(n):
        V[0, i] = math.cos(y[i])
        V[1, i] = math.sin(y[i])
        V[2, i] = 1.0 + y[n + i]
    # body positions rho_i and their gravity g_i (relative to the main satellite)
    rr = 0.0
    rv = 0.0
    full = par[P_GRAV] == GRAVITY_FULL
    eps = par[P_EPS]
    for i in range(n):
        rr -= y[2 * n + i] * V[0, i]
        rv -= y[2 * n + i] * V[1, i]
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
        mass = par[P_TAIL + j] - (par[P_TAIL + j + 1] if j + 1 < n else 0.0)
        Gr += mass * V[5, j]
        Gv += mass * V[6, j]
        V[3, j] = -Gr * V[1, j] + Gv * V[0, j]
        V[4, j] = Gr * V[0, j] + Gv * V[1, j]
    return q, sn, k


@njit(**INLINE)
def _coefficients(j, kk, y, n, par, V, q):
    """Entries (j, k) of the theta-equations: (diag(l) A, P, Q, b0 term) (module doc)."""
    mt = par[P_TAIL + max(j, kk)]
    c = V[0, kk] * V[0, j] + V[1, kk] * V[1, j]
    s = V[1, kk] * V[0, j] - V[0, kk] * V[1, j]
    lk = y[2 * n + kk]
    wk = V[2, kk]
    return (mt * y[2 * n + j] * lk * c,
            mt * (2.0 * wk * c - q * s),
            mt * s,
            -mt * lk * wk * (wk * s + q * c))


@njit(**INLINE)
def _solve_spd(S, R):
    """R <- S^-1 R for symmetric positive definite S (destroyed), R of shape (n, m)."""
    n = S.shape[0]
    m = R.shape[1]
    for p in range(n):
        inv = 1.0 / S[p, p]
        for i in range(p + 1, n):
            fac = S[i, p] * inv
            if fac != 0.0:
                for j in range(p + 1, n):
                    S[i, j] -= fac * S[p, j]
                for c in range(m):
                    R[i, c] -= fac * R[p, c]
    for p in range(n - 1, -1, -1):
        for c in range(m):
            acc = R[p, c]
            for j in range(p + 1, n):
                acc -= S[p, j] * R[j, c]
            R[p, c] = acc / S[p, p]


@njit(**INLINE)
def _theta_ddot(y, n, ddl, ddl_off, par, S, R, V, q, out, out_off):
    """theta'' into out[out_off:] from V (after :func:`_links`); l'' = ddl[ddl_off:]."""
    for j in range(n):
        b = V[3, j]
        for kk in range(n):
            s_jk, p_jk, q_jk, b_jk = _coefficients(j, kk, y, n, par, V, q)
            S[j, kk] = s_jk
            b += b_jk + p_jk * y[3 * n + kk] + q_jk * ddl[ddl_off + kk]
        R[j, 0] = -y[2 * n + j] * b
    _solve_spd(S, R)
    for j in range(n):
        out[out_off + j] = R[j, 0]


@njit(**INLINE)
def _tension(y, n, ddl, ddl_off, ddth, ddth_off, par, V, q, tension):
    """T^ from the e_j components of (*) (module docstring)."""
    for j in range(n):
        acc = -V[4, j]
        for kk in range(n):
            mt = par[P_TAIL + max(j, kk)]
            c = V[0, kk] * V[0, j] + V[1, kk] * V[1, j]
            s = V[1, kk] * V[0, j] - V[0, kk] * V[1, j]
            lk = y[2 * n + kk]
            dlk = y[3 * n + kk]
            wk = V[2, kk]
            lam = ddl[ddl_off + kk] - q * dlk
            sig = wk * (2.0 * dlk - q * lk)
            acc += mt * (-(lam - lk * wk * wk) * c + (lk * ddth[ddth_off + kk] + sig) * s)
        tension[j] = acc


@njit(**LOOP)
def _accel(nu, y, ddlength, par, S, R, V, ddtheta, tension):
    """theta'' and T^ for one state row y and its l''; R is (n, 1) scratch."""
    n = ddlength.shape[0]
    q, sn, k = _links(nu, y, n, par, V)
    _theta_ddot(y, n, ddlength, 0, par, S, R, V, q, ddtheta, 0)
    _tension(y, n, ddlength, 0, ddtheta, 0, par, V, q, tension)


@njit(**LOOP)
def _assemble(nu, y, n, par, S, rhs, P, Q, V):
    """Fill the affine theta-equations (rows scaled by l_j) for one state row y.

    S <- diag(l) A (symmetric), rhs[:, 0] <- -diag(l) b0, P <- P, Q <- Q (unscaled).
    """
    q, sn, k = _links(nu, y, n, par, V)
    for j in range(n):
        b0 = V[3, j]
        for kk in range(n):
            s_jk, p_jk, q_jk, b_jk = _coefficients(j, kk, y, n, par, V, q)
            S[j, kk] = s_jk
            P[j, kk] = p_jk
            Q[j, kk] = q_jk
            b0 += b_jk
        rhs[j, 0] = -y[2 * n + j] * b0


# --------------------------------------------------------------------------- #
# reel actuator
# --------------------------------------------------------------------------- #
@njit(**INLINE)
def _reel(k, sn, dlength, command, ecc, a_bound, v_bound, tau):
    """:func:`reel_ddlength` with k = 1 + e cos(nu) and sin(nu) given."""
    k2 = k * k
    k4 = k2 * k2
    cmd = command
    if v_bound < math.inf:
        cap = v_bound / k2
        cmd = min(max(cmd, -cap), cap)
    coriolis = 2.0 * ecc * sn * k2 * k * dlength
    a = k4 * (cmd - dlength) / tau - coriolis
    a = min(max(a, -a_bound), a_bound)
    return (a + coriolis) / k4


@njit(**LOOP)
def reel_ddlength(nu, dlength, command, ecc, a_bound, v_bound, tau):
    """Actual l'' [-] of one reel given its rate l' and the commanded rate l'_cmd.

    The reel follows the command as a first-order lag in l' with time constant tau
    [rad], l''_des = (l'_cmd - l') / tau, and its physical acceleration
    L_ddot / (L0 n^2) = k^4 l'' - 2 e sin(nu) k^3 l' is saturated at +-a_bound; the
    command is first clipped to the speed bound |L_dot| / (L0 n) = k^2 |l'| <= v_bound.
    """
    return _reel(1.0 + ecc * math.cos(nu), math.sin(nu), dlength, command, ecc, a_bound,
                 v_bound, tau)


@njit(**INLINE)
def _controlled(nu, y, args, dy, with_tension):
    cmd, dist, par, S, R, V, tension = args
    n = cmd.shape[0]
    q, sn, k = _links(nu, y, n, par, V)
    ecc = par[P_ECC]
    for j in range(n):
        dl = y[3 * n + j]
        dy[j] = y[n + j]
        dy[2 * n + j] = dl
        dy[3 * n + j] = _reel(k, sn, dl, cmd[j], ecc, par[P_ABOUND], par[P_VBOUND], par[P_TAU])
    _theta_ddot(y, n, dy, 3 * n, par, S, R, V, q, dy, n)
    if with_tension:
        _tension(y, n, dy, 3 * n, dy, n, par, V, q, tension)
    for j in range(n):
        dy[n + j] += dist[j]


@njit(**INLINE)
def controlled_rhs(nu, y, args, dy):
    """dy/dnu of the chain with its reels.

    ``args = (cmd, dist, par, S, R, V, tension)``: commanded reel rates l'_cmd, a
    disturbance d added to theta'' (paper Eq. 20, f_d = f + d), the parameter row and
    scratch.
    """
    _controlled(nu, y, args, dy, False)


@njit(**INLINE)
def controlled_rhs_tension(nu, y, args, dy):
    """:func:`controlled_rhs` that also writes the tension T^ at (nu, y) into ``args[6]``.

    The tension depends on theta'' but not the other way round, so it is computed
    only where it is used (at the RK4 substep boundaries).
    """
    _controlled(nu, y, args, dy, True)


rk4_step = make_rk4(controlled_rhs)


@njit(**KERNEL)
def make_scratch(n, lanes):
    """Work arrays for :func:`advance_one` with n tethers, one set per lane.

    Each lane (a thread's chunk of rows, or lane 0 for a serial loop) gets its own
    slice of every array; :func:`scratch_lane` returns lane c's set in the layout
    :func:`advance_one` takes.
    """
    m = 4 * n
    slots = lanes * LANE_STRIDE
    return (np.empty((slots, n, n)), np.empty((slots, n, 1)), np.empty((slots, 9, n)),
            np.empty((slots, n)), np.empty((slots, 6, m)))


@njit(**INLINE)
def scratch_lane(scratch, c):
    """Lane c of :func:`make_scratch`: (S, R, V, tension, k1, (k2, k3, k4, tmp), ybuf)."""
    S, R, V, tens, K = scratch
    i = c * LANE_STRIDE
    return (S[i], R[i], V[i], tens[i], K[i, 0], (K[i, 1], K[i, 2], K[i, 3], K[i, 4]), K[i, 5])


@njit(**INLINE)
def advance_one(nu, y, cmd, dist, par, h, n_sub, scratch, tension_min, deriv_end, tension_end):
    """Advance one state (nu, y) by ``n_sub`` RK4 steps of size ``h`` [rad]; y in place.

    Returns the final true anomaly. ``tension_min`` receives the minimum T^ over the
    substep boundaries (both ends included), ``deriv_end`` dy/dnu at the final state
    (it holds theta'' and l''), ``tension_end`` T^ at the final state.
    """
    S, R, V, tens, k1, work, ybuf = scratch
    n = cmd.shape[0]
    args = (cmd, dist, par, S, R, V, tens)
    t = nu
    for j in range(n):
        tension_min[j] = math.inf
    # n_sub + 1 evaluations with the tension: at the start of each substep (its k1)
    # and at the end (deriv_end); one loop, so the inlined right-hand side appears once
    for i in range(n_sub + 1):
        dy = k1 if i < n_sub else deriv_end
        controlled_rhs_tension(t, y, args, dy)
        for j in range(n):
            tension_min[j] = min(tension_min[j], tens[j])
        if i == n_sub:
            break
        rk4_step(t, y, h, args, k1, work, ybuf)
        for j in range(4 * n):
            y[j] = ybuf[j]
        t = nu + (i + 1) * h
    for j in range(n):
        tension_end[j] = tens[j]
    return t


@njit(**KERNEL)
def advance(nu, y, cmd, dist, par, h, n_sub, tension_min, deriv_end, tension_end):
    """Batched :func:`advance_one`: every row of (nu (B,), y (B, 4n)) in place.

    ``cmd`` and ``dist`` are (B, n); ``par`` is (B, 6+n) or (1, 6+n) (shared);
    outputs are (B, n), (B, 4n), (B, n).
    """
    _advance_rows(nu, y, cmd, dist, par, h, n_sub, tension_min, deriv_end, tension_end,
                  make_scratch(y.shape[1] // 4, 1))


@njit(**LOOP)
def _advance_rows(nu, y, cmd, dist, par, h, n_sub, tension_min, deriv_end, tension_end,
                  scratch):
    lane = scratch_lane(scratch, 0)
    shared = par.shape[0] == 1
    for b in range(y.shape[0]):
        pb = par[0] if shared else par[b]
        nu[b] = advance_one(nu[b], y[b], cmd[b], dist[b], pb, h, n_sub, lane,
                            tension_min[b], deriv_end[b], tension_end[b])


# --------------------------------------------------------------------------- #
# batched evaluations behind TetherChain
# --------------------------------------------------------------------------- #
@njit(**INLINE)
def _pack_row(theta, dtheta, length, dlength, n, row):
    for j in range(n):
        row[j] = theta[j]
        row[n + j] = dtheta[j]
        row[2 * n + j] = length[j]
        row[3 * n + j] = dlength[j]


@njit(**KERNEL)
def accel_batch(nu, theta, dtheta, length, dlength, ddlength, par, ddtheta, tension):
    """theta'' and T^ for a batch of states (arrays of shape (B,) and (B, n))."""
    n = theta.shape[1]
    _accel_rows(nu, theta, dtheta, length, dlength, ddlength, par, ddtheta, tension,
                np.empty((n, n)), np.empty((n, 1)), np.empty((9, n)), np.empty(4 * n))


@njit(**LOOP)
def _accel_rows(nu, theta, dtheta, length, dlength, ddlength, par, ddtheta, tension,
                S, R, V, row):
    n = theta.shape[1]
    shared = par.shape[0] == 1
    for b in range(theta.shape[0]):
        pb = par[0] if shared else par[b]
        _pack_row(theta[b], dtheta[b], length[b], dlength[b], n, row)
        _accel(nu[b], row, ddlength[b], pb, S, R, V, ddtheta[b], tension[b])


@njit(**KERNEL)
def affine_batch(nu, theta, dtheta, length, par, f, Bmat, Dmat):
    """(f, B, D) of theta'' = f + B l' + D l'' for a batch of states."""
    n = theta.shape[1]
    _affine_rows(nu, theta, dtheta, length, par, f, Bmat, Dmat, np.empty((n, n)),
                 np.empty((n, 1 + 2 * n)), np.empty((n, n)), np.empty((n, n)),
                 np.empty((9, n)), np.zeros(4 * n))


@njit(**LOOP)
def _affine_rows(nu, theta, dtheta, length, par, f, Bmat, Dmat, S, R, P, Q, V, row):
    n = theta.shape[1]
    shared = par.shape[0] == 1
    for b in range(theta.shape[0]):
        pb = par[0] if shared else par[b]
        _pack_row(theta[b], dtheta[b], length[b], row[3 * n:], n, row)
        _assemble(nu[b], row, n, pb, S, R[:, 0:1], P, Q, V)
        for j in range(n):
            lj = length[b, j]
            for kk in range(n):
                R[j, 1 + kk] = -lj * P[j, kk]
                R[j, 1 + n + kk] = -lj * Q[j, kk]
        _solve_spd(S, R)
        for j in range(n):
            f[b, j] = R[j, 0]
            for kk in range(n):
                Bmat[b, j, kk] = R[j, 1 + kk]
                Dmat[b, j, kk] = R[j, 1 + n + kk]


@njit(**LOOP)
def reel_batch(nu, dlength, command, par, out):
    """Vectorised :func:`reel_ddlength` over a batch (B,), (B, n)."""
    batch, n = dlength.shape
    shared = par.shape[0] == 1
    for b in range(batch):
        pb = par[0] if shared else par[b]
        for j in range(n):
            out[b, j] = reel_ddlength(nu[b], dlength[b, j], command[b, j], pb[P_ECC],
                                      pb[P_ABOUND], pb[P_VBOUND], pb[P_TAU])
