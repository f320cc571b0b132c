"""Tests of the reference librations and open-loop reel laws (tether_gym.tasks.reference).

The laws are checked by what they claim to do to the physics: Eq. 10, applied as
state feedback on a Table 1 chain, makes theta follow A sin(nu); Eq. 11a is the
small-amplitude integral of Eq. 10 (checked by quadrature); the tension polynomial
of Sec. 3.2 is the last tether's tension at apogee on the periodic solution (checked
through TetherChain.tension). The helpers' elementary relations (derivatives,
special cases) are checked too.
"""

from __future__ import annotations

import numpy as np
import pytest
from chain_helpers import rk4_integrate
from scipy.integrate import quad

from tether_gym.physics import TetherChain, make_rk4
from tether_gym.tasks.reference import (
    desired_libration,
    periodic_length_small_amplitude,
    periodic_reel_rate,
    tension_positivity_polynomial,
    zero_state_length,
    zero_state_reel_rate,
)

TABLE1_MASSES = (1.0, 2.0)


def _d1(fun, x, dx):
    return (fun(x - 2 * dx) - 8 * fun(x - dx) + 8 * fun(x + dx) - fun(x + 2 * dx)) / (12 * dx)


def _eq10_ratio_and_derivative(nu, theta, dtheta, e, amplitude, frequency=1.0):
    """g = l'/l of Eq. 10 and its nu-derivative along the motion, g' = g0 + g_th theta''.

    Eq. 10: g = N / Dn with N = 4 e sin(nu)(1+theta') + 2 A k w^2 sin(w nu)
    - 3 sin(2 theta) and Dn = 4 k (1 + theta'). Along a motion
    N' = N0 + 4 e sin(nu) theta'', Dn' = Dn0 + 4 k theta'' with
    N0 = 4 e cos(nu)(1+theta') - 2 A e sin(nu) w^2 sin(w nu) + 2 A k w^3 cos(w nu)
         - 6 cos(2 theta) theta',
    Dn0 = -4 e sin(nu)(1+theta'),
    and g' = (N' - g Dn') / Dn.

    Returns
    -------
    g, g0, g_th : ndarray
        with g' = g0 + g_th theta''.
    """
    sn, cn = np.sin(nu), np.cos(nu)
    k = 1.0 + e * cn
    w = frequency
    A = amplitude
    num = 4 * e * sn * (1 + dtheta) + 2 * A * k * w**2 * np.sin(w * nu) - 3 * np.sin(2 * theta)
    den = 4 * k * (1 + dtheta)
    g = num / den
    num0 = (4 * e * cn * (1 + dtheta) - 2 * A * e * sn * w**2 * np.sin(w * nu)
            + 2 * A * k * w**3 * np.cos(w * nu) - 6 * np.cos(2 * theta) * dtheta)
    den0 = -4 * e * sn * (1 + dtheta)
    g0 = (num0 - g * den0) / den
    g_th = (4 * e * sn - g * 4 * k) / den
    return g, g0, g_th


# --------------------------------------------------------------------------- #
# elementary relations
# --------------------------------------------------------------------------- #
def test_reference_derivatives():
    """theta_d' and theta_d'' of desired_libration() are the nu-derivatives of theta_d (1e-9)."""
    nu = np.linspace(-3.0, 9.0, 101)
    for amplitude, frequency in ((0.2, 1.0), (0.35, 1.7)):
        th, dth, ddth = desired_libration(nu, amplitude, frequency)
        np.testing.assert_allclose(th, amplitude * np.sin(frequency * nu), rtol=1e-15, atol=0)
        fd1 = _d1(lambda v, a=amplitude, w=frequency: desired_libration(v, a, w)[0], nu, 1e-3)
        fd2 = _d1(lambda v, a=amplitude, w=frequency: desired_libration(v, a, w)[1], nu, 1e-3)
        np.testing.assert_allclose(dth, fd1, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ddth, fd2, rtol=0, atol=1e-9)


