"""Tests of the orbit terms of the reel dynamics (tether_gym.physics.orbit) and of Scales.

Checked against independent computations: finite differences in time of
L(t) = L0 l(nu(t)) through Kepler's equation (tests/physics/kepler.py), quadrature
of dt = dnu / nu_dot, Kepler's third law and the exact inverse relations.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from kepler import time_from_true_anomaly, true_anomaly_from_time
from scipy.integrate import quad

from tether_gym.params import OrbitParams
from tether_gym.physics import Scales
from tether_gym.physics.orbit import coriolis, ddlength_from_accel, reel_accel

ECCENTRICITIES = [0.0, 0.2, 0.7]
P = 8.52e6
L0 = 2.0e4
N_RATE = OrbitParams().rate_scale  # n = sqrt(mu / p^3) [rad/s] for p = 8520 km


def _scales(e):
    return Scales(OrbitParams(eccentricity=e), L0)


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
def test_nu_dot_matches_finite_differences(e):
    """Scales.nu_dot = n k^2 equals 5-point differences of Kepler's map (1e-9)."""
    n = N_RATE
    t = _times(e, n)
    dt = 1e-3 / n
    nu = true_anomaly_from_time(t, e, n)
    fd_rate = _d1(lambda s: true_anomaly_from_time(s, e, n), t, dt)
    rate = _scales(e).nu_dot(nu, e)
    assert np.max(np.abs(fd_rate - rate)) <= 1e-9 * np.max(np.abs(rate))


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_kepler_reference_map(e):
    """The test's Kepler map: inverse to 1e-12, t(nu) = int dnu / nu_dot, period = Kepler III."""
    n = N_RATE
    nu = np.concatenate([np.linspace(-4.0 * np.pi, 10.0 * np.pi, 1001), [1e-14, -1e-14]])
    for nu0 in (0.0, 1.3, -2.0 * np.pi + 0.4):
        back = true_anomaly_from_time(time_from_true_anomaly(nu, e, n, nu0), e, n, nu0)
        assert np.max(np.abs(back - nu)) <= 1e-12
    scales = _scales(e)
    for end in (0.7, np.pi, 2.5 * np.pi, -1.9):
        ref, _ = quad(lambda v: 1.0 / scales.nu_dot(v, e), 0.0, end, epsabs=0.0,
                      epsrel=1e-13, limit=200)
        assert abs(time_from_true_anomaly(end, e, n) - ref) <= 1e-12 * abs(ref)
    period = OrbitParams(eccentricity=e).period
    a = P / (1.0 - e**2)
    assert period == pytest.approx(2.0 * np.pi * np.sqrt(a**3 / OrbitParams().mu), rel=1e-14)
    assert time_from_true_anomaly(2.0 * np.pi, e, n) == pytest.approx(period, rel=1e-13)


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_reel_formulas_are_time_derivatives(e):
    """Scales' L_dot and L_ddot equal d/dt, d^2/dt^2 of L(t) = L0 l(nu(t)) (1e-8).

    l(nu) = 0.5 + 0.1 sin(2 nu) + 0.05 cos(3 nu); derivatives by 5-point
    differences in t with dt = 1e-3 / (n (1+e)^2) (nu moves by <= 1e-3 per step) for
    L_dot and 4 dt for L_ddot.
    """
    n = N_RATE
    scales = _scales(e)

    def ell(v):
        return 0.5 + 0.1 * np.sin(2 * v) + 0.05 * np.cos(3 * v)

    def dell(v):
        return 0.2 * np.cos(2 * v) - 0.15 * np.sin(3 * v)

    def ddell(v):
        return -0.4 * np.sin(2 * v) - 0.45 * np.cos(3 * v)

    def big_l(s):
        return L0 * ell(true_anomaly_from_time(s, e, n))

    t = _times(e, n, orbits=2.0, count=300)
    nu = true_anomaly_from_time(t, e, n)
    dt = 1e-3 / (n * (1.0 + e) ** 2)
    rate = scales.reel_rate_si(nu, e, dell(nu))
    accel = scales.reel_accel_si(nu, e, dell(nu), ddell(nu))
    assert np.max(np.abs(_d1(big_l, t, dt) - rate)) <= 1e-8 * np.max(np.abs(rate))
    # a larger step for the second difference keeps its roundoff (~eps L / dt^2) small
    assert np.max(np.abs(_d2(big_l, t, 4.0 * dt) - accel)) <= 1e-8 * np.max(np.abs(accel))


@pytest.mark.parametrize("e", ECCENTRICITIES)
def test_reel_accel_and_its_inverse(e):
    """reel_accel = k^4 l'' - 2 e sin(nu) k^3 l' and ddlength_from_accel inverts it (1e-14).

    The compiled helpers equal their plain-Python bodies bit for bit.
    """
    rng = np.random.default_rng(1)
    for _ in range(200):
        nu, dl, ddl = rng.uniform(-10.0, 10.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)
        k, sn = 1.0 + e * math.cos(nu), math.sin(nu)
        a = reel_accel(k, sn, e, dl, ddl)
        assert a == pytest.approx(k**4 * ddl - 2.0 * e * sn * k**3 * dl, rel=1e-14, abs=1e-15)
        assert a == reel_accel.py_func(k, sn, e, dl, ddl)
        cor = coriolis(k, sn, e, dl)
        assert ddlength_from_accel(k**4, cor, a) == pytest.approx(ddl, rel=1e-13, abs=1e-14)


def test_scales_bounds_and_scales():
    """a_max / (L0 n^2) is 15.5, 1.55, 0.776 for L0 = 1, 10, 20 km (docs/model.md); v / (L0 n)."""
    orbit = OrbitParams()
    n = orbit.rate_scale
    assert n == pytest.approx(np.sqrt(orbit.mu / P**3), rel=1e-15)
    for length, expected in ((1e3, 15.5), (1e4, 1.55), (2e4, 0.776)):
        scales = Scales(orbit, length)
        assert scales.accel_bound(0.01) == pytest.approx(0.01 / (length * n**2), rel=1e-15)
        assert scales.accel_bound(0.01) == pytest.approx(expected, rel=5e-3)
        assert scales.accel_bound(None) == math.inf
        assert scales.speed_bound(2.0) == pytest.approx(2.0 / (length * n), rel=1e-15)
        assert scales.length_ratio == pytest.approx(length / P, rel=1e-15)
    with pytest.raises(ValueError, match="total_tether_length"):
        Scales(orbit, -1.0)
    with pytest.raises(TypeError, match="total_tether_length"):
        Scales(orbit, "2e4")
