"""CasADi symbolic form of the project's physics: the prediction model of ``mpc``.

The functions below rebuild, operation for operation, the compiled step of
:func:`tether_gym.physics.transition` (:mod:`tether_gym.physics.kernels`) as CasADi
``SX`` expressions, so that the model-predictive controller
(:mod:`tether_gym_agents.baselines.mpc`) gets exact derivatives of the very step the
env takes. ``tests/agents/baselines/test_mpc_model.py`` checks that they agree with
``transition`` to 1e-10 on random states (several N, eccentricities, masses, both
gravity models, with the reel model and the env's substeps): this is not a second
copy of the equations but a transcription that a test keeps equal to the one copy.

Equations (Shi, Zhu & Zhu 2019, Sec. 2; derivation in :mod:`tether_gym.physics.kernels`
and docs/model.md#equations-of-motion), n = N - 1 tethers, primes d/dnu:

* gravity of the bodies below tether j, projected (:func:`_links`): gradient model
  g_i = (2 rho_ir, -rho_iv) / k, full model g_i = -[(e_r + x_i)|e_r + x_i|^-3 - e_r] /
  (k^2 eps) with x_i = k eps rho_i, rho_i = -sum_{m<=i} l_m e_m (Eq. 1);
* theta-equations (Eq. 6a, the e_j^perp components of Newton's law for the bodies
  j..n): A th'' + b0 + P l' + Q l'' = 0, A_jk = Mt_jk l_k c_jk, P_jk = Mt_jk (2 w_k
  c_jk - q s_jk), Q_jk = Mt_jk s_jk (:func:`_theta_ddot`), solved with diag(l) A
  symmetric positive definite, by the same elimination without pivoting;
* tensions (Eq. 6b, the e_j components): T^_j = sum_k Mt_jk [-(lam_k - l_k w_k^2)
  c_jk + (l_k th_k'' + sig_k) s_jk] - G^par_j (:func:`_tension`);
* reel of each tether (:func:`_reel`, :func:`tether_gym.physics.kernels._reel`):
  first-order lag l''_des = (l'_cmd - l') / tau, the physical acceleration
  L_ddot / (L0 n^2) = k^4 l'' - 2 e sin(nu) k^3 l' saturated at +-a_bound, the command
  clipped to the speed bound k^2 |l'| <= v_bound;
* disturbance d added to theta'' (Eq. 20), after the tension is evaluated;
* classic RK4 (:func:`tether_gym.physics.integrators.make_rk4`), ``substeps`` steps of
  h per control step, the tension recorded at the substep boundaries (both ends).

CasADi is an optional dependency (the ``mpc`` extra): :func:`casadi` imports it on first
use and names the pip command when it is missing.
"""

from __future__ import annotations

import importlib
from typing import Any

from tether_gym.physics import PARAMS, STATE

__all__ = ["casadi", "INSTALL_HINT", "step_function", "rhs_function", "param_index"]

INSTALL_HINT = 'pip install -e ".[mpc]" (in a clone of tether_gym)'
"""The pip command that installs CasADi for the model-predictive controller."""

_CACHE: dict[tuple, Any] = {}


def casadi():
    """The ``casadi`` module, imported on first use.

    Raises
    ------
    ModuleNotFoundError
        When CasADi is not installed; the message gives the exact pip command.
    """
    try:
        return importlib.import_module("casadi")
    except ModuleNotFoundError as exc:
        raise ModuleNotFoundError(
            f"the model-predictive controller 'mpc' needs CasADi 3.8, which is not "
            f"installed: {INSTALL_HINT}  (or: pip install \"casadi>=3.8,<3.9\")",
            name="casadi") from exc


def param_index(n: int) -> dict[str, int]:
    """Offsets of the parameter row's fields (:data:`tether_gym.physics.PARAMS`) for n.

    A per-tether field (``tail_mass``) gives the offset of its first entry.
    """
    return {name: sl.start for name, sl in PARAMS.slices(n).items()}


def _fields(y, n: int):
    sl = STATE.slices(n)
    return tuple([y[i] for i in range(sl[name].start, sl[name].stop)] for name in STATE.names)


