"""Mathematical tests of the chain's equations of motion (tether_gym.physics.dynamics).

What is checked, against what:

* the paper's zero state (Sec. 3.1, Eq. 7, Table 1), integrated over three orbits;
* the single-tether equation and tension stated in docs/model.md#check-a-single-tether (N = 2);
* an independent Cartesian Newton formulation with constraint forces
  (``newton_reference.py``) for 1, 2, 3 and 5 tethers and both gravity models;
* the control-affine split theta'' = f + B l' + D l'' and its structure;
* exact gravity tending to the gravity-gradient model as L0 / p -> 0;
* conservation of the Jacobi integral on a circular orbit with fixed lengths;
* batched evaluations against looped single evaluations, and the integrator's
  right-hand side against the public model.
"""

from __future__ import annotations

import numpy as np
import pytest
from chain_helpers import advance, random_states, rel_err, rk4_integrate
from newton_reference import newton_accelerations

from tether_gym.physics import TetherChain, make_rk4

LENGTH_RATIO = 20e3 / 8520e3  # L0 / p for L0 = 20 km, p = 8520 km (paper Table 1)
TABLE1_MASSES = (1.0, 2.0)
TABLE1_E = 0.2

MASSES_BY_N = {  # number of tethers -> subsatellite masses (arbitrary units)
    1: (3.0,),
    2: (1.0, 2.0),
    3: (1.0, 2.0, 1.5),
    5: (0.7, 1.3, 2.0, 0.4, 1.1),
}


# --------------------------------------------------------------------------- #
# 1. zero state (paper Sec. 3.1)
# --------------------------------------------------------------------------- #
def _eq7_law(nu, length, e):
    """Eq. 7 as state feedback: l' = l e sin(nu)/k and l'' = d/dnu of it along the motion.

    With s(nu) = e sin(nu) / k, l' = l s and l'' = l' s + l s' = l (s^2 + s'), where
    s' = e (cos(nu) + e) / k^2.
    """
    k = 1.0 + e * np.cos(nu)
    s = e * np.sin(nu) / k
    ds = e * (np.cos(nu) + e) / k**2
    return length * s, length * (s * s + ds)


