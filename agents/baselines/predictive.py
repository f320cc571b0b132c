"""A one-step predictive reel law: the nominal step itself decides the held command.

For each tether the sliding variable of the paper's controller (Eq. 12),

    s_j = e_j' + c e_j,    e_j = theta_j - theta_d  [rad],

should fall from one control step to the next as

    s_j(k + 1) = s_j(k) - clip((1 - exp(-lam dt)) s_j(k), -K dt, K dt),        (*)

where s_j(k + 1) is *predicted* by the nominal model's own step,
:func:`tether_gym.physics.transition` (RK4 with the reels in the loop, exactly as the env
steps: :class:`~.prediction.NominalStep`): exp(-lam dt) s_j(k) near the surface (|s|
<= K dt / (1 - exp(-lam dt)), 0.03 by default), a fall of at most K per radian farther
out. (*) is n equations in the n held commands u (normalised, |u| <= 1); two Newton
iterations with a forward-difference Jacobian (n + 1 transitions per iteration) solve
them, started from the command under which the reels do not accelerate (there the
step's response to the command is informative: a command farther than about a_max tau /
(L0 n^2 k^4) from it saturates the reel and the response is flat). A reel saturated
over the whole step keeps its command and the others solve their own tethers'
equations; a solution beyond the box is clipped to it.

Unlike the sliding-mode law (Eqs. 16-17) there is no boundary layer and no inverted
continuous-time model: on the nominal model the law is exact over a step, so near the
surface the error falls to the precision of the float32 observation. The bound K is
what the reels can deliver: a reel limited to a_max changes l' by about 0.02 per control
step at the default limits, while exp(-10 dt) asks a transient with s ~ 0.2 for a change
of l' of order 0.5 in one step; with K = inf the law saturated the reels step after
step, ignored the reel rate it had built up and fell into a limit cycle (the paper's
case never converged, last-orbit error 0.65 rad in 5 of 5 seeds, and 2 of 5 random
starts failed), with K = 0.25 the 10 episodes tried survived at the float32 floor. The
command goes through the project's safety filter
(:class:`tether_gym.safety.SafetyFilter`, built beside it by
:func:`tether_gym_agents.evaluation.nominal.nominal_predictive`).
"""

from __future__ import annotations

import numpy as np

from tether_gym.params import check_range

from ..common.obs import ObservationLayout, ReelRatePolicy
from .prediction import NominalStep, OnNominalStep, decay, reference_ahead

__all__ = ["OneStepPredictive"]


class OneStepPredictive(OnNominalStep, ReelRatePolicy):
    """The held reel-rate command that makes the predicted s decay by exp(-lam dt).

    Parameters
    ----------
    step : NominalStep
        The nominal model's control step (its e, masses, reel limits, steps).
    layout : ObservationLayout
        How to read the env's observation (rate mode).
    c : float
        Slope of the sliding surface s = e' + c e [1/rad], > 0 (default 2).
    lam : float
        Decay rate of s per radian of true anomaly [1/rad], > 0 (default 10).
    k : float
        Largest fall of |s| per radian of true anomaly [rad/rad^2], > 0 (default 0.25;
        inf for the pure exponential target).
    iterations : int
        Newton iterations per control step, >= 1 (default 2).
    fd_step : float
        Forward-difference step of the Jacobian in the normalised command [-], > 0.
    """

    batch_invariant = True
    """Each row is solved on its own (row-wise compiled step, per-row least squares)."""

    def __init__(self, step: NominalStep, layout: ObservationLayout, c: float = 2.0,
                 lam: float = 10.0, k: float = 0.25, iterations: int = 2,
                 fd_step: float = 1e-6):
        if step.n_tethers != layout.n_tethers:
            raise ValueError(f"model has {step.n_tethers} tethers, the env {layout.n_tethers}")
        layout.require_rate_mode(type(self).__name__)
        self.step = step
        self.layout = layout
        self.c = check_range("c", c, 0.0, low_open=True)
        self.lam = check_range("lam", lam, 0.0, low_open=True)
        self.k = check_range("k", k, 0.0, low_open=True)
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
            raise ValueError(f"iterations={iterations!r} must be an int >= 1")
        self.iterations = iterations
        self.fd_step = check_range("fd_step", fd_step, 0.0, 0.1, low_open=True)

    def sliding_variable(self, obs: np.ndarray) -> np.ndarray:
        """s = e' + c e [rad/rad] per tether for observations (B, obs_dim) -> (B, n)."""
        st = self.layout.split(np.asarray(obs, dtype=np.float64))
        return (st.dtheta - st.dtheta_ref[:, None]
                + self.c * (st.theta - st.theta_ref[:, None]))

    def _residual(self, nu, y, u, target, ref):
        """Predicted s(k+1) - target for commands u (R, n) at states (R, 4n)."""
        n = self.step.n_tethers
        nxt = self.step(nu, y, u).state
        err = nxt[:, :n] - ref[0][:, None]
        derr = nxt[:, n:2 * n] - ref[1][:, None]
        return derr + self.c * err - target

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:
        """Commanded l' [-] (B, n) for observations (B, obs_dim)."""
        lay = self.layout
        n = lay.n_tethers
        st = lay.split(obs)
        nu, y = lay.state(obs)
        dt = self.step.control_step
        ref = reference_ahead(st.theta_ref, st.dtheta_ref, lay.frequency, dt)
        s0 = self.sliding_variable(obs)
        drop = np.clip((1.0 - decay(self.lam, dt)) * s0, -self.k * dt, self.k * dt)
        target = s0 - drop
        u = self.step.neutral_command(nu, y)
        b = u.shape[0]
        eye = self.fd_step * np.eye(n)
        for _ in range(self.iterations):
            cand = np.concatenate([u[:, None, :], u[:, None, :] + eye[None]], axis=1)
            res = self._residual(np.repeat(nu, n + 1), np.repeat(y, n + 1, axis=0),
                                 cand.reshape(b * (n + 1), n),
                                 np.repeat(target, n + 1, axis=0),
                                 tuple(np.repeat(r, n + 1) for r in ref)).reshape(b, n + 1, n)
            f0 = res[:, 0]
            jac = (res[:, 1:] - f0[:, None, :]).transpose(0, 2, 1) / self.fd_step
            for r in range(b):
                u[r] = _newton_step(u[r], jac[r], f0[r])
        return u * self.step.max_reel_rate

    def __repr__(self) -> str:
        return (f"OneStepPredictive(c={self.c}, lam={self.lam}, k={self.k}, "
                f"iterations={self.iterations})")


SATURATED = 1e-3
"""A command whose column of the Jacobian is below this fraction of the largest one moves
a saturated reel (the response to it is flat)."""


def _newton_step(u: np.ndarray, jac: np.ndarray, f0: np.ndarray) -> np.ndarray:
    """u + du clipped to [-1, 1], du solving the equations of the unsaturated reels.

    A reel saturated over the whole step does not respond to its command (its column of
    ``jac`` is flat): its command is kept and the other reels solve their own equations
    (rows of the same tethers), instead of a least-squares compromise that would let
    one reel chase another tether's sliding variable.
    """
    if not (np.all(np.isfinite(jac)) and np.all(np.isfinite(f0))):
        return u
    norms = np.abs(jac).max(axis=0)
    free = norms > SATURATED * max(norms.max(), 1e-300)
    if not free.any():
        return u
    du = np.zeros_like(u)
    sub = jac[np.ix_(free, free)]
    du[free] = np.linalg.lstsq(sub, -f0[free], rcond=None)[0]
    return np.clip(u + du, -1.0, 1.0)