def _links(ca, nu, theta, length, par, n: int, full: bool):
    """(q, sin nu, k, cos th, sin th, G^perp, G^par) (kernels._links, Eq. 1 and 6)."""
    idx = param_index(n)
    ecc = par[idx["eccentricity"]]
    tail = [par[idx["tail_mass"] + i] for i in range(n)]
    sn = ca.sin(nu)
    cn = ca.cos(nu)
    k = 1.0 + ecc * cn
    q = 2.0 * ecc * sn / k
    cth = [ca.cos(t) for t in theta]
    sth = [ca.sin(t) for t in theta]
    eps = par[idx["length_ratio"]]
    rr = 0.0
    rv = 0.0
    g5, g6 = [], []
    for i in range(n):
        rr = rr - length[i] * cth[i]
        rv = rv - length[i] * sth[i]
        if full:
            xr = k * eps * rr
            xv = k * eps * rv
            qq = 2.0 * xr + xr * xr + xv * xv
            fm = ca.expm1(-1.5 * ca.log1p(qq))  # |e_r + x|^-3 - 1
            scale = -1.0 / (k * k * eps)
            g5.append(scale * (fm + xr * (1.0 + fm)))
            g6.append(scale * (xv * (1.0 + fm)))
        else:
            g5.append(2.0 * rr / k)
            g6.append(-rv / k)
    gperp = [None] * n
    gpar = [None] * n
    gr = 0.0
    gv = 0.0
    for j in range(n - 1, -1, -1):
        mass = tail[j] - (tail[j + 1] if j + 1 < n else 0.0)
        gr = gr + mass * g5[j]
        gv = gv + mass * g6[j]
        gperp[j] = -gr * sth[j] + gv * cth[j]
        gpar[j] = gr * cth[j] + gv * sth[j]
    return q, sn, k, cth, sth, gperp, gpar, tail


def _pair(j, kk, cth, sth):
    """(c_jk, s_jk) = (cos(th_k - th_j), sin(th_k - th_j))."""
    return (cth[kk] * cth[j] + sth[kk] * sth[j], sth[kk] * cth[j] - cth[kk] * sth[j])


def _solve_spd(S, R, n: int):
    """S^-1 R by elimination without pivoting (kernels._solve_spd); lists of lists."""
    S = [row[:] for row in S]
    R = R[:]
    for p in range(n):
        inv = 1.0 / S[p][p]
        for i in range(p + 1, n):
            fac = S[i][p] * inv
            for j in range(p + 1, n):
                S[i][j] = S[i][j] - fac * S[p][j]
            R[i] = R[i] - fac * R[p]
    for p in range(n - 1, -1, -1):
        acc = R[p]
        for j in range(p + 1, n):
            acc = acc - S[p][j] * R[j]
        R[p] = acc / S[p][p]
    return R


def _theta_ddot(links, length, dtheta, dlength, ddlength, n: int):
    """theta'' [rad/rad^2] of the theta-equations (Eq. 6a; kernels._theta_ddot)."""
    q, _, _, cth, sth, gperp, _, tail = links
    S = [[None] * n for _ in range(n)]
    R = [None] * n
    for j in range(n):
        b = gperp[j]
        for kk in range(n):
            mt = tail[max(j, kk)]
            c, s = _pair(j, kk, cth, sth)
            wk = 1.0 + dtheta[kk]
            S[j][kk] = mt * length[j] * length[kk] * c
            b_jk = -mt * length[kk] * wk * (wk * s + q * c)
            b = b + (b_jk + mt * (2.0 * wk * c - q * s) * dlength[kk]) + mt * s * ddlength[kk]
        R[j] = -length[j] * b
    return _solve_spd(S, R, n)


def _tension(links, length, dtheta, dlength, ddlength, ddtheta, n: int):
    """T^ [-] (Eq. 6b; kernels._tension)."""
    q, _, _, cth, sth, _, gpar, tail = links
    out = []
    for j in range(n):
        acc = -gpar[j]
        for kk in range(n):
            mt = tail[max(j, kk)]
            c, s = _pair(j, kk, cth, sth)
            lk = length[kk]
            dlk = dlength[kk]
            wk = 1.0 + dtheta[kk]
            lam = ddlength[kk] - q * dlk
            sig = wk * (2.0 * dlk - q * lk)
            acc = acc + mt * (-(lam - lk * wk * wk) * c + (lk * ddtheta[kk] + sig) * s)
        out.append(acc)
    return out


def _reel(ca, k, sn, dlength, command, par, n: int):
    """Actual l'' [-] of one reel (kernels._reel): lag, speed clip, accel saturation."""
    idx = param_index(n)
    a_bound = par[idx["accel_bound"]]
    v_bound = par[idx["speed_bound"]]
    tau = par[idx["time_constant"]]
    ecc = par[idx["eccentricity"]]
    k2 = k * k
    k4 = k2 * k2
    cap = v_bound / k2  # inf without a speed limit: the clip is then the identity
    cmd = ca.fmin(ca.fmax(command, -cap), cap)
    cor = 2.0 * ecc * sn * (k * k) * k * dlength
    a = k4 * (cmd - dlength) / tau - cor
    a = ca.fmin(ca.fmax(a, -a_bound), a_bound)
    return (a + cor) / k4


