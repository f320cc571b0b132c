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

P_ECC, P_GRAV, P_EPS, P_ABOUND, P_VBOUND, P_TAU, P_TAIL = range(7)
GRAVITY_GRADIENT = 0
GRAVITY_FULL = 1


def pack_params(eccentricity, tail_masses, gravity=GRAVITY_GRADIENT, length_ratio=0.0,
                accel_bound=math.inf, speed_bound=math.inf, time_constant=1.0):
    """Pack one parameter row (see the module docstring) as a float64 array."""
    tail = np.asarray(tail_masses, dtype=float)
    head = [eccentricity, float(gravity), length_ratio, accel_bound, speed_bound, time_constant]
    return np.concatenate([np.asarray(head, dtype=float), tail])


# --------------------------------------------------------------------------- #
# equations of motion
# --------------------------------------------------------------------------- #
@njit(cache=True)
def _assemble(nu, theta, dtheta, length, par, S, rhs, P, Q, V):
    """Fill the affine theta-equations (rows scaled by l_j) and link quantities.

    S <- diag(l) A (symmetric), rhs[:, 0] <- -diag(l) b0, P <- P, Q <- Q (unscaled).
    V rows: 0 cos th, 1 sin th, 2 w = 1 + th', 3 G^perp, 4 G^par, 5..8 scratch.
    """
    n = theta.shape[0]
    ecc = par[P_ECC]
    sn = math.sin(nu)
    k = 1.0 + ecc * math.cos(nu)
    q = 2.0 * ecc * sn / k
    ct = V[0]
    st = V[1]
    w = V[2]
    gperp = V[3]
    gpar = V[4]
    gr = V[5]
    gv = V[6]
    for i in range(n):
        ct[i] = math.cos(theta[i])
        st[i] = math.sin(theta[i])
        w[i] = 1.0 + dtheta[i]
    # body positions rho_i and their gravity g_i (relative to the main satellite)
    rr = 0.0
    rv = 0.0
    full = par[P_GRAV] == GRAVITY_FULL
    eps = par[P_EPS]
    for i in range(n):
        rr -= length[i] * ct[i]
        rv -= length[i] * st[i]
        if full:
            xr = k * eps * rr
            xv = k * eps * rv
            qq = 2.0 * xr + xr * xr + xv * xv
            fm = math.expm1(-1.5 * math.log1p(qq))  # |e_r + x|^-3 - 1
            scale = -1.0 / (k * k * eps)
            gr[i] = scale * (fm + xr * (1.0 + fm))
            gv[i] = scale * (xv * (1.0 + fm))
        else:
            gr[i] = 2.0 * rr / k
            gv[i] = -rv / k
    # tail sums G_j = sum_{i>=j} M_i g_i, projected on e_j^perp and e_j
    Gr = 0.0
    Gv = 0.0
    tail = par[P_TAIL:]
    for j in range(n - 1, -1, -1):
        mass = tail[j] - (tail[j + 1] if j + 1 < n else 0.0)
        Gr += mass * gr[j]
        Gv += mass * gv[j]
        gperp[j] = -Gr * st[j] + Gv * ct[j]
        gpar[j] = Gr * ct[j] + Gv * st[j]
    for j in range(n):
        b0 = gperp[j]
        for kk in range(n):
            mt = tail[max(j, kk)]
            c = ct[kk] * ct[j] + st[kk] * st[j]
            s = st[kk] * ct[j] - ct[kk] * st[j]
            S[j, kk] = mt * length[j] * length[kk] * c
            P[j, kk] = mt * (2.0 * w[kk] * c - q * s)
            Q[j, kk] = mt * s
            b0 -= mt * length[kk] * w[kk] * (w[kk] * s + q * c)
        rhs[j, 0] = -length[j] * b0


@njit(cache=True)
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


