"""The paper's open-loop reel laws, and a random baseline, as SB3-style policies.

* :class:`ZeroStateReel` -- Eq. 7, l_i' = l_i e sin(nu) / k, which keeps an aligned
  chain at theta = theta' = 0 (Sec. 3.1).
* :class:`PeriodicReel` -- Eq. 10 (as corrected in docs/model.md), which makes the aligned libration
  theta = A sin(w nu) a solution (Sec. 3.2).
* :class:`RandomPolicy` -- uniform actions, the floor of the benchmark.

The laws themselves are :func:`tether_gym.tasks.reference.zero_state_reel_rate` and
:func:`~tether_gym.tasks.reference.periodic_reel_rate`; this module only reads the
observation, evaluates them and scales the result to the action box. Both laws are
*relative* rates (l_i' proportional to l_i): they are evaluated with the measured
lengths, so the ratio l_i'/l_i that drives the libration is exactly the law's whatever
length the reels have reached. The command is held over one control step (zero-order
hold) and the reel follows it with its lag, so a trajectory through the env tracks the
exact law with an error of order (control_step / 2 + reel_time_constant) d(l'/l)/dnu
(tests/agents/test_open_loop.py derives the resulting bound on theta).
"""

from __future__ import annotations

import math
from enum import Enum

import numpy as np

from tether_gym.params import check_range
from tether_gym.tasks.reference import (
    desired_libration,
    periodic_reel_rate,
    zero_state_reel_rate,
)

from ..common.obs import RATE_ENV_KWARGS, ObservationLayout, ReelRatePolicy

__all__ = ["AngleSource", "ZeroStateReel", "PeriodicReel", "RandomPolicy"]


def _base(env):
    return env.unwrapped if hasattr(env, "unwrapped") else env


def _true_anomaly(st) -> np.ndarray:
    """nu [rad] in (-pi, pi] from the observation's (sin nu, cos nu), shape (B,)."""
    return np.arctan2(st.sin_nu, st.cos_nu)


class AngleSource(Enum):
    """Where Eq. 10 takes theta and theta' from.

    ``REFERENCE``: theta_d = A sin(w nu) and theta_d' (the open-loop law of the paper,
    a function of nu and the lengths only). ``MEASURED``: each tether's own measured
    theta_i, theta_i' (a feedback variant: it imposes theta_i'' = theta_d'' on an
    aligned chain but leaves any error in theta and theta' uncorrected).
    """

    REFERENCE = "reference"
    MEASURED = "measured"


class ZeroStateReel(ReelRatePolicy):
    """Paper Eq. 7: l_i' = l_i e sin(nu) / (1 + e cos(nu)) (zero state, Sec. 3.1).

    Parameters
    ----------
    eccentricity : float
        e [-] in [0, 1) of the orbit the law is designed for.
    layout : ObservationLayout
        How to read the env's observation and scale the action.
    use_observed_params : bool
        When the observation carries e (domain randomisation), use it instead of
        ``eccentricity`` (default True).
    """

    def __init__(self, eccentricity: float, layout: ObservationLayout,
                 use_observed_params: bool = True):
        if not isinstance(layout, ObservationLayout):
            raise TypeError(f"layout must be an ObservationLayout, got {type(layout).__name__}")
        self.eccentricity = check_range("eccentricity", eccentricity, 0.0, 1.0, high_open=True)
        layout.require_rate_mode(type(self).__name__)
        self.layout = layout
        self.use_observed_params = bool(use_observed_params)

    @classmethod
    def for_env(cls, env, eccentricity: float | None = None, **kwargs) -> ZeroStateReel:
        """Build for a TetherLibration env (wrapped or not); e defaults to the env's."""
        base = _base(env)
        e = base.config.eccentricity if eccentricity is None else eccentricity
        return cls(e, ObservationLayout.from_env(base), **kwargs)

    def _ecc(self, st) -> np.ndarray | float:
        if self.use_observed_params and st.eccentricity is not None:
            return st.eccentricity[:, None]
        return self.eccentricity

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:
        """l' [-] of Eq. 7 for a batch of observations (B, obs_dim) -> (B, N-1)."""
        st = self.layout.split(obs)
        nu = _true_anomaly(st)[:, None]
        return zero_state_reel_rate(nu, st.length, self._ecc(st))

    def __repr__(self) -> str:
        return f"ZeroStateReel(eccentricity={self.eccentricity})"