def _rhs(ca, nu, y, command, disturbance, par, n: int, full: bool):
    """(dy/dnu, T^) of the chain with its reels (kernels.controlled_rhs)."""
    theta, dtheta, length, dlength = _fields(y, n)
    links = _links(ca, nu, theta, length, par, n, full)
    _, sn, k = links[:3]
    ddl = [_reel(ca, k, sn, dlength[j], command[j], par, n) for j in range(n)]
    ddth = _theta_ddot(links, length, dtheta, dlength, ddl, n)
    tension = _tension(links, length, dtheta, dlength, ddl, ddth, n)
    ddth_d = [ddth[j] + disturbance[j] for j in range(n)]
    return ca.vertcat(*dtheta, *ddth_d, *dlength, *ddl), ca.vertcat(*tension)


def _symbols(ca, n: int):
    """CasADi symbols (nu, y (4n), command (n), disturbance (n), par (PARAMS row))."""
    return (ca.SX.sym("nu"), ca.SX.sym("y", 4 * n), ca.SX.sym("command", n),
            ca.SX.sym("disturbance", n), ca.SX.sym("par", PARAMS.size(n)))


def rhs_function(n: int, full: bool = False):
    """CasADi Function ``rhs(nu, y, command, disturbance, par) -> (dy, tension)``.

    Parameters
    ----------
    n : int
        Number of tethers N - 1.
    full : bool
        Exact inverse-square gravity (True) or the gradient model (False): the
        parameter row's gravity code must agree.
    """
    key = ("rhs", n, full)
    if key not in _CACHE:
        ca = casadi()
        nu, y, cmd, dist, par = _symbols(ca, n)
        dy, tension = _rhs(ca, nu, y, cmd, dist, par, n, full)
        _CACHE[key] = ca.Function("rhs", [nu, y, cmd, dist, par], [dy, tension],
                                  ["nu", "y", "command", "disturbance", "par"],
                                  ["dy", "tension"])
    return _CACHE[key]


def rk4_step(ca, nu, y, command, disturbance, par, h, substeps: int, n: int, full: bool):
    """Symbolic control step (:func:`tether_gym.physics.transition`).

    Returns
    -------
    nu_end, y_end, tensions, derivative
        True anomaly [rad] and state at the end, the tensions T^ [-] at the
        ``substeps + 1`` substep boundaries (columns, both ends included; their minimum
        is ``Transition.tension_min``) and dy/dnu at the end.
    """
    t = nu
    tensions = []
    for i in range(substeps):
        k1, tension = _rhs(ca, t, y, command, disturbance, par, n, full)
        tensions.append(tension)
        half = 0.5 * h
        k2, _ = _rhs(ca, t + half, y + half * k1, command, disturbance, par, n, full)
        k3, _ = _rhs(ca, t + half, y + half * k2, command, disturbance, par, n, full)
        k4, _ = _rhs(ca, t + h, y + h * k3, command, disturbance, par, n, full)
        y = y + (h / 6.0) * (k1 + 2.0 * (k2 + k3) + k4)
        t = nu + (i + 1) * h
    deriv, tension = _rhs(ca, t, y, command, disturbance, par, n, full)
    tensions.append(tension)
    return t, y, ca.horzcat(*tensions), deriv


def step_function(n: int, substeps: int, full: bool = False):
    """CasADi Function of one control step, the symbolic :func:`~tether_gym.physics.transition`.

    ``step(nu, y, command, disturbance, par, h) -> (nu_end, y_end, tensions,
    derivative)``: nu [rad], y the state row (STATE layout), command l'_cmd [-] (n,),
    disturbance d [rad/rad^2] (n,), par the parameter row (PARAMS layout), h the RK4 step
    [rad]; tensions (n, substeps + 1) [-] at the substep boundaries. Cached per
    (n, substeps, full).
    """
    key = ("step", n, substeps, full)
    if key not in _CACHE:
        ca = casadi()
        nu, y, cmd, dist, par = _symbols(ca, n)
        h = ca.SX.sym("h")
        out = rk4_step(ca, nu, y, cmd, dist, par, h, substeps, n, full)
        _CACHE[key] = ca.Function("step", [nu, y, cmd, dist, par, h], list(out),
                                  ["nu", "y", "command", "disturbance", "par", "h"],
                                  ["nu_end", "y_end", "tensions", "derivative"])
    return _CACHE[key]
