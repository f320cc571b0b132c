"""Layouts of the chain's state row and parameter row, and the parameter-row packer.

State row (one per chain), n = N-1 tethers, primes are d/dnu (paper Sec. 2)::

    [theta_1..theta_n, theta_1'..theta_n', l_1..l_n, l_1'..l_n']

Parameter row (one per chain, or one shared by a batch)::

    [e, gravity code, L0/p, a_bound, v_bound, tau, Mt_1..Mt_n]

with Mt_j = sum_{i>=j} M_i the mass fraction hanging on tether j (encoded by
:func:`tail_masses`, decoded by :func:`mass_fraction`), a_bound = a_max / (L0 n^2)
and v_bound = v_max / (L0 n) the reel limits made dimensionless
(:class:`tether_gym.params.Scales`; inf for no limit) and tau the reel lag [rad].
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..params import Gravity
from .jit import INLINE
from .layout import Field, Layout, at

__all__ = ["STATE", "PARAMS", "S", "P", "GRAVITY_CODE", "pack_params", "mass_fractions",
           "tail_masses", "mass_fraction"]

STATE = Layout("state", (
    Field("theta", True, "[rad]", "libration angle from the local vertical (to Earth), "
          "positive when the lower body trails"),
    Field("dtheta", True, "[rad/rad]", "theta' = d theta / d nu"),
    Field("length", True, "[-]", "tether length l = L / L0"),
    Field("dlength", True, "[-]", "reel rate l' = dl / d nu"),
))
S = STATE.index
"""Offsets of the state row's fields, ``at(S.length, n)`` etc."""

PARAMS = Layout("params", (
    Field("eccentricity", False, "[-]", "orbit eccentricity e"),
    Field("gravity", False, "[-]", "gravity model code (GRAVITY_CODE)"),
    Field("length_ratio", False, "[-]", "L0 / p (full gravity only)"),
    Field("accel_bound", False, "[-]", "reel acceleration limit a_max / (L0 n^2)"),
    Field("speed_bound", False, "[-]", "reel speed limit v_max / (L0 n)"),
    Field("time_constant", False, "[rad]", "reel lag tau"),
    Field("tail_mass", True, "[-]", "Mt_j = sum_{i>=j} M_i"),
))
P = PARAMS.index
"""Offsets of the parameter row's fields."""

GRAVITY_CODE = {Gravity.GRADIENT: 0, Gravity.FULL: 1}
"""Gravity model -> the integer the kernels read (the only place it is an integer)."""
GRAVITY_FULL_CODE = GRAVITY_CODE[Gravity.FULL]


def mass_fractions(masses) -> np.ndarray:
    """M_i = m_i / sum(m) [-], along the last axis."""
    m = np.asarray(masses, dtype=float)
    return m / m.sum(axis=-1, keepdims=True)


def tail_masses(masses) -> np.ndarray:
    """Mt_j = sum_{i>=j} M_i [-] (:func:`mass_fractions`), along the last axis."""
    frac = mass_fractions(masses)
    return np.cumsum(frac[..., ::-1], axis=-1)[..., ::-1]


@njit(**INLINE)
def mass_fraction(par, j, n):
    """M_j = Mt_j - Mt_{j+1} [-] from a parameter row (inverse of :func:`tail_masses`)."""
    t = at(P.tail_mass, n)
    return par[t + j] - (par[t + j + 1] if j + 1 < n else 0.0)


def pack_params(eccentricity, tail, gravity: Gravity = Gravity.GRADIENT,
                length_ratio: float = 0.0, accel_bound: float = math.inf,
                speed_bound: float = math.inf, time_constant: float = 1.0) -> np.ndarray:
    """Parameter rows (module docstring) for e of shape (...,) and tails of shape (..., n).

    Returns an array of shape (..., PARAMS.size(n)); e and the tails broadcast.
    """
    ecc = np.asarray(eccentricity, dtype=float)
    tail = np.asarray(tail, dtype=float)
    n = tail.shape[-1]
    lead = np.broadcast_shapes(ecc.shape, tail.shape[:-1])
    rows = np.empty(lead + (PARAMS.size(n),))
    sl = PARAMS.slices(n)
    rows[..., sl["eccentricity"]] = ecc[..., None]
    rows[..., sl["gravity"]] = float(GRAVITY_CODE[Gravity.parse(gravity)])
    rows[..., sl["length_ratio"]] = length_ratio
    rows[..., sl["accel_bound"]] = accel_bound
    rows[..., sl["speed_bound"]] = speed_bound
    rows[..., sl["time_constant"]] = time_constant
    rows[..., sl["tail_mass"]] = tail
    return rows