class PeriodicReel(ReelRatePolicy):
    """Paper Eq. 10 (as corrected in docs/model.md) for the aligned libration theta = A sin(w nu).

        l_i' = l_i [4 e sin(nu)(1 + theta') + 2 A k w^2 sin(w nu) - 3 sin(2 theta)]
               / (4 k (1 + theta'))

    l_i are the measured lengths. theta and theta' are the reference's,
    theta_d = A sin(w nu) and theta_d' = A w cos(w nu), by default: that is the
    paper's open-loop law (Sec. 4.1 calls Eq. 10 "an open-loop control"), a function
    of nu and the lengths only, and the reference is then an exact solution of the
    aligned chain. ``angles=AngleSource.MEASURED`` evaluates it on each tether's
    measured theta_i, theta_i' instead (see :class:`AngleSource`).

    Parameters
    ----------
    eccentricity : float
        e [-] in [0, 1).
    amplitude : float
        A [rad] in [0, 1) (|A w| < 1 keeps 1 + theta_d' > 0).
    frequency : float
        w [-], a whole number >= 0: the law is evaluated at nu recovered from
        (sin nu, cos nu), which determines sin(w nu) only for integer w.
    layout : ObservationLayout
    angles : AngleSource
        Where theta, theta' come from (default ``REFERENCE``).
    use_observed_params : bool
        Use the observed e under domain randomisation (default True).
    """

    def __init__(self, eccentricity: float, amplitude: float, layout: ObservationLayout,
                 frequency: float = 1.0, angles: AngleSource = AngleSource.REFERENCE,
                 use_observed_params: bool = True):
        if not isinstance(layout, ObservationLayout):
            raise TypeError(f"layout must be an ObservationLayout, got {type(layout).__name__}")
        self.eccentricity = check_range("eccentricity", eccentricity, 0.0, 1.0, high_open=True)
        self.amplitude = check_range("amplitude", amplitude, 0.0, 1.0, high_open=True)
        self.frequency = check_range("frequency", frequency, 0.0)
        if self.frequency != math.floor(self.frequency):
            raise ValueError(f"frequency={frequency!r} must be a whole number: the policy "
                             "sees nu only through (sin nu, cos nu), which fixes sin(w nu) "
                             "only for integer w")
        if self.amplitude * self.frequency >= 1.0:
            raise ValueError(f"amplitude * frequency = {self.amplitude * self.frequency!r} "
                             "must be < 1 (Eq. 10 divides by 1 + theta_d')")
        if not isinstance(angles, AngleSource):
            raise TypeError(f"angles must be an AngleSource, got {angles!r}; valid: "
                            f"{[a.name for a in AngleSource]}")
        layout.require_rate_mode(type(self).__name__)
        self.layout = layout
        self.angles = angles
        self.use_observed_params = bool(use_observed_params)

    @classmethod
    def for_env(cls, env, amplitude: float | None = None, eccentricity: float | None = None,
                **kwargs) -> PeriodicReel:
        """Build for a TetherLibration env; A, w and e default to the env's."""
        base = _base(env)
        cfg = base.config
        return cls(cfg.eccentricity if eccentricity is None else eccentricity,
                   cfg.amplitude if amplitude is None else amplitude,
                   ObservationLayout.from_env(base),
                   frequency=kwargs.pop("frequency", cfg.frequency), **kwargs)

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:
        """l' [-] of Eq. 10 for a batch of observations (B, obs_dim) -> (B, N-1)."""
        st = self.layout.split(obs)
        nu = _true_anomaly(st)[:, None]
        e = (st.eccentricity[:, None]
             if self.use_observed_params and st.eccentricity is not None else self.eccentricity)
        if self.angles is AngleSource.REFERENCE:
            theta, dtheta, _ = desired_libration(nu, self.amplitude, self.frequency)
        else:
            theta, dtheta = st.theta, st.dtheta
        return periodic_reel_rate(nu, theta, dtheta, st.length, e, self.amplitude,
                                  self.frequency)

    def __repr__(self) -> str:
        return (f"PeriodicReel(eccentricity={self.eccentricity}, amplitude={self.amplitude}, "
                f"frequency={self.frequency}, angles={self.angles.value!r})")


class RandomPolicy:
    """Actions drawn uniformly from the env's action box (the benchmark's floor).

    Parameters
    ----------
    env : gymnasium.Env
        A TetherLibration env (wrapped or not); gives the action box and the
        observation layout.
    seed : int or None
        Seed of the policy's own generator (independent of the env's).
    """

    ENV_KWARGS = RATE_ENV_KWARGS
    """Env arguments of the benchmark's random baseline (uniform reel-rate commands)."""

    def __init__(self, env, seed: int | None = None):
        base = _base(env)
        self.layout = ObservationLayout.from_env(base)
        space = base.action_space
        self.low = np.asarray(space.low, dtype=np.float64)
        self.high = np.asarray(space.high, dtype=np.float64)
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    @classmethod
    def for_env(cls, env, seed: int | None = None) -> RandomPolicy:
        """Build for a TetherLibration env (wrapped or not), seeded."""
        return cls(env, seed)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """(action, None): one uniform draw per observation (single or batch)."""
        batch, single = self.layout.as_batch(observation)
        size = (batch.shape[0],) + self.low.shape
        action = self.rng.uniform(self.low, self.high, size).astype(np.float32)
        return (action[0] if single else action), None

    def __repr__(self) -> str:
        return f"RandomPolicy(seed={self.seed})"
