"""Reading a TetherLibration observation and scaling reel rates to actions."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from tether_gym.envs.layout import OBSERVATION

__all__ = ["ObservationLayout", "ObservedState", "ReelRatePolicy"]


class ObservedState(NamedTuple):
    """The observation's fields (:data:`tether_gym.envs.layout.OBSERVATION`).

    Each has a leading batch axis: scalars are (B,), per-tether fields (B, n), absent
    optional fields None.
    """

    sin_nu: np.ndarray
    cos_nu: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    length: np.ndarray
    dlength: np.ndarray
    theta_ref: np.ndarray
    dtheta_ref: np.ndarray
    error: np.ndarray
    derror: np.ndarray
    log_length: np.ndarray
    command: np.ndarray
    eccentricity: np.ndarray | None
    mass_fractions: np.ndarray | None


assert ObservedState._fields == OBSERVATION.names, "ObservedState must follow OBSERVATION"


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
        l'_cmd at |u| = 1 [-].
    with_params : bool
        Whether e and the mass fractions close the observation.
    with_eccentricity : bool
        Whether e closes the observation (implied by ``with_params``; alone with
        ``observe_params="eccentricity"``).
    action_mode : str
        The env's ``action_mode``: ``"rate"`` (the action is the command u) or
        ``"increment"`` (the action changes u).
    """

    n_tethers: int
    frequency: float
    max_reel_rate: float
    with_params: bool = False
    action_mode: str = "rate"
    with_eccentricity: bool = False

    @classmethod
    def from_env(cls, env) -> ObservationLayout:
        """The layout of a TetherLibration env (wrapped or not)."""
        cfg = env.unwrapped.config if hasattr(env, "unwrapped") else env.config
        observed = cfg.observed
        return cls(cfg.n_tethers, cfg.frequency, cfg.max_reel_rate, observed["masses"],
                   cfg.action_mode, observed["eccentricity"])

    @property
    def switches(self) -> dict[str, bool]:
        """The optional groups of OBSERVATION that are on."""
        return {"eccentricity": self.with_params or self.with_eccentricity,
                "masses": self.with_params}

    def require_rate_mode(self, who: str) -> None:
        """Raise ValueError unless the env takes reel-rate commands as actions."""
        if self.action_mode != "rate":
            raise ValueError(f"{who} commands reel rates: make the env with "
                             f"action_mode='rate' (it has action_mode={self.action_mode!r})")

    @property
    def obs_dim(self) -> int:
        """Length of one observation (OBSERVATION's size for this n and switch)."""
        return OBSERVATION.size(self.n_tethers, **self.switches)

    def as_batch(self, observation) -> tuple[np.ndarray, bool]:
        """(obs as a float64 (B, obs_dim) batch, whether a single observation was given).

        Raises ValueError naming the shape when it is neither (obs_dim,) nor (B, obs_dim).
        """
        obs = np.asarray(observation, dtype=np.float64)
        dim = self.obs_dim
        if obs.ndim == 1 and obs.shape[0] == dim:
            return obs[None], True
        if obs.ndim == 2 and obs.shape[1] == dim:
            return obs, False
        raise ValueError(f"observation must have shape ({dim},) or (B, {dim}) for this env "
                         f"(N-1 = {self.n_tethers} tethers), got {obs.shape}")

    def split(self, obs: np.ndarray) -> ObservedState:
        """The fields of a (B, obs_dim) batch of observations (views)."""
        obs = np.asarray(obs, dtype=np.float64)
        expected = self.obs_dim
        if obs.ndim != 2 or obs.shape[1] != expected:
            raise ValueError(f"observation batch must have shape (B, {expected}), got {obs.shape}")
        slices = OBSERVATION.slices(self.n_tethers, **self.switches)
        values: dict[str, Any] = {}
        for f in OBSERVATION:
            sl = slices.get(f.name)
            values[f.name] = (None if sl is None else
                              obs[:, sl] if f.per_tether else obs[:, sl.start])
        return ObservedState(**values)

    def to_action(self, reel_rate: np.ndarray) -> np.ndarray:
        """Commanded l' [-] -> action in [-1, 1] (float32), clipped (``action_mode="rate"``)."""
        return np.clip(np.asarray(reel_rate) / self.max_reel_rate, -1.0, 1.0).astype(np.float32)

    def to_reel_rate(self, command: np.ndarray) -> np.ndarray:
        """Normalised command u -> commanded l' [-] (float64), as the env applies it.

        Clipped to [-1, 1] and scaled by ``max_reel_rate`` (the inverse of
        :meth:`to_action` inside the box). In ``action_mode="rate"`` u is the action.
        """
        return np.clip(np.asarray(command, dtype=np.float64), -1.0, 1.0) * self.max_reel_rate


class ReelRatePolicy:
    """Base of the model-based baselines: a reel-rate law behind SB3's ``predict``.

    Subclasses set ``self.layout`` and implement :meth:`reel_rate`, mapping a batch of
    observations (B, obs_dim) to commanded reel rates l' (B, N-1) [-]; :meth:`predict`
    scales them to the env's action box with :meth:`ObservationLayout.to_action`. They
    run on envs made with ``action_mode="rate"`` (:data:`ENV_KWARGS`), where the
    action is the command.
    """

    layout: ObservationLayout
    ENV_KWARGS = {"action_mode": "rate"}
    """Env arguments these policies need."""

    def reel_rate(self, obs: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        """Commanded reel rates l' (B, N-1) [-] for observations (B, obs_dim)."""
        raise NotImplementedError

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """stable-baselines3 policy interface: (action, None) for one or a batch of obs.

        The laws are deterministic; ``state``, ``episode_start`` and ``deterministic``
        are accepted for compatibility and ignored.
        """
        batch, single = self.layout.as_batch(observation)
        action = self.layout.to_action(self.reel_rate(batch))
        return (action[0] if single else action), None
