"""Hybrid policies: a safety filter around any rate-mode policy, and residual RL.

Both have stable-baselines3's ``predict(observation, state=None, episode_start=None,
deterministic=True) -> (actions, state)``, so they run through
:func:`~tether_gym_agents.rollout.rollout`, :mod:`~tether_gym_agents.evaluation` and
SB3's ``evaluate_policy`` like every other policy.

* :class:`FilteredPolicy` passes the wrapped policy's action (a normalised reel-rate
  command) through :meth:`tether_gym.safety.SafetyFilter.project` at the state read
  from the observation, and counts the interventions.
* :class:`ResidualPolicy` commands ``clip(a_base + scale * a_residual, -1, 1)``, with
  a_base the base law's action (e.g. the sliding-mode controller) and a_residual a
  trained model's deterministic action; given a filter, it filters the sum.
"""

from __future__ import annotations

import numpy as np

from tether_gym.params import check_range
from tether_gym.physics import STATE
from tether_gym.safety import FilterResult, SafetyFilter

from .obs import ObservationLayout

__all__ = ["FilteredPolicy", "ResidualPolicy", "state_from_observation"]


def state_from_observation(layout: ObservationLayout, obs: np.ndarray):
    """(nu (B,) [rad], state rows (B, 4n) in the STATE layout) of a (B, obs_dim) batch.

    nu = arctan2(sin nu, cos nu) lies in (-pi, pi]: the orbit terms depend on nu only
    through sin and cos, so the wrapped angle predicts the same step.
    """
    st = layout.split(obs)
    n = layout.n_tethers
    y = np.empty((obs.shape[0], STATE.size(n)))
    sl = STATE.slices(n)
    for name in STATE.names:
        y[:, sl[name]] = getattr(st, name)
    return np.arctan2(st.sin_nu, st.cos_nu), y


class _Filtering:
    """Shared filter step and intervention counters of the hybrid policies."""

    layout: ObservationLayout
    safety_filter: SafetyFilter | None

    def _init_counts(self) -> None:
        self.steps = 0
        """Filtered actions so far (one per observation)."""
        self.interventions = 0
        """Of those, how many the filter changed."""
        self.infeasible = 0
        """Of those, how many had no command meeting every constraint."""
        self.last_filter_active: bool | None = None
        """Whether the filter changed the last action (one observation per call), read by
        :func:`tether_gym_agents.rollout.rollout` for the ``filter_rate`` metric."""
        self.last_result: FilterResult | None = None

    def reset_counts(self) -> None:
        """Set the counters to zero (e.g. between episodes)."""
        self._init_counts()

    @property
    def filter_rate(self) -> float:
        """interventions / steps (NaN before the first step)."""
        return self.interventions / self.steps if self.steps else float("nan")

    def _filter(self, obs: np.ndarray, action: np.ndarray) -> np.ndarray:
        if self.safety_filter is None:
            return action
        nu, y = state_from_observation(self.layout, obs)
        res = self.safety_filter.project(nu, y, np.asarray(action, dtype=np.float64))
        self.last_result = res
        self.steps += int(res.active.shape[0])
        self.interventions += int(res.active.sum())
        self.infeasible += int((~res.feasible).sum())
        self.last_filter_active = bool(res.active[-1])
        return res.command.astype(np.float32)


def _layout_of(policy, layout: ObservationLayout | None) -> ObservationLayout:
    layout = layout if layout is not None else getattr(policy, "layout", None)
    if not isinstance(layout, ObservationLayout):
        raise TypeError(f"policy {policy!r} has no ObservationLayout: pass layout="
                        "ObservationLayout.from_env(env)")
    return layout


