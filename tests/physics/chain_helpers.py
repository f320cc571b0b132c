"""Shared helpers for the physics tests (not a test module).

Imported by the test modules of this directory as a top-level module (pytest's
default ``prepend`` import mode puts this directory on ``sys.path``).
"""

from __future__ import annotations

import numpy as np

from tether_gym.physics import kernels


def advance(nu, y, cmd, par, h, n_sub, dist=None):
    """Run :func:`tether_gym.physics.kernels.advance` in place on a batch.

    Parameters
    ----------
    nu : ndarray, shape (B,)
        True anomaly [rad]; updated in place.
    y : ndarray, shape (B, 4n)
        States ``[theta, theta', l, l']``; updated in place.
    cmd : ndarray, shape (B, n)
        Commanded reel rates l'_cmd [-].
    par : ndarray, shape (1 or B, 6 + n)
        Parameter rows from :func:`kernels.pack_params`.
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
    batch, m = y.shape
    n = m // 4
    if dist is None:
        dist = np.zeros((batch, n))
    tension_min = np.empty((batch, n))
    deriv_end = np.empty((batch, m))
    tension_end = np.empty((batch, n))
    kernels.advance(nu, y, cmd, dist, par, h, n_sub, tension_min, deriv_end, tension_end)
    return tension_min, deriv_end, tension_end


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
