"""An independent formulation of the chain: Newton's law in inertial Cartesian axes.

Shares nothing with tether_gym.physics.kernels. Units: n = sqrt(mu/p^3) = 1 and
p = 1 (so mu = 1); time t. The main satellite follows its Kepler orbit; each point
mass obeys m_i a_i = m_i g(R_i) + T_i u_i - T_{i+1} u_{i+1} with u_i the unit vector
from body i to body i-1; the tensions are the constraint forces that make
|R_i - R_{i-1}| = L_i(t) hold to second order. The unknown accelerations and
tensions solve one linear system; theta'' and T^ follow by kinematics.
"""

from __future__ import annotations

import numpy as np


def newton_accelerations(nu, theta, dtheta, length, dlength, ddlength, masses, e,
                         gravity="gradient", length_ratio=1e-3):
    """theta'' and T^ of one state, from Cartesian Newton-Euler with constraint forces."""
    theta, dtheta, length, dlength, ddlength = (np.asarray(a, dtype=float) for a in
                                                (theta, dtheta, length, dlength, ddlength))
    m = np.asarray(masses, dtype=float)
    n = m.size
    L0 = length_ratio if gravity == "full" else 1.0  # gradient model is scale-free
    k = 1.0 + e * np.cos(nu)
    r = 1.0 / k
    nud = k**2
    nudd = -2.0 * e * np.sin(nu) * k**3
    er = np.array([np.cos(nu), np.sin(nu)])
    R0 = r * er

    phi = nu + theta
    L = L0 * length
    Ld = L0 * nud * dlength
    Ldd = L0 * (nud**2 * ddlength + nudd * dlength)
    phid = nud * (1.0 + dtheta)
    ephi = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    eperp = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
    w = -L[:, None] * ephi  # R_i - R_{i-1}
    wd = -Ld[:, None] * ephi - (L * phid)[:, None] * eperp
    R = R0 + np.cumsum(w, axis=0)

    def grav(Ri):
        if gravity == "full":
            return -Ri / np.linalg.norm(Ri) ** 3
        g0 = -R0 / r**3
        rho = Ri - R0
        return g0 + (3.0 * (er @ rho) * er - rho) / r**3

    a0 = -R0 / r**3
    # unknowns: a_1..a_n (2n), T_1..T_n (n)
    size = 3 * n
    Amat = np.zeros((size, size))
    rhs = np.zeros(size)
    u = ephi  # unit vector from body i toward body i-1
    for i in range(n):
        # m_i a_i - T_i u_i + T_{i+1} u_{i+1} = m_i g(R_i)
        for c in range(2):
            row = 2 * i + c
            Amat[row, 2 * i + c] = m[i]
            Amat[row, 2 * n + i] = -u[i, c]
            if i + 1 < n:
                Amat[row, 2 * n + i + 1] = u[i + 1, c]
            rhs[row] = m[i] * grav(R[i])[c]
        # w_i . (a_i - a_{i-1}) = Ld^2 + L Ldd - |wd|^2
        row = 2 * n + i
        Amat[row, 2 * i:2 * i + 2] = w[i]
        prev = a0 if i == 0 else None
        if i > 0:
            Amat[row, 2 * (i - 1):2 * i] = -w[i]
        rhs[row] = Ld[i] ** 2 + L[i] * Ldd[i] - wd[i] @ wd[i]
        if prev is not None:
            rhs[row] += w[i] @ a0
    sol = np.linalg.solve(Amat, rhs)
    acc = sol[:2 * n].reshape(n, 2)
    T = sol[2 * n:]
    prev_acc = np.vstack([a0, acc[:-1]])
    wdd = acc - prev_acc
    # wdd . (-eperp) = 2 Ld phid + L phidd
    phidd = (-(wdd * eperp).sum(axis=1) - 2.0 * Ld * phid) / L
    thdd = phidd - nudd
    ddtheta = (thdd - nudd * dtheta) / nud**2
    tension = T / (nud**2 * L0 * m.sum())
    return ddtheta, tension
