"""The paper's sliding-mode controller (Eqs. 12-17, as corrected in docs/model.md).

    s = C (theta - theta_d) + (theta' - theta_d')                                (12)
    u = l' = -B^-1 [f + C (theta' - theta_d') - theta_d''] - B^-1 K sat(s / eps)  (16-17)

with theta'' = f + B l' + D l'' from ``TetherChain.control_affine`` (the D l'' term is
left out of the inverted model: with the previous step's l'' in it the loop went slack
at 0.42 orbit at the paper's step, and made no visible difference at the env's default
step, docs/model.md#sliding-mode-controller-eqs-12-19), theta_d'' = -w^2 theta_d, and
sat(x) = x for |x| < 1, sign(x) otherwise. The controller reads everything from the
observation, so it runs through the same ``predict`` interface as any trained agent.
"""

from __future__ import annotations

import numpy as np

from tether_gym.params import check_range
from tether_gym.physics import TetherChain

from ..common.obs import ObservationLayout, ReelRatePolicy

__all__ = ["SlidingModeController"]


class SlidingModeController(ReelRatePolicy):
    """Sliding-mode reel-rate law of Shi, Zhu & Zhu (2019), Sec. 4.1.

    Parameters
    ----------
    model : TetherChain
        Model the law inverts (its e and masses are the *nominal* ones).
    layout : ObservationLayout
        How to read the env's observation and scale the action.
    c, k, eps : float
        Sliding-surface slope C = c I [1/rad], switching gain K = k I [rad/rad^2] and
        boundary-layer width eps [rad/rad], all > 0 (paper: 1, 1, 0.1).
    use_observed_params : bool
        When the observation carries e and the masses (domain randomisation), design
        on them instead of ``model`` (default True).
    """

    batch_invariant = True
    """Each row's action is bitwise the same in any batch (row-wise NumPy and a batched
    LAPACK solve per row), so rollouts batch the episodes that share the law."""

    def __init__(self, model: TetherChain, layout: ObservationLayout, c: float = 1.0,
                 k: float = 1.0, eps: float = 0.1, use_observed_params: bool = True):
        if not isinstance(model, TetherChain):
            raise TypeError(f"model must be a TetherChain, got {type(model).__name__}")
        if model.n_tethers != layout.n_tethers:
            raise ValueError(f"model has {model.n_tethers} tethers, the env {layout.n_tethers}")
        layout.require_rate_mode(type(self).__name__)
        self.model = model
        self.layout = layout
        self.c = check_range("c", c, 0.0, low_open=True)
        self.k = check_range("k", k, 0.0, low_open=True)
        self.eps = check_range("eps", eps, 0.0, low_open=True)
        self.use_observed_params = bool(use_observed_params)

    @classmethod
    def for_env(cls, env, c: float = 1.0, k: float = 1.0, eps: float = 0.1,
                nominal: TetherChain | None = None, **kwargs) -> SlidingModeController:
        """Build for a TetherLibration env (wrapped or not).

        ``nominal`` replaces the env's own model (its configured e and masses) for
        model-mismatch studies.
        """
        base = env.unwrapped if hasattr(env, "unwrapped") else env
        if not hasattr(base, "config") or not hasattr(base, "model"):
            raise TypeError(f"env must be a TetherLibration env (gym.make("
                            f"'tether_gym/TetherLibration-v1') or its vector env), got "
                            f"{type(env).__name__}")
        layout = ObservationLayout.from_env(base)
        model = nominal if nominal is not None else base.model
        return cls(model, layout, c=c, k=k, eps=eps, **kwargs)

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:
        """u = l' [-] for a batch of observations (B, obs_dim) -> (B, n)."""
        lay = self.layout
        st = lay.split(obs)
        nu = np.arctan2(st.sin_nu, st.cos_nu)
        ddref = -lay.frequency**2 * st.theta_ref
        derr = st.dtheta - st.dtheta_ref[:, None]
        sat = np.clip(self._surface(st) / self.eps, -1.0, 1.0)
        f, B = self._affine(nu, st)
        rhs = f + self.c * derr - ddref[:, None] + self.k * sat
        return -np.linalg.solve(B, rhs[..., None])[..., 0]

    def sliding_variable(self, obs: np.ndarray) -> np.ndarray:
        """s of Eq. 12 [rad/rad] for a batch of observations (B, obs_dim) -> (B, N-1)."""
        return self._surface(self.layout.split(obs))

    def _surface(self, st) -> np.ndarray:
        err = st.theta - st.theta_ref[:, None]
        derr = st.dtheta - st.dtheta_ref[:, None]
        return self.c * err + derr

    def _affine(self, nu, st):
        if self.use_observed_params and st.eccentricity is not None:
            f = np.empty_like(st.theta)
            B = np.empty(st.theta.shape + (st.theta.shape[1],))
            for b in range(nu.shape[0]):
                masses = (self.model.mass_fractions if st.mass_fractions is None
                          else st.mass_fractions[b])
                chain = TetherChain(masses, float(st.eccentricity[b]),
                                    self.model.gravity, self.model.length_ratio)
                f[b], B[b], _ = chain.control_affine(nu[b], st.theta[b], st.dtheta[b],
                                                     st.length[b])
            return f, B
        f, B, _ = self.model.control_affine(nu, st.theta, st.dtheta, st.length)
        return f, B

    def __repr__(self) -> str:
        return (f"SlidingModeController(c={self.c}, k={self.k}, eps={self.eps}, "
                f"model={self.model!r})")

