"""Shared helpers for the physics tests (not a test module).

Imported by the test modules of this directory as a top-level module (pytest's
default ``prepend`` import mode puts this directory on ``sys.path``).
"""

from __future__ import annotations

import numpy as np

from tether_gym.physics import transition


def advance(nu, y, cmd, par, h, n_sub, dist=None):
    """Run :func:`tether_gym.physics.transition` in place on a batch.

    Parameters
    ----------
    nu : ndarray, shape (B,)
        True anomaly [rad]; updated in place.
    y : ndarray, shape (B, 4n)
        States ``[theta, theta', l, l']``; updated in place.
    cmd : ndarray, shape (B, n)
        Commanded reel rates l'_cmd [-].
    par : ndarray, shape (1 or B, 6 + n)
        Parameter rows (``TetherChain.param_row``).
    h : float
        RK4 step [rad].
    n_sub : int
        Number of steps.
    dist : ndarray, shape (B, n), optional
        Disturbance added to theta'' (zero by default).

    Returns
    -------
    tension_min, deriv_end, tension_end : ndarray
        The kernel's outputs, shapes (B, n), (B, 4n), (B, n).
    """
    out = transition(nu, y, cmd, par, h, n_sub, disturbance=dist)
    nu[:] = out.nu
    y[:] = out.state
    return out.tension_min, out.derivative, out.tension


def rk4_integrate(integrate, t0, y0, h, n_steps, args):
    """Take ``n_steps`` steps with an integrator from :func:`make_rk4`, one call per step.

    Returns the array of states, shape (n_steps + 1, len(y0)).
    """
    y = np.array(y0, dtype=float)
    m = y.shape[0]
    out = np.empty((n_steps + 1, m))
    out[0] = y
    work = tuple(np.empty(m) for _ in range(5))
    deriv = np.empty(m)
    for i in range(n_steps):
        t = integrate(t0 + i * h, y, h, 1, args, work, deriv)
        assert t == t0 + i * h + h
        out[i + 1] = y
    return out


def random_states(rng, n, size, theta_scale=1.0):
    """Random chain states with every quantity of order one.

    Returns
    -------
    nu : ndarray, shape (size,)
    theta, dtheta, length, dlength, ddlength : ndarray, shape (size, n)
    """
    nu = rng.uniform(-2.0 * np.pi, 4.0 * np.pi, size)
    theta = theta_scale * rng.uniform(-1.0, 1.0, (size, n))
    dtheta = rng.uniform(-0.8, 0.8, (size, n))
    length = rng.uniform(0.1, 1.0, (size, n))
    dlength = rng.uniform(-0.5, 0.5, (size, n))
    ddlength = rng.uniform(-1.0, 1.0, (size, n))
    return nu, theta, dtheta, length, dlength, ddlength


def rel_err(a, b):
    """max |a - b| / (1 + |b|), elementwise, as one float."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b) / (1.0 + np.abs(b))))
