"""What the predictive baselines share: the nominal step they predict with, the reference ahead.

Both ``predictive`` (:mod:`.predictive`) and ``mpc`` (:mod:`.mpc`) predict with the
env's own step, :func:`tether_gym.physics.transition` (RK4 with the reels in the loop,
``control_step / physics_step`` substeps), on the *nominal* model: the env's configured
e and masses, or a scenario's nominal ones (model mismatch), with the env's reel limits
and lag. :class:`NominalStep` holds that setup; :func:`reference_ahead` gives the
reference theta_d = A sin(w nu) (paper Eq. 8) a given true anomaly ahead, from the
observed theta_d and theta_d' alone (no A, no unwrapped nu needed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from tether_gym.envs.config import env_config
from tether_gym.params import Gravity
from tether_gym.physics import PARAMS, STATE, transition

from ..common.obs import ObservationLayout

__all__ = ["NominalStep", "OnNominalStep", "reference_ahead", "decay"]


@dataclass(frozen=True)
class NominalStep:
    """The nominal model's control step, as the env takes it.

    Parameters
    ----------
    params : ndarray, shape (P,)
        Parameter row with the reel limits (``EnvConfig.param_rows``).
    n_tethers : int
        n = N - 1.
    physics_step : float
        RK4 step h [rad].
    substeps : int
        RK4 steps per control step.
    max_reel_rate : float
        l'_cmd [-] at a normalised command u = 1.
    length_bounds : tuple of float
        (l_min, l_max) [-] of the task.
    safe_tension : float
        The reward's T_safe [-].
    full_gravity : bool
        Exact inverse-square gravity (else the gradient model).
    """

    params: np.ndarray
    n_tethers: int
    physics_step: float
    substeps: int
    max_reel_rate: float
    length_bounds: tuple[float, float]
    safe_tension: float
    full_gravity: bool

    @classmethod
    def for_env(cls, env, eccentricity: float | None = None, masses=None,
                reel_time_constant: float | None = None,
                accel_limit: float | None = None) -> NominalStep:
        """The step of a TetherLibration env's model, or of a nominal model in it.

        Each argument left None is the env's own: eccentricity e [-], masses (any common
        unit), reel_time_constant tau [rad], accel_limit [m/s^2] (a scenario's
        ``nominal`` dict, :data:`tether_gym_agents.evaluation.scenarios.NOMINAL_KEYS`).
        """
        cfg = env_config(env)
        par = cfg.nominal_params(eccentricity, masses, reel_time_constant, accel_limit)
        return cls(np.asarray(par, dtype=float).reshape(-1), cfg.n_tethers,
                   float(cfg.physics_step), int(cfg.n_substeps), float(cfg.max_reel_rate),
                   tuple(cfg.length_bounds), float(cfg.reward_weights.safe_tension),
                   Gravity.parse(cfg.gravity) is Gravity.FULL)

    @property
    def accel_bound(self) -> float:
        """The reels' acceleration limit a_max / (L0 n^2) [-] (inf without one)."""
        return float(self.params[PARAMS.slices(self.n_tethers)["accel_bound"]][0])

    @property
    def control_step(self) -> float:
        """True anomaly per control step [rad]."""
        return self.physics_step * self.substeps

    def neutral_command(self, nu, state) -> np.ndarray:
        """Normalised commands (B, n) under which each reel's physical acceleration is zero.

        The reel (:func:`tether_gym.physics.kernels._reel`) demands L_ddot / (L0 n^2) =
        k^4 (l'_cmd - l') / tau - 2 e sin(nu) k^3 l'; it is zero at l'_cmd = l' + tau 2 e
        sin(nu) l' / k. Around this command the reel does not saturate, so the step's
        response to the command is informative there (a Newton start).
        """
        sl = PARAMS.slices(self.n_tethers)
        ecc = self.params[sl["eccentricity"]][0]
        tau = self.params[sl["time_constant"]][0]
        nu = np.asarray(nu, dtype=float)[:, None]
        k = 1.0 + ecc * np.cos(nu)
        rate = np.asarray(state)[:, STATE.slices(self.n_tethers)["dlength"]]
        cmd = rate + tau * 2.0 * ecc * np.sin(nu) * rate / k
        return np.clip(cmd / self.max_reel_rate, -1.0, 1.0)

    def __call__(self, nu, state, command):
        """:func:`~tether_gym.physics.transition` of states (B, 4n) under normalised u (B, n)."""
        return transition(nu, state, np.clip(command, -1.0, 1.0) * self.max_reel_rate,
                          self.params, self.physics_step, self.substeps)


_Law = TypeVar("_Law", bound="OnNominalStep")


class OnNominalStep:
    """A law built as ``cls(step, layout, **kwargs)`` on a :class:`NominalStep`.

    Gives it :meth:`for_env` (the predictive and the model-predictive laws).
    """

    @classmethod
    def for_env(cls: type[_Law], env, nominal: dict | None = None, **kwargs) -> _Law:
        """Build for a TetherLibration env, on its model or on ``nominal``.

        ``nominal`` holds the :class:`NominalStep` arguments that differ from the
        env's (a scenario's ``nominal``: e, masses, reel lag, accel limit).
        """
        return cls(NominalStep.for_env(env, **(nominal or {})),  # type: ignore[call-arg]
                   ObservationLayout.from_env(env), **kwargs)


def reference_ahead(theta_ref, dtheta_ref, frequency: float, delta):
    """(theta_d, theta_d') [rad, rad/rad] at nu + delta from their values at nu.

    With theta_d = A sin(w nu) (paper Eq. 8): theta_d(nu + delta) = theta_d cos(w delta)
    + (theta_d' / w) sin(w delta), theta_d'(nu + delta) = theta_d' cos(w delta) - w
    theta_d sin(w delta) (w = 0: constant). ``theta_ref``, ``dtheta_ref`` broadcast
    against ``delta`` [rad].
    """
    w = float(frequency)
    delta = np.asarray(delta, dtype=float)
    if w == 0.0:
        return (np.asarray(theta_ref, dtype=float) + 0.0 * delta,
                np.asarray(dtheta_ref, dtype=float) + 0.0 * delta)
    c = np.cos(w * delta)
    s = np.sin(w * delta)
    return theta_ref * c + dtheta_ref / w * s, dtheta_ref * c - w * theta_ref * s


def decay(rate: float, step: float) -> float:
    """exp(-rate * step) [-]: the factor a quantity decaying at ``rate`` keeps over a step."""
    return math.exp(-rate * step)