@pytest.mark.parametrize("e", [0.0, 0.2, 0.7])
def test_zero_state_helpers(e):
    """zero_state_length integrates zero_state_reel_rate (Eq. 7) and starts at l(nu0).

    Also: Eq. 10 with A = 0 on the zero state (theta = theta' = 0) is Eq. 7, and
    Table 1's lengths peak at 0.75 at apogee for e = 0.2.
    """
    l0 = np.array([0.5, 0.3])
    nu = np.linspace(-2.0, 14.0, 161)
    for nu0 in (0.0, 1.1):
        length = zero_state_length(nu, l0, e, nu0)
        assert length.shape == (161, 2)
        np.testing.assert_allclose(zero_state_length(nu0, l0, e, nu0), l0, rtol=1e-15)
        rate = zero_state_reel_rate(nu, length, e)
        fd = _d1(lambda v, v0=nu0: zero_state_length(v, l0, e, v0), nu, 1e-3)
        np.testing.assert_allclose(rate, fd, rtol=0, atol=1e-10)
    length = zero_state_length(nu, l0, e)
    np.testing.assert_allclose(
        periodic_reel_rate(nu[:, None], 0.0, 0.0, length, e, 0.0),
        zero_state_reel_rate(nu, length, e), rtol=1e-14, atol=1e-16)
    if e == 0.2:
        np.testing.assert_allclose(zero_state_length(np.pi, [0.5, 0.5], e), [0.75, 0.75],
                                   rtol=1e-15)


# --------------------------------------------------------------------------- #
# Eq. 10 as state feedback
# --------------------------------------------------------------------------- #
@pytest.mark.slow  # ~7 s alone (75k Python-level right-hand sides), ~11 s on a busy machine
def test_eq10_state_feedback_tracks_periodic_solution():
    """Eq. 10 on the measured state keeps theta = A sin(nu) to 1e-8 over three orbits.

    Table 1 chain (N = 3, masses (1, 2), l(0) = (0.5, 0.5)), e = 0.2,
    A = 0.1, 0.2, 0.3, theta = 0 and theta' = A at nu = 0, RK4 h = 0.001.
    Each reel runs l_i' = periodic_reel_rate(nu, theta_i, theta_i', l_i) and l_i''
    is the exact derivative of that law along the motion,
    l'' = l' g + l (g0 + g_th theta''), solved together with
    theta'' = f + B l' + D l'' from TetherChain.control_affine (D = 0 for an aligned
    chain, so this is explicit there). The chain then obeys theta'' = -A sin(nu)
    exactly and the remaining error is RK4's.
    """
    e = 0.2
    amps = np.array([0.1, 0.2, 0.3])
    chain = TetherChain(TABLE1_MASSES, e)
    n = 2
    h = 1e-3
    n_steps = int(np.ceil(6.0 * np.pi / h))
    eye = np.eye(n)

    def rhs(nu, y, args, dydt, node=False):
        Y = y.reshape(3, 3 * n)
        th, dth, ln = Y[:, :n], Y[:, n:2 * n], Y[:, 2 * n:]
        dl = periodic_reel_rate(nu, th, dth, ln, e, amps[:, None])  # one row per A
        g, g0, g_th = _eq10_ratio_and_derivative(nu, th, dth, e, amps[:, None])
        f, B, D = chain.control_affine(nu, th, dth, ln)
        free = f + np.einsum("aij,aj->ai", B, dl)
        beta = ln * g_th
        lhs = eye - beta[:, :, None] * D
        ddl = np.linalg.solve(lhs, (dl * g + ln * g0 + beta * free)[:, :, None])[:, :, 0]
        ddth = free + np.einsum("aij,aj->ai", D, ddl)
        dydt[:] = np.concatenate([dth, ddth, dl], axis=1).ravel()

    step = make_rk4(rhs, compiled=False)
    y0 = np.concatenate([np.zeros((3, n)), np.repeat(amps[:, None], n, axis=1),
                         np.full((3, n), 0.5)], axis=1).ravel()
    traj = rk4_integrate(step, 0.0, y0, h, n_steps, None).reshape(n_steps + 1, 3, 3 * n)
    nu = h * np.arange(n_steps + 1)
    assert nu[-1] >= 6.0 * np.pi
    target = amps[None, :, None] * np.sin(nu)[:, None, None]
    target_rate = amps[None, :, None] * np.cos(nu)[:, None, None]
    assert np.max(np.abs(traj[:, :, :n] - target)) < 1e-8
    assert np.max(np.abs(traj[:, :, n:2 * n] - target_rate)) < 1e-8
    length = traj[:, :, 2 * n:]
    assert np.all(length > 0.0)
    # reel magnitude (swing of l_1 + l_2 over the run, per unit L0): docs/model.md quotes
    # about 22 %, 3 % and 19 % for A = 0.1, 0.2, 0.3 (the paper: 24 %, 2 %, 18 %)
    swing = np.ptp(length.sum(axis=2), axis=0)
    np.testing.assert_allclose(swing, [0.22, 0.035, 0.19], rtol=0.0, atol=0.01)


