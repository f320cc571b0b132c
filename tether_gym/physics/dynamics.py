"""The public face of the physics: :class:`TetherChain` and :func:`transition`.

``TetherChain`` evaluates the chain's equations of motion at given states (theta'',
tensions, the control-affine split used by model-based controllers);
:func:`transition` advances states over a step with the reels in the loop, exactly
as the environments do (python-control's ``dynamics(t, x, u, params)`` /
Gymnasium FuncEnv's ``transition`` style). The equations themselves live in
:mod:`tether_gym.physics.kernels` (one copy, with their derivation); this module
validates inputs, broadcasts leading axes and calls them.

Variables (dimensionless, paper Sec. 2): ``nu`` true anomaly [rad]; ``theta`` [rad]
libration angle of each tether from the local vertical (pointing to Earth),
positive when the lower body trails the upper one; ``dtheta`` = d theta / d nu
[rad/rad]; ``length`` l_i = L_i / L0 [-]; ``dlength`` = l_i' [-]; ``ddlength`` = l_i''
[-]. Tensions T^_i = T_i / (nu_dot^2 L0 m_tot) [-].
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..params import Gravity, check_masses, check_range
from . import kernels
from .state import PARAMS, STATE, mass_fractions, pack_params, tail_masses

__all__ = ["TetherChain", "Transition", "transition"]

MIN_LENGTH = 1.0e-6
"""Shortest tether length l = L / L0 [-] the model evaluates (the equations divide by l)."""
MAX_MAGNITUDE = 1.0e6
"""Largest |value| of any state entry [-]: beyond it the results are not physics (the
terms grow like l^2 or 1/l and overflow to NaN)."""


class TetherChain:
    """Planar chain of N-1 point masses hanging from a heavy satellite on a Kepler orbit.

    Parameters
    ----------
    masses : sequence of float
        Subsatellite masses m_1 (attached to the main satellite) ... m_{N-1}, in any
        common unit, each > 0; normalised internally to M_i = m_i / m_tot.
    eccentricity : float
        Orbit eccentricity e [-] in [0, 1).
    gravity : {"gradient", "full"}
        Second-order gravity-gradient model (default; the paper's model) or exact
        inverse-square gravity.
    length_ratio : float, optional
        L0 / p [-] (initial total tether length over the semi-latus rectum), > 0;
        required by ``gravity="full"`` and ignored by the gradient model.

    Examples
    --------
    >>> chain = TetherChain(masses=(1.0, 2.0), eccentricity=0.2)
    >>> f, B, D = chain.control_affine(0.0, [0.1, 0.0], [0.2, 0.2], [0.5, 0.5])
    """

    def __init__(self, masses, eccentricity, gravity="gradient", length_ratio=None):
        masses = check_masses(masses)
        self.eccentricity = check_range("eccentricity", eccentricity, 0.0, 1.0, high_open=True)
        self.gravity = Gravity.parse(gravity)
        if self.gravity is Gravity.FULL:
            if length_ratio is None:
                raise ValueError("gravity='full' needs length_ratio = L0 / p (> 0); got None")
            self.length_ratio = check_range("length_ratio", length_ratio, 0.0, 1.0,
                                            low_open=True, high_open=True)
        else:
            self.length_ratio = (None if length_ratio is None else
                                 check_range("length_ratio", length_ratio, 0.0, 1.0,
                                             low_open=True, high_open=True))
        self.tail_masses = tail_masses(masses)
        """Mt_j = sum_{i>=j} M_i [-], the mass fraction hanging on tether j."""
        self.mass_fractions = mass_fractions(masses)
        """M_i = m_i / m_tot [-]."""
        self.par = self.param_row()[None, :]
        """The parameter row (1, P) of the chain without reel limits."""

    def param_row(self, accel_bound: float = math.inf, speed_bound: float = math.inf,
                  time_constant: float = 1.0) -> np.ndarray:
        """Parameter row (:data:`~tether_gym.physics.state.PARAMS`) with reel limits.

        Parameters
        ----------
        accel_bound, speed_bound : float
            Reel limits a_max / (L0 n^2) and v_max / (L0 n) [-]
            (:class:`tether_gym.params.Scales`); inf for none.
        time_constant : float
            Reel lag tau [rad], > 0.
        """
        check_range("time_constant", time_constant, 0.0, low_open=True)
        for name, value in (("accel_bound", accel_bound), ("speed_bound", speed_bound)):
            if not (isinstance(value, (int, float, np.floating)) and value > 0.0):
                raise ValueError(f"{name}={value!r} must be > 0 (inf for no limit)")
        return pack_params(self.eccentricity, self.tail_masses, self.gravity,
                           self.length_ratio or 0.0, accel_bound, speed_bound, time_constant)

    @property
    def n_tethers(self) -> int:
        """N - 1."""
        return self.mass_fractions.shape[0]

    def __repr__(self) -> str:
        return (f"TetherChain(masses={tuple(self.mass_fractions.round(12))}, "
                f"eccentricity={self.eccentricity}, gravity={self.gravity.value!r}"
                + (f", length_ratio={self.length_ratio}" if self.length_ratio else "") + ")")

    # ------------------------------------------------------------------ #
    def _broadcast(self, nu, *vectors):
        """Validate and broadcast to nu (B,), vectors (B, n); return shapes to restore."""
        n = self.n_tethers
        names = ("theta", "dtheta", "length", "dlength", "ddlength")
        nu = np.asarray(nu, dtype=float)
        arrs = []
        for name, v in zip(names, vectors, strict=False):  # names cover the longest call
            a = np.asarray(v, dtype=float)
            if a.ndim == 0 or a.shape[-1] != n:
                raise ValueError(f"{name} must have shape (..., {n}), got {a.shape}")
            arrs.append(a)
        lead = np.broadcast_shapes(nu.shape, *(a.shape[:-1] for a in arrs))
        for name, a in zip(("nu",) + names, [nu] + arrs, strict=False):
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name}={a!r} must be finite (no NaN or inf)")
        if np.any(arrs[2] < MIN_LENGTH) or np.any(arrs[2] > MAX_MAGNITUDE):
            raise ValueError(f"length={arrs[2]!r} must lie in [{MIN_LENGTH:g}, "
                             f"{MAX_MAGNITUDE:g}] (l = L / L0 [-])")
        for name, a in zip(("nu",) + names, [nu] + arrs, strict=False):
            if np.any(np.abs(a) > MAX_MAGNITUDE):
                raise ValueError(f"{name}={a!r} must lie in [-{MAX_MAGNITUDE:g}, "
                                 f"{MAX_MAGNITUDE:g}]")
        size = int(np.prod(lead))
        flat_nu = np.ascontiguousarray(np.broadcast_to(nu, lead).reshape(size))
        flat = [np.ascontiguousarray(np.broadcast_to(a, lead + (n,)).reshape(size, n))
                for a in arrs]
        return lead, flat_nu, flat

    def _accel(self, nu, theta, dtheta, length, dlength, ddlength):
        lead, nu_f, (th, dth, ln, dl, ddl) = self._broadcast(nu, theta, dtheta, length,
                                                             dlength, ddlength)
        ddtheta = np.empty_like(th)
        tension = np.empty_like(th)
        kernels.accel_rows(nu_f, _rows(th, dth, ln, dl), ddl, self.par, ddtheta, tension,
                           kernels.make_scratch(self.n_tethers))
        shape = lead + (self.n_tethers,)
        return ddtheta.reshape(shape), tension.reshape(shape)

    def theta_ddot(self, nu, theta, dtheta, length, dlength, ddlength):
        """theta'' [rad/rad^2] from the theta-equations (paper Eq. 6a), shape (..., N-1)."""
        return self._accel(nu, theta, dtheta, length, dlength, ddlength)[0]

    def tension(self, nu, theta, dtheta, length, dlength, ddlength):
        """Dimensionless tensions T^ [-] (paper Eq. 6b), shape (..., N-1)."""
        return self._accel(nu, theta, dtheta, length, dlength, ddlength)[1]

    def accelerations(self, nu, theta, dtheta, length, dlength, ddlength):
        """(theta'', T^) in one evaluation."""
        return self._accel(nu, theta, dtheta, length, dlength, ddlength)

    def control_affine(self, nu, theta, dtheta, length):
        """Exact split theta'' = f + B l' + D l'' (docs/model.md#control-affine-form).

        Returns
        -------
        f : ndarray, shape (..., N-1)
        B : ndarray, shape (..., N-1, N-1)
            Response of theta'' to the reel rates l'; a full matrix in general.
        D : ndarray, shape (..., N-1, N-1)
            Response to the reel accelerations l''; zero when all tethers are aligned.
        """
        n = self.n_tethers
        lead, nu_f, (th, dth, ln) = self._broadcast(nu, theta, dtheta, length)
        f = np.empty_like(th)
        B = np.empty(th.shape + (n,))
        D = np.empty(th.shape + (n,))
        kernels.affine_rows(nu_f, _rows(th, dth, ln, np.zeros_like(th)), self.par, f, B, D,
                            kernels.make_scratch(n), np.empty((n, 1 + 2 * n)))
        return (f.reshape(lead + (n,)), B.reshape(lead + (n, n)), D.reshape(lead + (n, n)))


def _rows(theta, dtheta, length, dlength) -> np.ndarray:
    """State rows (B, 4n) in the STATE layout from its fields (B, n) each."""
    n = theta.shape[1]
    y = np.empty((theta.shape[0], STATE.size(n)))
    for name, value in zip(STATE.names, (theta, dtheta, length, dlength), strict=True):
        y[:, STATE.slices(n)[name]] = value
    return y


class Transition(NamedTuple):
    """Result of :func:`transition` (leading axes as the inputs')."""

    nu: np.ndarray
    """True anomaly at the end of the step [rad]."""
    state: np.ndarray
    """State rows at the end of the step (STATE layout)."""
    tension_min: np.ndarray
    """Smallest T^_i [-] over the RK4 substep boundaries (both ends included)."""
    tension: np.ndarray
    """T^_i [-] at the end of the step."""
    derivative: np.ndarray
    """dy/dnu at the end of the step under the held command (holds theta'' and l'')."""


def transition(nu, state, command, params, h: float, substeps: int = 1,
               disturbance=None) -> Transition:
    """Advance chains with their reels by ``substeps`` RK4 steps of ``h`` in true anomaly.

    The reels follow the held command (first-order lag, acceleration and speed
    limits, :func:`tether_gym.physics.kernels._reel`) inside every RK4 stage, and
    the disturbance is added to theta'' (paper Eq. 20). This is the same compiled
    step the environments take.

    Parameters
    ----------
    nu : float or ndarray, shape (B,)
        True anomaly at the start [rad].
    state : ndarray, shape (4n,) or (B, 4n)
        State rows ``[theta, theta', l, l']`` (:data:`~tether_gym.physics.state.STATE`).
    command : ndarray, shape (n,) or (B, n)
        Commanded reel rates l'_cmd [-], held over the step.
    params : TetherChain or ndarray, shape (P,) or (B, P)
        A chain (no reel limits) or parameter rows from :meth:`TetherChain.param_row`
        or :class:`tether_gym.params.Scales`.
    h : float
        RK4 step in true anomaly [rad], >= 0 (the env's ``physics_step``).
    substeps : int
        Number of RK4 steps (the env takes control_step / physics_step of them per
        step), >= 0; 0 evaluates the derivative and tension at the start only.
    disturbance : ndarray, shape (n,) or (B, n), optional
        d added to theta'' [rad/rad^2] (zero by default).

    Returns
    -------
    Transition
    """
    par = params.par if isinstance(params, TetherChain) else np.asarray(params, dtype=float)
    y = np.array(state, dtype=float, ndmin=2, copy=True)
    batch, m = y.shape
    if m % 4:
        raise ValueError(f"state must have 4n entries per row, got shape {np.shape(state)}")
    n = m // 4
    par = np.ascontiguousarray(par.reshape(-1, par.shape[-1]))
    if par.shape[1] != PARAMS.size(n) or par.shape[0] not in (1, batch):
        raise ValueError(f"params of shape {par.shape} do not fit {batch} states of {n} "
                         f"tethers (need (1 or {batch}, {PARAMS.size(n)}))")
    nu_a = np.array(np.broadcast_to(np.asarray(nu, dtype=float), (batch,)))
    cmd = np.ascontiguousarray(np.broadcast_to(np.asarray(command, dtype=float), (batch, n)))
    dist = (np.zeros((batch, n)) if disturbance is None else
            np.ascontiguousarray(np.broadcast_to(np.asarray(disturbance, dtype=float),
                                                 (batch, n))))
    for name, value in (("nu", nu_a), ("state", y), ("command", cmd), ("disturbance", dist)):
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{name}={value!r} must be finite (no NaN or inf)")
    check_range("h", h, 0.0)
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 0:
        raise ValueError(f"substeps={substeps!r} must be an int >= 0")
    out = kernels.StepOutputs(np.empty((batch, n)), np.empty((batch, m)), np.empty((batch, n)))
    kernels.transition_rows(nu_a, y, kernels.StepInputs(cmd, dist), par,
                            kernels.Substeps(float(h), int(substeps)), out, kernels.make_scratch(n))
    single = np.ndim(state) == 1
    pick = (lambda a: a[0]) if single else (lambda a: a)
    return Transition(pick(nu_a), pick(y), pick(out.tension_min), pick(out.tension),
                      pick(out.derivative))
