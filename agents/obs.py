"""Reading a TetherLibration observation and scaling reel rates to actions."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

__all__ = ["ObservationLayout", "ObservedState"]


class ObservedState(NamedTuple):
    """The observation's fields, each with a leading batch axis."""

    sin_nu: np.ndarray
    cos_nu: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    length: np.ndarray
    dlength: np.ndarray
    theta_ref: np.ndarray
    dtheta_ref: np.ndarray
    eccentricity: np.ndarray | None
    masses: np.ndarray | None


@dataclass(frozen=True)
class ObservationLayout:
    """Observation layout and action scaling of one env configuration.

    Parameters
    ----------
    n_tethers : int
        N - 1.
    frequency : float
        w of the reference theta_d = A sin(w nu) [-].
    max_reel_rate : float
        l'_cmd at |action| = 1 [-].
    with_params : bool
        Whether e and the mass fractions close the observation.
    """

    n_tethers: int
    frequency: float
    max_reel_rate: float
    with_params: bool = False

    @classmethod
    def from_env(cls, env) -> ObservationLayout:
        cfg = env.unwrapped.config if hasattr(env, "unwrapped") else env.config
        return cls(cfg.n_tethers, cfg.frequency, cfg.max_reel_rate, cfg.randomised)

    def split(self, obs: np.ndarray) -> ObservedState:
        n = self.n_tethers
        obs = np.asarray(obs, dtype=np.float64)
        expected = 4 * n + 4 + ((1 + n) if self.with_params else 0)
        if obs.ndim != 2 or obs.shape[1] != expected:
            raise ValueError(f"observation batch must have shape (B, {expected}), got {obs.shape}")
        m = 4 * n
        return ObservedState(
            obs[:, 0], obs[:, 1], obs[:, 2:2 + n], obs[:, 2 + n:2 + 2 * n],
            obs[:, 2 + 2 * n:2 + 3 * n], obs[:, 2 + 3 * n:2 + m], obs[:, 2 + m],
            obs[:, 3 + m],
            obs[:, 4 + m] if self.with_params else None,
            obs[:, 5 + m:5 + m + n] if self.with_params else None,
        )

    def to_action(self, reel_rate: np.ndarray) -> np.ndarray:
        """Commanded l' [-] -> action in [-1, 1] (float32), clipped."""
        return np.clip(np.asarray(reel_rate) / self.max_reel_rate, -1.0, 1.0).astype(np.float32)