# --------------------------------------------------------------------------- #
# Eq. 11a
# --------------------------------------------------------------------------- #
def _eq10_small_amplitude_log_rate(s, e, amplitude):
    """d ln(l)/d nu of Eq. 10 with sin(2 theta) -> 2 theta on theta = A sin(nu)."""
    th, dth = amplitude * np.sin(s), amplitude * np.cos(s)
    k = 1.0 + e * np.cos(s)
    return ((4 * e * np.sin(s) * (1 + dth) + 2 * amplitude * k * np.sin(s) - 6 * th)
            / (4 * k * (1 + dth)))


@pytest.mark.parametrize("e, amplitude", [
    (0.2, 0.05), (0.2, 0.1), (0.2, 0.199), (0.2, 0.2), (0.2, 0.201), (0.2, 0.3),
    (0.5, 0.1), (0.5, 0.5), (0.7, 0.3), (0.0, 0.2),
])
def test_eq11a_is_small_amplitude_integral_of_eq10(e, amplitude):
    """periodic_length_small_amplitude = l0 exp(int_0^nu Eq. 10 (small A)) to 1e-10.

    Quadrature (scipy.integrate.quad) of the small-amplitude Eq. 10 over
    consecutive pieces of [0, 4 pi]; includes the A = e branch and its neighbours.
    """
    l0 = np.array([0.5, 0.25])
    nodes = np.linspace(0.0, 4.0 * np.pi, 41)
    log_ratio = [0.0]
    for a, b in zip(nodes[:-1], nodes[1:], strict=True):
        piece, _ = quad(_eq10_small_amplitude_log_rate, a, b, args=(e, amplitude),
                        epsabs=1e-15, epsrel=1e-13)
        log_ratio.append(log_ratio[-1] + piece)
    expected = l0 * np.exp(np.array(log_ratio))[:, None]
    got = periodic_length_small_amplitude(nodes[:, None], l0, e, amplitude)
    assert got.shape == (41, 2)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=0.0)


# --------------------------------------------------------------------------- #
# Sec. 3.2 tension polynomial
# --------------------------------------------------------------------------- #
def _periodic_solution_tension(chain, nu, e, amplitude, length):
    """T^ of an aligned chain on theta = A sin(nu) driven by Eq. 10 (open loop).

    theta_i = A sin(nu), theta_i' = A cos(nu), theta'' = -A sin(nu) for every
    tether, l' from periodic_reel_rate and l'' = l' g + l g' (exact).
    """
    n = chain.n_tethers
    nu = np.asarray(nu, dtype=float)
    th, dth, ddth = desired_libration(nu, amplitude, 1.0)
    th_n, dth_n = (np.repeat(np.asarray(v)[..., None], n, axis=-1) for v in (th, dth))
    ln = np.broadcast_to(length, th_n.shape)
    dl = periodic_reel_rate(nu[..., None], th_n, dth_n, ln, e, amplitude)
    g, g0, g_th = _eq10_ratio_and_derivative(nu[..., None], th_n, dth_n, e, amplitude)
    ddl = dl * g + ln * (g0 + g_th * np.asarray(ddth)[..., None])
    return chain.tension(nu, th_n, dth_n, ln, dl, ddl)