def test_zero_state_table1_three_orbits():
    """Eq. 7's reel law keeps theta = 0 exactly; l and T^ follow the closed forms.

    Table 1 (masses (1, 2), l(0) = (0.5, 0.5), e = 0.2), theta = theta' = 0 at
    nu = 0, RK4 with h = 0.001 over three orbits. Expected (docs/model.md#zero-state-eq-7):
    l = l(0)(1+e)/(1+e cos nu) peaking at 0.75 at nu = pi; T^_1 = 3/k^2,
    T^_2 = 2.4/k^2.
    """
    e = TABLE1_E
    chain = TetherChain(TABLE1_MASSES, e)
    l0 = np.array([0.5, 0.5])
    h = 1e-3
    n_steps = int(np.ceil(6.0 * np.pi / h))

    def rhs(nu, y, args, dydt, node=False):
        th, dth, ln = y[0:2], y[2:4], y[4:6]
        dl, ddl = _eq7_law(nu, ln, e)
        dydt[0:2] = dth
        dydt[2:4] = chain.theta_ddot(nu, th, dth, ln, dl, ddl)
        dydt[4:6] = dl

    step = make_rk4(rhs, compiled=False)
    y0 = np.concatenate([np.zeros(4), l0])
    traj = rk4_integrate(step, 0.0, y0, h, n_steps, None)
    nu = h * np.arange(n_steps + 1)
    theta, dtheta, length = traj[:, 0:2], traj[:, 2:4], traj[:, 4:6]

    assert nu[-1] >= 6.0 * np.pi
    assert np.max(np.abs(theta)) < 1e-9
    assert np.max(np.abs(dtheta)) < 1e-9

    k = 1.0 + e * np.cos(nu)
    l_exact = l0 * ((1.0 + e) / k)[:, None]
    assert np.max(np.abs(length - l_exact)) < 1e-9

    dl, ddl = _eq7_law(nu[:, None], length, e)
    tension = chain.tension(nu, theta, dtheta, length, dl, ddl)
    t_exact = np.stack([3.0 / k**2, 2.4 / k**2], axis=1)
    assert np.max(np.abs(tension - t_exact)) < 1e-9

    # the peak: no grid value above 0.75, and one extra step landing exactly on pi
    assert np.max(length) <= 0.75 + 1e-9
    i = int(np.pi // h)
    y_pi = traj[i].copy()
    step(nu[i], y_pi, np.pi - nu[i], 1, None, tuple(np.empty(6) for _ in range(5)), np.empty(6))
    np.testing.assert_allclose(y_pi[4:6], [0.75, 0.75], rtol=0.0, atol=1e-9)


# --------------------------------------------------------------------------- #
# 2. N = 2 reduces to docs/model.md's single-tether equations
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("e", [0.0, 0.2, 0.7])
@pytest.mark.parametrize("mass", [1.0, 350.0])
def test_single_tether_matches_notes(e, mass):
    """theta'' and T^ equal docs/model.md's N = 2 formulas on random states (1e-12).

    theta'' = -2 (l'/l - e sin(nu)/k)(1 + theta') - 3 sin(2 theta) / (2k),
    T^ = M [ l (1+theta')^2 + l (3 cos^2 theta - 1)/k + 2 e sin(nu) l'/k - l'' ],
    with M = 1 (one subsatellite carries all the mass).
    """
    rng = np.random.default_rng(12)
    nu, th, dth, ln, dl, ddl = random_states(rng, 1, 500, theta_scale=1.5)
    chain = TetherChain((mass,), e)
    ddtheta, tension = chain.accelerations(nu, th, dth, ln, dl, ddl)

    nu_c = nu[:, None]
    k = 1.0 + e * np.cos(nu_c)
    sn = np.sin(nu_c)
    ddtheta_ref = -2.0 * (dl / ln - e * sn / k) * (1.0 + dth) - 1.5 * np.sin(2.0 * th) / k
    tension_ref = (ln * (1.0 + dth) ** 2 + ln * (3.0 * np.cos(th) ** 2 - 1.0) / k
                   + 2.0 * e * sn * dl / k - ddl)
    assert rel_err(ddtheta, ddtheta_ref) <= 1e-12
    assert rel_err(tension, tension_ref) <= 1e-12


# --------------------------------------------------------------------------- #
# 3. independent Newton formulation; control-affine structure
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("gravity", ["gradient", "full"])
@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_agrees_with_cartesian_newton(n, gravity):
    """theta'' and T^ agree with the Cartesian Newton formulation to 1e-9 (relative).

    100 random states per case (random e in [0, 0.7)), full gravity with
    L0 / p = 20 km / 8520 km. Criterion |a - b| <= 1e-9 (1 + |b|).
    """
    rng = np.random.default_rng(100 + 10 * n + (gravity == "full"))
    masses = MASSES_BY_N[n]
    worst = 0.0
    for _ in range(10):
        e = rng.uniform(0.0, 0.7)
        chain = TetherChain(masses, e, gravity=gravity, length_ratio=LENGTH_RATIO)
        states = random_states(rng, n, 10)
        ddtheta, tension = chain.accelerations(*states)
        for b in range(10):
            ref_dd, ref_t = newton_accelerations(*(s[b] for s in states), masses, e,
                                                 gravity=gravity, length_ratio=LENGTH_RATIO)
            worst = max(worst, rel_err(ddtheta[b], ref_dd), rel_err(tension[b], ref_t))
    assert worst <= 1e-9


@pytest.mark.parametrize("gravity", ["gradient", "full"])
@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_control_affine_reproduces_theta_ddot(n, gravity):
    """f + B l' + D l'' equals theta'' for arbitrary l', l'' (1e-12 relative)."""
    rng = np.random.default_rng(7 + n)
    chain = TetherChain(MASSES_BY_N[n], 0.3, gravity=gravity, length_ratio=LENGTH_RATIO)
    nu, th, dth, ln, dl, ddl = random_states(rng, n, 200)
    f, B, D = chain.control_affine(nu, th, dth, ln)
    assert f.shape == (200, n) and B.shape == D.shape == (200, n, n)
    affine = f + np.einsum("bij,bj->bi", B, dl) + np.einsum("bij,bj->bi", D, ddl)
    assert rel_err(affine, chain.theta_ddot(nu, th, dth, ln, dl, ddl)) <= 1e-12


@pytest.mark.parametrize("gravity", ["gradient", "full"])
@pytest.mark.parametrize("n", [2, 3, 5])
def test_control_affine_structure(n, gravity):
    """Aligned chain: D = 0 and B = diag(-2 (1 + theta_k') / l_k); otherwise both full.

    For theta_1 = ... = theta_n the theta-equations decouple per tether
    (docs/model.md#control-affine-form), which gives the diagonal B above (the N = 2 coefficient
    of l'). For a non-aligned chain D and the off-diagonal part of B are non-zero.
    """
    rng = np.random.default_rng(3 * n)
    chain = TetherChain(MASSES_BY_N[n], 0.2, gravity=gravity, length_ratio=LENGTH_RATIO)
    nu, th, dth, ln, _, _ = random_states(rng, n, 50)
    aligned = np.repeat(th[:, :1], n, axis=1)
    _, B, D = chain.control_affine(nu, aligned, dth, ln)
    assert np.max(np.abs(D)) <= 1e-15
    B_diag = np.zeros_like(B)
    idx = np.arange(n)
    B_diag[:, idx, idx] = -2.0 * (1.0 + dth) / ln
    assert rel_err(B, B_diag) <= 1e-12

    _, B, D = chain.control_affine(nu, th, dth, ln)
    off = ~np.eye(n, dtype=bool)
    assert np.min(np.max(np.abs(D), axis=(1, 2))) > 1e-3
    assert np.min(np.max(np.abs(B[:, off]), axis=1)) > 1e-3


def test_full_gravity_tends_to_gradient():
    """|full - gradient| shrinks linearly with L0 / p (factor 10 per decade, +-30 %)."""
    rng = np.random.default_rng(5)
    masses = MASSES_BY_N[3]
    states = random_states(rng, 3, 100)
    grad = TetherChain(masses, 0.3).accelerations(*states)
    ratios = np.array([1e-2, 1e-3, 1e-4, 1e-5])
    diffs = []
    for eps in ratios:
        full = TetherChain(masses, 0.3, gravity="full", length_ratio=eps).accelerations(*states)
        diffs.append(max(np.max(np.abs(full[i] - grad[i])) for i in range(2)))
    diffs = np.array(diffs)
    assert np.all(diffs > 0.0)
    np.testing.assert_allclose(diffs[:-1] / diffs[1:], 10.0, rtol=0.3)
    assert diffs[-1] < 1e-3  # O(1) accelerations, O(L0/p) = 1e-5 correction


# --------------------------------------------------------------------------- #
# 4. Jacobi integral on a circular orbit
# --------------------------------------------------------------------------- #
def _rel_positions(theta, dtheta, length):
    """rho_i (radial, along-track) and rho_i' for fixed lengths, shape (..., n) each."""
    c, s = np.cos(theta), np.sin(theta)
    rr = -np.cumsum(length * c, axis=-1)
    rv = -np.cumsum(length * s, axis=-1)
    vr = np.cumsum(length * dtheta * s, axis=-1)
    vv = -np.cumsum(length * dtheta * c, axis=-1)
    return rr, rv, vr, vv


def jacobi_integral(y, mass_fractions, length_ratio=None):
    r"""Jacobi integral of the chain on a circular orbit with fixed tether lengths.

    Derivation. For e = 0, nu = n t and the orbital frame rotates at the constant
    rate 1 (per unit nu). In that frame body i sits at rho_i = -sum_{k<=i} l_k e_k,
    e_k = (cos th_k, sin th_k) (components on e_r, e_v), with velocity
    rho_i' = -sum_{k<=i} l_k th_k' (-sin th_k, cos th_k) (the l_k are constant).
    Its inertial velocity relative to the main satellite is rho_i' + e_z x rho_i,
    so the dimensionless Lagrangian (energies / (m_tot n^2 L0^2)) is

        L = 1/2 sum_i M_i |rho_i' + e_z x rho_i|^2 - V(rho),

    with V the potential of the gravity relative to the free-falling main satellite.
    L does not depend on nu explicitly (e = 0, fixed lengths: the constraints are
    scleronomic in the rotating frame and the tensions do no work), hence the
    Jacobi integral H = sum_q q' dL/dq' - L = T2 - T0 + V is conserved, with
    T2 = 1/2 sum M_i |rho_i'|^2 and T0 = 1/2 sum M_i |rho_i|^2 (the term linear in
    rho_i' drops out of H).

    Gravity gradient: V = sum M_i (-3/2 rho_ir^2 + 1/2 |rho_i|^2) (force
    (2 rho_r, -rho_v), the kernel's g_i), so

        H = 1/2 sum_i M_i |rho_i'|^2 - 3/2 sum_i M_i rho_ir^2.

    Exact gravity: with eps = L0 / p, V = -(1/eps^2) sum_i M_i
    [(1/|e_r + eps rho_i| - 1) + eps rho_ir] (its gradient is minus the kernel's
    g_i = -[(e_r + x)|e_r + x|^-3 - e_r] / eps, x = eps rho_i). With
    q = 2 x_r + |x|^2 and s = sqrt(1 + q) = |e_r + x|, the identity
    1/s - 1 + q/2 = q^2 (s + 2) / (2 s (1 + s)^2) evaluates the bracket without
    cancellation: (1/s - 1) + x_r = q^2 (s+2) / (2 s (1+s)^2) - |x|^2 / 2, and the
    |x|^2 / 2 term cancels T0, leaving

        H = 1/2 sum_i M_i |rho_i'|^2 - (1/eps^2) sum_i M_i q_i^2 (s_i+2) / (2 s_i (1+s_i)^2),

    which tends to the gradient form as eps -> 0 (q^2 (s+2)/(2 s (1+s)^2) ~ 3/8 q^2).

    Parameters
    ----------
    y : ndarray, shape (..., 4n)
        States [theta, theta', l, l'] (l' = 0).
    mass_fractions : ndarray, shape (n,)
    length_ratio : float or None
        eps = L0 / p for exact gravity, None for the gradient model.
    """
    n = mass_fractions.shape[0]
    rr, rv, vr, vv = _rel_positions(y[..., :n], y[..., n:2 * n], y[..., 2 * n:3 * n])
    kinetic = 0.5 * np.sum(mass_fractions * (vr**2 + vv**2), axis=-1)
    if length_ratio is None:
        return kinetic - 1.5 * np.sum(mass_fractions * rr**2, axis=-1)
    eps = length_ratio
    xr, xv = eps * rr, eps * rv
    q = 2.0 * xr + xr**2 + xv**2
    s = np.sqrt(1.0 + q)
    bracket = q**2 * (s + 2.0) / (2.0 * s * (1.0 + s) ** 2)
    return kinetic - np.sum(mass_fractions * bracket, axis=-1) / eps**2


JACOBI_CASES = {  # N -> (masses, theta(0), theta'(0), l)
    3: ((1.0, 2.0), (0.3, -0.2), (0.2, -0.1), (0.5, 0.5)),
    4: ((1.0, 2.0, 1.5), (0.3, -0.2, 0.25), (0.2, -0.1, 0.15), (0.5, 0.3, 0.4)),
}


@pytest.mark.parametrize("gravity", ["gradient", "full"])
@pytest.mark.parametrize("n_bodies", [3, 4])
def test_jacobi_integral_conserved(n_bodies, gravity):
    """e = 0, fixed lengths: H drifts < 1e-9 relative over 10 orbits (RK4, h = 0.001).

    Also checks that the test is sensitive: the kinetic part of H changes by more
    than 1 % of |H| along the run, and for exact gravity the gradient-model H is
    *not* conserved to 1e-6 (the two models differ at O(L0/p)).
    """
    masses, th0, dth0, l0 = JACOBI_CASES[n_bodies]
    full = gravity == "full"
    chain = TetherChain(masses, 0.0, gravity=gravity, length_ratio=LENGTH_RATIO if full else None)
    n = chain.n_tethers
    M = chain.mass_fractions
    eps = LENGTH_RATIO if full else None
    y = np.concatenate([th0, dth0, l0, np.zeros(n)])[None, :]
    nu = np.zeros(1)
    cmd = np.zeros((1, n))
    h = 1e-3
    n_chunks, chunk = 40, 1571  # 62840 steps >= 10 orbits
    states = [y[0].copy()]
    for _ in range(n_chunks):
        advance(nu, y, cmd, chain.par, h, chunk)
        states.append(y[0].copy())
    states = np.array(states)
    assert nu[0] >= 20.0 * np.pi
    assert np.all(states[:, 2 * n:] == states[0, 2 * n:])  # lengths and l' = 0 held exactly

    H = jacobi_integral(states, M, eps)
    H0 = H[0]
    assert abs(H0) > 0.1
    assert np.max(np.abs(H - H0)) / abs(H0) < 1e-9

    kinetic = jacobi_integral(states, M, eps) - jacobi_integral(
        states * np.r_[np.ones(n), np.zeros(n), np.ones(2 * n)], M, eps)
    assert np.ptp(kinetic) > 1e-2 * abs(H0)
    if full:
        H_grad = jacobi_integral(states, M, None)
        assert np.max(np.abs(H_grad - H_grad[0])) / abs(H_grad[0]) > 1e-6


def test_jacobi_integral_full_tends_to_gradient():
    """The exact-gravity Jacobi integral approaches the gradient one as O(L0/p)."""
    rng = np.random.default_rng(9)
    M = np.array([0.2, 0.5, 0.3])
    y = np.concatenate([rng.uniform(-1, 1, (20, 3)), rng.uniform(-0.5, 0.5, (20, 3)),
                        rng.uniform(0.1, 1.0, (20, 3)), np.zeros((20, 3))], axis=1)
    grad = jacobi_integral(y, M)
    d3 = np.max(np.abs(jacobi_integral(y, M, 1e-3) - grad))
    d5 = np.max(np.abs(jacobi_integral(y, M, 1e-5) - grad))
    assert 0.0 < d5 < 1e-4
    assert 50.0 < d3 / d5 < 200.0


# --------------------------------------------------------------------------- #
# 6. batching
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("lead", [(4,), (2, 3)])
def test_batched_calls_equal_looped_calls(lead):
    """Every TetherChain method on a batch equals the same method called per state.

    Compared bitwise (the same compiled code runs on each state). Covers a per-state
    nu array and a scalar nu broadcast over the batch.
    """
    n = 3
    rng = np.random.default_rng(21)
    chain = TetherChain(MASSES_BY_N[n], 0.25, gravity="full", length_ratio=LENGTH_RATIO)
    size = int(np.prod(lead))
    nu, th, dth, ln, dl, ddl = random_states(rng, n, size)
    nu = nu.reshape(lead)
    th, dth, ln, dl, ddl = (a.reshape(lead + (n,)) for a in (th, dth, ln, dl, ddl))

    for nu_arg in (nu, 0.7):
        dd, tt = chain.accelerations(nu_arg, th, dth, ln, dl, ddl)
        f, B, D = chain.control_affine(nu_arg, th, dth, ln)
        assert dd.shape == tt.shape == f.shape == lead + (n,)
        assert B.shape == D.shape == lead + (n, n)
        np.testing.assert_array_equal(chain.theta_ddot(nu_arg, th, dth, ln, dl, ddl), dd)
        np.testing.assert_array_equal(chain.tension(nu_arg, th, dth, ln, dl, ddl), tt)
        for idx in np.ndindex(*lead):
            nu_i = nu_arg[idx] if np.ndim(nu_arg) else nu_arg
            args = (th[idx], dth[idx], ln[idx])
            d1, t1 = chain.accelerations(nu_i, *args, dl[idx], ddl[idx])
            np.testing.assert_array_equal(d1, dd[idx])
            np.testing.assert_array_equal(t1, tt[idx])
            np.testing.assert_array_equal(chain.theta_ddot(nu_i, *args, dl[idx], ddl[idx]),
                                          dd[idx])
            f1, B1, D1 = chain.control_affine(nu_i, *args)
            np.testing.assert_array_equal(f1, f[idx])
            np.testing.assert_array_equal(B1, B[idx])
            np.testing.assert_array_equal(D1, D[idx])


def test_advance_batch_equals_single_rows():
    """transition on a batch (per-row and shared parameters) equals row-by-row runs."""
    n = 2
    rng = np.random.default_rng(4)
    batch = 5
    chain = TetherChain(TABLE1_MASSES, 0.2)
    nu0 = rng.uniform(0.0, 2.0 * np.pi, batch)
    y0 = np.concatenate([rng.uniform(-0.3, 0.3, (batch, 2 * n)),
                         rng.uniform(0.3, 0.7, (batch, n)), rng.uniform(-0.1, 0.1, (batch, n))],
                        axis=1)
    cmd = rng.uniform(-0.2, 0.2, (batch, n))
    par_rows = np.stack([chain.param_row(time_constant=tau)
                         for tau in rng.uniform(0.01, 0.1, batch)])

    for par in (chain.par, par_rows):
        nu_b, y_b = nu0.copy(), y0.copy()
        out_b = advance(nu_b, y_b, cmd, par, 2e-3, 50)
        for b in range(batch):
            nu_1, y_1 = nu0[b:b + 1].copy(), y0[b:b + 1].copy()
            out_1 = advance(nu_1, y_1, cmd[b:b + 1], par[b:b + 1] if par.shape[0] > 1 else par,
                            2e-3, 50)
            np.testing.assert_array_equal(nu_1, nu_b[b:b + 1])
            np.testing.assert_array_equal(y_1, y_b[b:b + 1])
            for o1, ob in zip(out_1, out_b, strict=True):
                np.testing.assert_array_equal(o1, ob[b:b + 1])


def test_integrator_rhs_is_the_chain():
    """advance's derivative and tension equal TetherChain's at the same state.

    With no reel limit l'' = (l'_cmd - l') / tau, and the disturbance adds to theta''.
    """
    n = 3
    rng = np.random.default_rng(8)
    chain = TetherChain(MASSES_BY_N[n], 0.4, gravity="full", length_ratio=LENGTH_RATIO)
    tau = 0.3
    par = chain.param_row(time_constant=tau)[None]
    nu, th, dth, ln, dl, _ = random_states(rng, n, 6)
    y = np.concatenate([th, dth, ln, dl], axis=1)
    cmd = rng.uniform(-0.5, 0.5, (6, n))
    dist = rng.uniform(-0.1, 0.1, (6, n))
    _, deriv, tension = advance(nu.copy(), y.copy(), cmd, par, 1e-3, 0, dist=dist)
    ddl = (cmd - dl) / tau
    ddtheta, tension_ref = chain.accelerations(nu, th, dth, ln, dl, ddl)
    np.testing.assert_array_equal(deriv[:, :n], dth)
    np.testing.assert_array_equal(deriv[:, 2 * n:3 * n], dl)
    assert rel_err(deriv[:, 3 * n:], ddl) <= 1e-15
    assert rel_err(deriv[:, n:2 * n], ddtheta + dist) <= 1e-14
    assert rel_err(tension, tension_ref) <= 1e-14