@njit(cache=True)
def _accel(nu, theta, dtheta, length, dlength, ddlength, par, S, R, P, Q, V, ddtheta, tension):
    """theta'' and T^ for one state; R is (n, 1) scratch."""
    n = theta.shape[0]
    _assemble(nu, theta, dtheta, length, par, S, R, P, Q, V)
    for j in range(n):
        acc = 0.0
        for kk in range(n):
            acc += P[j, kk] * dlength[kk] + Q[j, kk] * ddlength[kk]
        R[j, 0] -= length[j] * acc
    _solve_spd(S, R)
    ecc = par[P_ECC]
    q = 2.0 * ecc * math.sin(nu) / (1.0 + ecc * math.cos(nu))
    ct = V[0]
    st = V[1]
    w = V[2]
    tail = par[P_TAIL:]
    for j in range(n):
        ddtheta[j] = R[j, 0]
    for j in range(n):
        acc = -V[4, j]
        for kk in range(n):
            mt = tail[max(j, kk)]
            c = ct[kk] * ct[j] + st[kk] * st[j]
            s = st[kk] * ct[j] - ct[kk] * st[j]
            lam = ddlength[kk] - q * dlength[kk]
            sig = w[kk] * (2.0 * dlength[kk] - q * length[kk])
            acc += mt * (-(lam - length[kk] * w[kk] * w[kk]) * c
                         + (length[kk] * ddtheta[kk] + sig) * s)
        tension[j] = acc


# --------------------------------------------------------------------------- #
# reel actuator
# --------------------------------------------------------------------------- #
@njit(cache=True)
def reel_ddlength(nu, dlength, command, ecc, a_bound, v_bound, tau):
    """Actual l'' [-] of one reel given its rate l' and the commanded rate l'_cmd.

    The reel follows the command as a first-order lag in l' with time constant tau
    [rad], l''_des = (l'_cmd - l') / tau, and its physical acceleration
    L_ddot / (L0 n^2) = k^4 l'' - 2 e sin(nu) k^3 l' is saturated at +-a_bound; the
    command is first clipped to the speed bound |L_dot| / (L0 n) = k^2 |l'| <= v_bound.
    """
    k = 1.0 + ecc * math.cos(nu)
    k2 = k * k
    k4 = k2 * k2
    cmd = command
    if v_bound < math.inf:
        cap = v_bound / k2
        cmd = min(max(cmd, -cap), cap)
    coriolis = 2.0 * ecc * math.sin(nu) * k2 * k * dlength
    a = k4 * (cmd - dlength) / tau - coriolis
    a = min(max(a, -a_bound), a_bound)
    return (a + coriolis) / k4


@njit(cache=True)
def controlled_rhs(nu, y, args, dy):
    """dy/dnu of the chain with its reels.

    ``args = (cmd, dist, par, S, R, P, Q, V, tension)``: commanded reel rates l'_cmd,
    a disturbance d added to theta'' (paper Eq. 20, f_d = f + d), the parameter row
    and scratch. Writes the tension T^ at (nu, y) into ``args[8]`` as a by-product.
    """
    cmd, dist, par, S, R, P, Q, V, tension = args
    n = cmd.shape[0]
    ecc = par[P_ECC]
    for j in range(n):
        dl = y[3 * n + j]
        dy[2 * n + j] = dl
        dy[3 * n + j] = reel_ddlength(nu, dl, cmd[j], ecc, par[P_ABOUND], par[P_VBOUND], par[P_TAU])
        dy[j] = y[n + j]
    _accel(nu, y[0:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:4 * n], dy[3 * n:4 * n], par,
           S, R, P, Q, V, dy[n:2 * n], tension)
    for j in range(n):
        dy[n + j] += dist[j]


rk4_step = make_rk4(controlled_rhs)


@njit(cache=True)
def make_scratch(n):
    """Work arrays for :func:`advance_one` with n tethers."""
    m = 4 * n
    return (np.empty((n, n)), np.empty((n, 1)), np.empty((n, n)), np.empty((n, n)),
            np.empty((9, n)), np.empty(n), np.empty(m), np.empty((4, m)), np.empty(m))