@pytest.mark.parametrize("masses", [(1.0,), TABLE1_MASSES, (1.0, 2.0, 1.5)])
def test_tension_polynomial_is_last_tension_at_apogee(masses):
    """poly(e, A) = 2 (1-e)^2 (1-A) T^_{N-1} / (M_{N-1} sum_k l_k) at nu = pi (1e-12).

    On the periodic solution of an aligned chain the last tension is
    M_{N-1} (sum_k l_k) times a function of (nu, e, A) alone; at apogee that function
    times 2 (1-e)^2 (1-A) is the paper's polynomial.
    """
    length = np.linspace(0.3, 0.6, len(masses))
    for e in (0.0, 0.2, 0.5, 0.7):
        chain = TetherChain(masses, e)
        for amplitude in (0.05, 0.2, 0.35, 0.5, 0.8):
            tension = _periodic_solution_tension(chain, np.pi, e, amplitude, length)
            scaled = (2.0 * (1 - e) ** 2 * (1 - amplitude) * tension[-1]
                      / (chain.mass_fractions[-1] * length.sum()))
            poly = tension_positivity_polynomial(e, amplitude)
            assert scaled == pytest.approx(poly, rel=1e-12, abs=1e-12)


def test_tension_polynomial_sign_versus_orbit_minimum():
    """docs/model.md: the polynomial's sign is that of the orbit-minimum last tension up to
    e = 0.5, and it is slightly too permissive at e = 0.7 (Table 1 chain)."""
    chain_nu = np.linspace(0.0, 2.0 * np.pi, 2001)  # includes apogee
    amps = np.arange(0.02, 0.99, 0.02)
    length = np.array([0.5, 0.5])
    for e in (0.0, 0.2, 0.5):
        chain = TetherChain(TABLE1_MASSES, e)
        minimum = np.array([_periodic_solution_tension(chain, chain_nu, e, a, length)[:, -1].min()
                            for a in amps])
        poly = tension_positivity_polynomial(e, amps)
        assert np.any(poly < 0) and np.any(poly > 0)
        np.testing.assert_array_equal(np.sign(minimum), np.sign(poly))
    chain = TetherChain(TABLE1_MASSES, 0.7)
    amps = np.linspace(0.6, 0.7, 101)
    minimum = np.array([_periodic_solution_tension(chain, chain_nu, 0.7, a, length)[:, -1].min()
                        for a in amps])
    poly = tension_positivity_polynomial(0.7, amps)
    assert np.any((poly > 0) & (minimum < 0))
    assert not np.any((poly < 0) & (minimum > 0))


@pytest.mark.parametrize("gap", [1e-6, 1e-8, 1e-10, 1e-12, 0.0])
def test_eq11a_has_no_cancellation_near_a_equal_e(gap):
    """Near A = e Eq. 11a's 1/(A - e) form cancels; ours stays within 1e-13 of quadrature."""
    e = 0.2
    amplitude = e + gap

    def rate(v):  # small-A Eq. 10: d ln l / d nu with sin(2 theta) -> 2 theta
        return ((4 * e * np.sin(v) * (1 + amplitude * np.cos(v))
                 + 2 * amplitude * (1 + e * np.cos(v)) * np.sin(v) - 6 * amplitude * np.sin(v))
                / (4 * (1 + e * np.cos(v)) * (1 + amplitude * np.cos(v))))

    for nu in (0.7, 2.5, 4.0):
        exact = np.exp(quad(rate, 0.0, nu, epsabs=1e-15, epsrel=1e-15)[0])
        assert abs(periodic_length_small_amplitude(nu, 1.0, e, amplitude) - exact) < 1e-13


def test_reel_laws_pair_batch_nu_with_tether_lengths():
    """nu of shape (B,) pairs with lengths (B, n) for B != n and B == n alike."""
    rng = np.random.default_rng(3)
    for batch, n in ((5, 2), (3, 3)):
        nu = rng.uniform(0, 6, batch)
        length = rng.uniform(0.2, 1.0, (batch, n))
        got = periodic_reel_rate(nu, 0.1, 0.2, length, 0.2, 0.2)
        loop = np.array([periodic_reel_rate(nu[b], 0.1, 0.2, length[b], 0.2, 0.2)
                         for b in range(batch)])
        np.testing.assert_array_equal(got, loop)
        got0 = zero_state_reel_rate(nu, length, 0.2)
        loop0 = np.array([zero_state_reel_rate(nu[b], length[b], 0.2) for b in range(batch)])
        np.testing.assert_array_equal(got0, loop0)
