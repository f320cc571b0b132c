"""Tests of the Keplerian orbit helpers (tether_gym.physics.orbit).

Checked against independent computations: finite differences of the Kepler-equation
maps, quadrature of dt = dnu / nu_dot, Kepler's third law, the vis-viva equation and
a numerically differentiated L(t) = L0 l(nu(t)).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from tether_gym.params import OrbitParams
from tether_gym.physics import orbit

ECCENTRICITIES = [0.0, 0.2, 0.7]
P = 8.52e6
N_RATE = OrbitParams().rate_scale  # n = sqrt(mu / p^3) [rad/s] for p = 8520 km


def _d1(fun, t, dt):
    """Five-point central first derivative (error O(dt^4))."""
    return (fun(t - 2 * dt) - 8 * fun(t - dt) + 8 * fun(t + dt) - fun(t + 2 * dt)) / (12 * dt)


def _d2(fun, t, dt):
    """Five-point central second derivative (error O(dt^4))."""
    return (-fun(t - 2 * dt) + 16 * fun(t - dt) - 30 * fun(t) + 16 * fun(t + dt)
            - fun(t + 2 * dt)) / (12 * dt**2)


def _times(e, n, orbits=3.0, count=400):
    period = 2.0 * np.pi / (n * (1.0 - e**2) ** 1.5)
    return np.linspace(-0.5 * period, orbits * period, count)


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_nu_dot_and_nu_ddot_match_finite_differences(e):
    """nu_dot and nu_ddot equal 5-point differences of true_anomaly_from_time (1e-9).

    Step dt = 1e-3 / n; the error of the differences is O(dt^4) plus roundoff,
    both below 1e-10 relative here.
    """
    n = N_RATE
    t = _times(e, n)
    dt = 1e-3 / n
    nu = orbit.true_anomaly_from_time(t, e, n)

    fd_rate = _d1(lambda s: orbit.true_anomaly_from_time(s, e, n), t, dt)
    rate = orbit.nu_dot(nu, e, n)
    assert np.max(np.abs(fd_rate - rate)) <= 1e-9 * np.max(np.abs(rate))

    fd_acc = _d1(lambda s: orbit.nu_dot(orbit.true_anomaly_from_time(s, e, n), e, n), t, dt)
    acc = orbit.nu_ddot(nu, e, n)
    scale = n**2 * (1.0 + e) ** 3  # max |nu_ddot| is O(n^2 e k^3)
    assert np.max(np.abs(fd_acc - acc)) <= 1e-9 * scale


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_time_and_true_anomaly_are_inverse(e):
    """t(nu) and nu(t) invert each other over several orbits, also with nu0 != 0 (1e-12)."""
    n = N_RATE
    nu = np.concatenate([np.linspace(-4.0 * np.pi, 10.0 * np.pi, 1001),
                         np.pi * np.arange(-3, 10), [1e-14, -1e-14]])
    for nu0 in (0.0, 1.3, -2.0 * np.pi + 0.4):
        t = orbit.time_from_true_anomaly(nu, e, n, nu0)
        back = orbit.true_anomaly_from_time(t, e, n, nu0)
        assert np.max(np.abs(back - nu)) <= 1e-12
    period = OrbitParams(eccentricity=e).period
    t = np.linspace(-2.0 * period, 5.0 * period, 777)
    again = orbit.time_from_true_anomaly(orbit.true_anomaly_from_time(t, e, n), e, n)
    assert np.max(np.abs(again - t)) <= 1e-12 * period


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_time_is_monotone_and_matches_quadrature(e):
    """t(nu) increases strictly (also across nu = pi (2m+1)) and equals int dnu / nu_dot."""
    n = N_RATE
    nu = np.linspace(-3.0 * np.pi, 7.0 * np.pi, 20001)
    t = orbit.time_from_true_anomaly(nu, e, n)
    assert np.all(np.diff(t) > 0.0)
    for end in (0.7, np.pi, 2.5 * np.pi, -1.9):
        ref, _ = quad(lambda v: 1.0 / orbit.nu_dot(v, e, n), 0.0, end,
                      epsabs=0.0, epsrel=1e-13, limit=200)
        assert abs(orbit.time_from_true_anomaly(end, e, n) - ref) <= 1e-12 * abs(ref)


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_period(e):
    """OrbitParams.period is Kepler's third law and the time for each 2 pi of nu."""
    params = OrbitParams(eccentricity=e)
    a = P / (1.0 - e**2)
    mu = params.mu
    assert params.period == pytest.approx(2.0 * np.pi * np.sqrt(a**3 / mu), rel=1e-14)
    n = params.rate_scale
    assert n == pytest.approx(np.sqrt(mu / P**3), rel=1e-15)
    assert orbit.rate_scale(P, mu) == pytest.approx(n, rel=1e-15)
    for m in (1, 2, 5):
        for start in (0.0, 0.9, -2.0):
            dt = orbit.time_from_true_anomaly(start + 2.0 * np.pi * m, e, n, start)
            assert dt == pytest.approx(m * params.period, rel=1e-13)
    assert orbit.true_anomaly_from_time(params.period, e, n) == pytest.approx(
        2.0 * np.pi, rel=0.0, abs=1e-12)


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_radius_and_vis_viva(e):
    """r = p/k (perigee p/(1+e), apogee p/(1-e)) and v^2 = mu (2/r - 1/a) (1e-13)."""
    mu = OrbitParams().mu
    n = orbit.rate_scale(P, mu)
    assert orbit.radius(0.0, P, e) == pytest.approx(P / (1.0 + e), rel=1e-15)
    assert orbit.radius(np.pi, P, e) == pytest.approx(P / (1.0 - e), rel=1e-15)
    nu = np.linspace(-np.pi, 3.0 * np.pi, 101)
    r = orbit.radius(nu, P, e)
    dr_dnu = P * e * np.sin(nu) / orbit.k_factor(nu, e) ** 2
    speed2 = (dr_dnu**2 + r**2) * orbit.nu_dot(nu, e, n) ** 2
    a = P / (1.0 - e**2)
    np.testing.assert_allclose(speed2, mu * (2.0 / r - 1.0 / a), rtol=1e-13)


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_reel_conversions_are_inverse(e):
    """reel_rate/accel to_physical and from_physical are inverse maps (1e-14)."""
    rng = np.random.default_rng(1)
    n, L0 = N_RATE, 2e4
    nu = rng.uniform(-10.0, 10.0, 300)
    dl = rng.uniform(-1.0, 1.0, 300)
    ddl = rng.uniform(-1.0, 1.0, 300)
    rate = orbit.reel_rate_to_physical(nu, dl, e, n, L0)
    np.testing.assert_allclose(orbit.reel_rate_from_physical(nu, rate, e, n, L0), dl,
                               rtol=1e-14, atol=0.0)
    accel = orbit.reel_accel_to_physical(nu, dl, ddl, e, n, L0)
    np.testing.assert_allclose(orbit.reel_accel_from_physical(nu, dl, accel, e, n, L0), ddl,
                               rtol=0.0, atol=1e-14)
    phys = rng.uniform(-0.02, 0.02, 300)  # [m/s^2]
    dl_back = orbit.reel_accel_to_physical(
        nu, dl, orbit.reel_accel_from_physical(nu, dl, phys, e, n, L0), e, n, L0)
    np.testing.assert_allclose(dl_back, phys, rtol=0.0, atol=1e-14 * 0.02)


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_reel_formulas_are_time_derivatives(e):
    """L_dot and L_ddot formulas equal d/dt, d^2/dt^2 of L(t) = L0 l(nu(t)) (1e-8).

    l(nu) = 0.5 + 0.1 sin(2 nu) + 0.05 cos(3 nu); derivatives by 5-point
    differences in t with dt = 1e-3 / (n (1+e)^2) (nu moves by <= 1e-3 per step) for
    L_dot and 4 dt for L_ddot; measured errors <= 1e-9 relative.
    """
    n, L0 = N_RATE, 2e4

    def ell(v):
        return 0.5 + 0.1 * np.sin(2 * v) + 0.05 * np.cos(3 * v)

    def dell(v):
        return 0.2 * np.cos(2 * v) - 0.15 * np.sin(3 * v)

    def ddell(v):
        return -0.4 * np.sin(2 * v) - 0.45 * np.cos(3 * v)

    def big_l(s):
        return L0 * ell(orbit.true_anomaly_from_time(s, e, n))

    t = _times(e, n, orbits=2.0, count=300)
    nu = orbit.true_anomaly_from_time(t, e, n)
    dt = 1e-3 / (n * (1.0 + e) ** 2)
    rate = orbit.reel_rate_to_physical(nu, dell(nu), e, n, L0)
    accel = orbit.reel_accel_to_physical(nu, dell(nu), ddell(nu), e, n, L0)
    assert np.max(np.abs(_d1(big_l, t, dt) - rate)) <= 1e-8 * np.max(np.abs(rate))
    # a larger step for the second difference keeps its roundoff (~eps L / dt^2) small
    assert np.max(np.abs(_d2(big_l, t, 4.0 * dt) - accel)) <= 1e-8 * np.max(np.abs(accel))