@njit(cache=True)
def advance_one(nu, y, cmd, dist, par, h, n_sub, scratch, tension_min, deriv_end, tension_end):
    """Advance one state (nu, y) by ``n_sub`` RK4 steps of size ``h`` [rad]; y in place.

    Returns the final true anomaly. ``tension_min`` receives the minimum T^ over the
    substep boundaries (both ends included), ``deriv_end`` dy/dnu at the final state
    (it holds theta'' and l''), ``tension_end`` T^ at the final state.
    """
    S, R, P, Q, V, tens, k1, work, ybuf = scratch
    n = cmd.shape[0]
    args = (cmd, dist, par, S, R, P, Q, V, tens)
    t = nu
    for j in range(n):
        tension_min[j] = math.inf
    for i in range(n_sub):
        controlled_rhs(t, y, args, k1)
        for j in range(n):
            tension_min[j] = min(tension_min[j], tens[j])
        rk4_step(t, y, h, args, k1, work, ybuf)
        y[:] = ybuf
        t = nu + (i + 1) * h
    controlled_rhs(t, y, args, deriv_end)
    for j in range(n):
        tension_end[j] = tens[j]
        tension_min[j] = min(tension_min[j], tens[j])
    return t


@njit(cache=True)
def advance(nu, y, cmd, dist, par, h, n_sub, tension_min, deriv_end, tension_end):
    """Batched :func:`advance_one`: every row of (nu (B,), y (B, 4n)) in place.

    ``cmd`` and ``dist`` are (B, n); ``par`` is (B, 6+n) or (1, 6+n) (shared);
    outputs are (B, n), (B, 4n), (B, n).
    """
    batch, m = y.shape
    scratch = make_scratch(m // 4)
    shared = par.shape[0] == 1
    for b in range(batch):
        pb = par[0] if shared else par[b]
        nu[b] = advance_one(nu[b], y[b], cmd[b], dist[b], pb, h, n_sub, scratch,
                            tension_min[b], deriv_end[b], tension_end[b])


# --------------------------------------------------------------------------- #
# batched evaluations behind TetherChain
# --------------------------------------------------------------------------- #
@njit(cache=True)
def accel_batch(nu, theta, dtheta, length, dlength, ddlength, par, ddtheta, tension):
    """theta'' and T^ for a batch of states (arrays of shape (B,) and (B, n))."""
    batch, n = theta.shape
    S = np.empty((n, n))
    R = np.empty((n, 1))
    P = np.empty((n, n))
    Q = np.empty((n, n))
    V = np.empty((9, n))
    shared = par.shape[0] == 1
    for b in range(batch):
        pb = par[0] if shared else par[b]
        _accel(nu[b], theta[b], dtheta[b], length[b], dlength[b], ddlength[b], pb,
               S, R, P, Q, V, ddtheta[b], tension[b])


@njit(cache=True)
def affine_batch(nu, theta, dtheta, length, par, f, Bmat, Dmat):
    """(f, B, D) of theta'' = f + B l' + D l'' for a batch of states."""
    batch, n = theta.shape
    S = np.empty((n, n))
    R = np.empty((n, 1 + 2 * n))
    P = np.empty((n, n))
    Q = np.empty((n, n))
    V = np.empty((9, n))
    shared = par.shape[0] == 1
    for b in range(batch):
        pb = par[0] if shared else par[b]
        _assemble(nu[b], theta[b], dtheta[b], length[b], pb, S, R[:, 0:1], P, Q, V)
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


@njit(cache=True)
def reel_batch(nu, dlength, command, par, out):
    """Vectorised :func:`reel_ddlength` over a batch (B,), (B, n)."""
    batch, n = dlength.shape
    shared = par.shape[0] == 1
    for b in range(batch):
        pb = par[0] if shared else par[b]
        for j in range(n):
            out[b, j] = reel_ddlength(nu[b], dlength[b, j], command[b, j], pb[P_ECC],
                                      pb[P_ABOUND], pb[P_VBOUND], pb[P_TAU])
