"""Reading a TetherLibration observation, scaling reel rates to actions, the rate mode.

The policies of this package that command reel rates (the baselines, the hybrids)
run on envs made with ``action_mode="rate"``: :data:`RATE_ENV_KWARGS` is that env
argument, :func:`with_rate_mode` adds it to a user's env arguments (or refuses another
mode) and :func:`require_rate_mode` (:mod:`tether_gym.envs.actions`) checks a built
env's mode. :func:`require_predict` checks that an object is a policy (has
stable-baselines3's ``predict``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import KW_ONLY, dataclass
from typing import Any, NamedTuple

import numpy as np

from tether_gym.envs.actions import RATE, require_rate_mode
from tether_gym.envs.config import env_config
from tether_gym.envs.layout import OBSERVATION
from tether_gym.physics import STATE

__all__ = ["ObservationLayout", "ObservedState", "ReelRatePolicy", "RATE_ENV_KWARGS",
           "require_rate_mode", "with_rate_mode", "require_predict"]

RATE_ENV_KWARGS: dict[str, Any] = {"action_mode": RATE}
"""The env arguments of the policies that command reel rates (do not modify: copy)."""


def with_rate_mode(env_kwargs: Mapping[str, Any], who: str) -> dict[str, Any]:
    """``env_kwargs`` with ``action_mode="rate"`` (a new dict).

    Raises
    ------
    ValueError
        If ``env_kwargs`` gives another ``action_mode``; the message names ``who`` (what
        needs reel-rate actions) and the mode given.
    """
    mode = env_kwargs.get("action_mode", RATE)
    require_rate_mode(mode, who)
    return {**env_kwargs, **RATE_ENV_KWARGS}


def require_predict(name: str, policy: Any) -> Any:
    """``policy`` after checking it has a ``predict`` method (TypeError naming ``name``)."""
    if not callable(getattr(policy, "predict", None)):
        raise TypeError(f"{name} must have a predict method, got {type(policy).__name__}")
    return policy


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
        Whether e and the mass fractions close the observation (keyword only).
    with_eccentricity : bool
        Whether e closes the observation (implied by ``with_params``; alone with
        ``observe_params="eccentricity"``; keyword only).
    action_mode : str
        The env's ``action_mode``: ``"rate"`` (the action is the command u) or
        ``"increment"`` (the action changes u; keyword only).
    """

    n_tethers: int
    frequency: float
    max_reel_rate: float
    _: KW_ONLY
    with_params: bool = False
    with_eccentricity: bool = False
    action_mode: str = RATE

    @classmethod
    def from_env(cls, env) -> ObservationLayout:
        """The layout of a TetherLibration env (wrapped or not, or its vector env)."""
        cfg = env_config(env)
        observed = cfg.observed
        return cls(n_tethers=cfg.n_tethers, frequency=cfg.frequency,
                   max_reel_rate=cfg.max_reel_rate, with_params=observed["masses"],
                   with_eccentricity=observed["eccentricity"], action_mode=cfg.action_mode)

    @property
    def switches(self) -> dict[str, bool]:
        """The optional groups of OBSERVATION that are on."""
        return {"eccentricity": self.with_params or self.with_eccentricity,
                "masses": self.with_params}

    def require_rate_mode(self, who: str) -> None:
        """Raise ValueError unless the env takes reel-rate commands as actions.

        :func:`tether_gym.envs.actions.require_rate_mode` of this env's mode.
        """
        require_rate_mode(self.action_mode, who)

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

    def state(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(nu (B,) [rad], state rows (B, 4n) in the STATE layout) of a (B, obs_dim) batch.

        The state as the observation shows it (float32, and noisy under ``obs_noise``):
        the input of a safety filter that sees what the policy sees
        (:class:`tether_gym.wrappers.FilterInTheLoop`). nu = arctan2(sin nu, cos nu) lies
        in (-pi, pi]: the orbit terms depend on nu only through sin and cos, so the
        wrapped angle predicts the same step.
        """
        st = self.split(obs)
        sl = STATE.slices(self.n_tethers)
        y = np.empty((st.theta.shape[0], STATE.size(self.n_tethers)))
        for name in STATE.names:
            y[:, sl[name]] = getattr(st, name)
        return np.arctan2(st.sin_nu, st.cos_nu), y

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
    ENV_KWARGS = RATE_ENV_KWARGS
    """Env arguments these policies need (:data:`RATE_ENV_KWARGS`)."""

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
