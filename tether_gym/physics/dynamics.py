"""The public model of the tethered chain: :class:`TetherChain`.

The equations themselves live in :mod:`tether_gym.physics.kernels` (one copy, with
their derivation); this module validates inputs, broadcasts leading axes and calls
them.

Variables (dimensionless, paper Sec. 2): ``nu`` true anomaly [rad]; ``theta`` [rad]
libration angle of each tether from the local vertical (pointing to Earth),
positive when the lower body trails the upper one; ``dtheta`` = d theta / d nu
[rad/rad]; ``length`` l_i = L_i / L0 [-]; ``dlength`` = l_i' [-]; ``ddlength`` = l_i''
[-]. Tensions T^_i = T_i / (nu_dot^2 L0 m_tot) [-].
"""

from __future__ import annotations

import numpy as np

from ..params import Gravity, as_float_tuple, check_range
from . import kernels

__all__ = ["TetherChain"]


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
        masses = as_float_tuple("masses", masses)
        if len(masses) < 1:
            raise ValueError(f"masses={masses!r}: need at least one subsatellite (N >= 2)")
        if min(masses) <= 0.0:
            raise ValueError(f"masses={masses!r} must all be > 0")
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
        total = sum(masses)
        self.mass_fractions = np.array(masses) / total
        """M_i = m_i / m_tot [-]."""
        self.tail_masses = np.cumsum(self.mass_fractions[::-1])[::-1].copy()
        """sum_{i>=j} M_i [-], the mass hanging on tether j."""
        self.par = kernels.pack_params(
            self.eccentricity,
            self.tail_masses,
            kernels.GRAVITY_FULL if self.gravity is Gravity.FULL else kernels.GRAVITY_GRADIENT,
            self.length_ratio or 0.0,
        )[None, :]

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
        if np.any(arrs[2] <= 0.0):
            raise ValueError(f"length={arrs[2]!r} must be > 0")
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
        kernels.accel_batch(nu_f, th, dth, ln, dl, ddl, self.par, ddtheta, tension)
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
        """Exact split theta'' = f + B l' + D l'' (NOTES.md, "Structure").

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
        kernels.affine_batch(nu_f, th, dth, ln, self.par, f, B, D)
        return (f.reshape(lead + (n,)), B.reshape(lead + (n, n)), D.reshape(lead + (n, n)))
