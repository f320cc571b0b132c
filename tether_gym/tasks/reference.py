"""Reference librations and the paper's open-loop reel laws (pure functions).

All tethers track the same reference (paper Eq. 8-9, w the libration frequency per
radian of true anomaly, A the amplitude [rad]):

    theta_d = A sin(w nu),  theta_d' = A w cos(w nu),  theta_d'' = -A w^2 sin(w nu).

A = 0 is the zero state of Sec. 3.1.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..physics.jit import INLINE

__all__ = [
    "desired_libration",
    "desired_libration_jit",
    "zero_state_reel_rate",
    "zero_state_length",
    "periodic_reel_rate",
    "periodic_reel_factors",
    "expand_like",
    "periodic_length_small_amplitude",
    "tension_positivity_polynomial",
]


def desired_libration(nu, amplitude, frequency):
    """(theta_d, theta_d', theta_d'') [rad, rad/rad, rad/rad^2] at true anomaly nu.

    Plain arithmetic on floats or arrays; :func:`desired_libration_jit` is the same
    function compiled for the kernels.
    """
    phase = frequency * nu
    s = np.sin(phase)
    return (amplitude * s, amplitude * frequency * np.cos(phase),
            -amplitude * frequency * frequency * s)


desired_libration_jit = njit(**INLINE)(desired_libration)


def expand_like(nu, like):
    """nu as a float array, with a trailing axis when ``like`` has one more axis.

    Pairs per-episode values (nu, theta_d, ...) of shape (...) with per-tether values of
    shape (..., n).
    """
    nu = np.asarray(nu, dtype=float)
    return nu[..., None] if np.ndim(like) > nu.ndim else nu


def zero_state_reel_rate(nu, length, e):
    """Paper Eq. 7: l_i' = l_i e sin(nu) / (1 + e cos(nu)) keeps theta = theta' = 0."""
    length = np.asarray(length, dtype=float)
    nu = expand_like(nu, length)
    return length * e * np.sin(nu) / (1.0 + e * np.cos(nu))


def zero_state_length(nu, length0, e, nu0=0.0):
    """Integral of Eq. 7: l_i = l_i(nu0) (1 + e cos nu0) / (1 + e cos nu)."""
    nu = np.asarray(nu, dtype=float)
    ratio = (1.0 + e * np.cos(nu0)) / (1.0 + e * np.cos(nu))
    return np.asarray(length0, dtype=float) * (ratio[..., None] if np.ndim(length0) > 0 and
                                               nu.ndim > 0 else ratio)


def periodic_reel_rate(nu, theta, dtheta, length, e, amplitude, frequency=1.0):
    """Paper Eq. 10 as corrected, for an aligned chain on theta = A sin(w nu).

    (docs/model.md#periodic-reference-eqs-8-10)

    l_i' = l_i [4 e sin(nu)(1 + theta') + 2 A k w^2 sin(w nu) - 3 sin(2 theta)]
           / (4 k (1 + theta'))

    ``theta`` and ``dtheta`` are the (common) libration angle and rate at which the
    law is evaluated: the reference itself for the open-loop law, or the measured
    state. ``nu`` of shape (...) pairs with ``length`` of shape (..., n).
    """
    length = np.asarray(length, dtype=float)
    num, den = periodic_reel_factors(expand_like(nu, length), expand_like(theta, length),
                                     expand_like(dtheta, length), e, amplitude, frequency)
    return length * num / den


def periodic_reel_factors(nu, theta, dtheta, e, amplitude, frequency=1.0):
    """(num, den) of Eq. 10, l_i' = l_i num / den (see :func:`periodic_reel_rate`).

    num = 4 e sin(nu)(1 + theta') + 2 A k w^2 sin(w nu) - 3 sin(2 theta),
    den = 4 k (1 + theta'), k = 1 + e cos(nu); elementwise, broadcasting the arguments.
    """
    k = 1.0 + e * np.cos(nu)
    num = (4.0 * e * np.sin(nu) * (1.0 + dtheta)
           + 2.0 * amplitude * k * frequency**2 * np.sin(frequency * nu)
           - 3.0 * np.sin(2.0 * theta))
    return num, 4.0 * k * (1.0 + dtheta)


def periodic_length_small_amplitude(nu, length0, e, amplitude):
    """Paper Eq. 11a: small-A integral of Eq. 10 for w = 1.

    (docs/model.md#small-amplitude-closed-form-eqs-11a-11b)

    ln(l/l0) = {(2A+e)[ln(1+A cos nu) - ln(1+A)] + (2e-5A)[ln(1+e cos nu) - ln(1+e)]}
               / (2 (A - e)),
    and for A = e: ln(l/l0) = -(3/2)[ln(1+e cos nu) + 1/(1+e cos nu) - ln(1+e) - 1/(1+e)].
    Valid from nu = 0 (where l = l0). Evaluated without cancellation near A = e by
    writing 2e - 5A = -(2A + e) - 3(A - e):
    ln(l/l0) = (2A+e)/2 [g(x) - g(y)] - (3/2)[ln(1+e cos nu) - ln(1+e)] with
    g(z) = ln(1 + (A-e) z)/(A-e) (= z at A = e), x = cos nu/(1+e cos nu), y = 1/(1+e).
    """
    nu = np.asarray(nu, dtype=float)
    A = float(amplitude)
    delta = A - e
    c = np.cos(nu)
    x = c / (1.0 + e * c)
    y = 1.0 / (1.0 + e)

    def g(z):
        return z if delta == 0.0 else np.log1p(delta * z) / delta

    log_ratio = (0.5 * (2.0 * A + e) * (g(x) - g(y))
                 - 1.5 * (np.log1p(e * c) - np.log1p(e)))
    return np.asarray(length0, dtype=float) * np.exp(log_ratio)


def tension_positivity_polynomial(e, amplitude):
    """Sec. 3.2's condition for T^_{N-1} > 0 (the last tether at apogee).

    (docs/model.md#tension-positivity-sec-32)

    6 - 12A + 6A^2 - 2A^3 - 6e + 15Ae - 12A^2 e + 4A^3 e - 3Ae^2 + 6A^2 e^2 - 2A^3 e^2;
    the paper requires it to be > 0.
    """
    A = amplitude
    return (6 - 12 * A + 6 * A**2 - 2 * A**3 - 6 * e + 15 * A * e - 12 * A**2 * e
            + 4 * A**3 * e - 3 * A * e**2 + 6 * A**2 * e**2 - 2 * A**3 * e**2)