class FilteredPolicy(_Filtering):
    """Any rate-mode policy with a :class:`~tether_gym.safety.SafetyFilter` on its actions.

    Parameters
    ----------
    policy : object with ``predict``
        Its actions are normalised reel-rate commands in [-1, 1] (a rate-mode env's
        actions; e.g. :class:`~tether_gym_agents.smc.SlidingModeController`).
    safety_filter : SafetyFilter
        The filter (:meth:`SafetyFilter.for_env`).
    layout : ObservationLayout or None
        How to read the observation; None takes ``policy.layout``.

    Notes
    -----
    The state is read from the observation (float32, and noisy under ``obs_noise``),
    nu as arctan2(sin nu, cos nu). Counters: ``steps``, ``interventions``,
    ``infeasible``, ``filter_rate``, ``reset_counts()``.
    """

    def __init__(self, policy, safety_filter: SafetyFilter,
                 layout: ObservationLayout | None = None):
        if not hasattr(policy, "predict"):
            raise TypeError(f"policy must have a predict method, got {type(policy).__name__}")
        if not isinstance(safety_filter, SafetyFilter):
            raise TypeError(f"safety_filter must be a SafetyFilter, got "
                            f"{type(safety_filter).__name__}")
        self.policy = policy
        self.safety_filter = safety_filter
        self.layout = _layout_of(policy, layout)
        self.layout.require_rate_mode(type(self).__name__)
        if safety_filter.n != self.layout.n_tethers:
            raise ValueError(f"the filter is for {safety_filter.n} tethers, the policy's env "
                             f"has {self.layout.n_tethers}")
        self._init_counts()

    @classmethod
    def for_env(cls, policy, env, **filter_kwargs) -> FilteredPolicy:
        """``policy`` filtered by ``SafetyFilter.for_env(env, **filter_kwargs)``."""
        return cls(policy, SafetyFilter.for_env(env, **filter_kwargs),
                   ObservationLayout.from_env(env))

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """stable-baselines3 interface: the wrapped policy's action, filtered."""
        batch, single = self.layout.as_batch(observation)
        action, state = self.policy.predict(batch, state=state, episode_start=episode_start,
                                            deterministic=deterministic)
        action = np.asarray(action, dtype=np.float64).reshape(batch.shape[0], -1)
        out = self._filter(batch, action)
        return (out[0] if single else out), state

    def __repr__(self) -> str:
        return f"FilteredPolicy({self.policy!r}, {self.safety_filter!r})"


class ResidualPolicy(_Filtering):
    """Base law plus a scaled learned residual: a = clip(a_base + scale * a_res, -1, 1).

    Parameters
    ----------
    base : object with ``predict``
        The base law (rate mode), e.g. the sliding-mode controller.
    residual_model : object with ``predict``
        A trained model (e.g. a stable-baselines3 PPO or SAC) whose deterministic
        action in [-1, 1]^n is the residual.
    scale : float
        Weight of the residual [-], >= 0 (0 gives the base law).
    safety_filter : SafetyFilter or None
        Filter of the summed action (None: unfiltered).
    layout : ObservationLayout or None
        How to read the observation; None takes ``base.layout``.
    """

    def __init__(self, base, residual_model, scale: float,
                 safety_filter: SafetyFilter | None = None,
                 layout: ObservationLayout | None = None):
        for name, obj in (("base", base), ("residual_model", residual_model)):
            if not hasattr(obj, "predict"):
                raise TypeError(f"{name} must have a predict method, got {type(obj).__name__}")
        if safety_filter is not None and not isinstance(safety_filter, SafetyFilter):
            raise TypeError(f"safety_filter must be a SafetyFilter or None, got "
                            f"{type(safety_filter).__name__}")
        self.base = base
        self.residual_model = residual_model
        self.scale = check_range("scale", scale, 0.0)
        self.safety_filter = safety_filter
        self.layout = _layout_of(base, layout)
        self.layout.require_rate_mode(type(self).__name__)
        self._init_counts()

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """stable-baselines3 interface: (action, None); the residual is always deterministic."""
        batch, single = self.layout.as_batch(observation)
        b = batch.shape[0]
        base, _ = self.base.predict(batch, deterministic=True)
        obs32 = batch.astype(np.float32)
        res, _ = self.residual_model.predict(obs32, deterministic=True)
        total = (np.asarray(base, dtype=np.float64).reshape(b, -1)
                 + self.scale * np.asarray(res, dtype=np.float64).reshape(b, -1))
        out = self._filter(batch, np.clip(total, -1.0, 1.0)).astype(np.float32)
        return (out[0] if single else out), None

    def __repr__(self) -> str:
        return (f"ResidualPolicy(base={self.base!r}, scale={self.scale}, "
                f"filtered={self.safety_filter is not None})")
