"""Hybrid policies: a safety filter around any rate-mode policy, residual RL and handover.

All have stable-baselines3's ``predict(observation, state=None, episode_start=None,
deterministic=True) -> (actions, state)``, so they run through
:func:`~tether_gym_agents.evaluation.rollout.rollout`,
:mod:`~tether_gym_agents.evaluation.benchmark` and
SB3's ``evaluate_policy`` like every other policy. They are ``batch_invariant`` when
their parts are (each row's action is bitwise what it would be alone).

Each filters its commands through :class:`tether_gym.wrappers.FilterInTheLoop` at the
state read from the observation (:meth:`ObservationLayout.state`: what the policy
sees, float32 and noisy under ``obs_noise``), the same filter step as
:class:`tether_gym.wrappers.SafetyFilterWrapper` and the residual training
(:mod:`tether_gym_agents.training.residual_env`).

* :class:`FilteredPolicy` passes the wrapped policy's action (a normalised reel-rate
  command) through :meth:`tether_gym.safety.SafetyFilter.project` and counts the
  interventions.
* :class:`ResidualPolicy` commands ``clip(a_base + scale * a_residual, -1, 1)``, with
  a_base the base law's action (e.g. the sliding-mode controller) and a_residual a
  trained model's deterministic action; given a filter, it filters the sum.
* :class:`HandoverPolicy` lets a trained policy steer the transient and hands over to
  the sliding-mode law once the law acts inside its boundary layer without saturating,
  filtered.
"""

from __future__ import annotations

import numpy as np

from tether_gym.envs.actions import INCREMENT, next_command
from tether_gym.params import check_range
from tether_gym.safety import FilterResult, SafetyFilter
from tether_gym.wrappers import FilterInTheLoop

from ..common.obs import ObservationLayout, require_predict
from .residual_spec import check_scale

__all__ = ["FilteredPolicy", "ResidualPolicy", "HandoverPolicy"]


class _Filtering:
    """The observation layout, the filter in the loop and its counters of a hybrid policy.

    The filter predicts from the state read from the observation
    (:meth:`ObservationLayout.state`), what the policy itself sees.
    """

    layout: ObservationLayout
    loop: FilterInTheLoop

    def _setup(self, safety_filter, source, layout: ObservationLayout | None) -> None:
        """Keep the layout (``layout``, else ``source.layout``; rate mode) and the filter."""
        self.layout = _layout_of(source, layout)
        self.layout.require_rate_mode(type(self).__name__)
        self.loop = FilterInTheLoop(safety_filter, self.layout.n_tethers)

    @property
    def safety_filter(self) -> SafetyFilter | None:
        """The filter of every command (None: unfiltered)."""
        return self.loop.safety_filter

    @property
    def steps(self) -> int:
        """Filtered actions so far (one per observation)."""
        return self.loop.steps

    @property
    def interventions(self) -> int:
        """Of those, how many the filter changed."""
        return self.loop.interventions

    @property
    def infeasible(self) -> int:
        """Of those, how many had no command meeting every constraint."""
        return self.loop.infeasible

    @property
    def filter_rate(self) -> float:
        """interventions / steps (NaN before the first step)."""
        return self.loop.filter_rate

    @property
    def last_result(self) -> FilterResult | None:
        """The filter's answer of the last call (None without a filter)."""
        return self.loop.last_result

    @property
    def last_filter_active(self) -> np.ndarray | None:
        """(B,) bool: whether the filter changed each action of the last call.

        None without a filter. Read by :func:`tether_gym_agents.evaluation.rollout.rollout`
        for the ``filter_rate`` metric.
        """
        return self.loop.last_active

    def reset_counts(self) -> None:
        """Set the counters to zero (e.g. between episodes)."""
        self.loop.reset_counts()

    def project(self, observation, action) -> np.ndarray:
        """``action`` (desired reel-rate commands) as this policy's filter sends it.

        For one observation (obs_dim,) or a batch (B, obs_dim); unchanged without a
        filter. Counted like the policy's own commands.
        """
        batch, single = self.layout.as_batch(observation)
        out = self._filter(batch, np.asarray(action, dtype=np.float64).reshape(batch.shape[0], -1))
        return out[0] if single else out

    @property
    def batch_invariant(self) -> bool:
        """True when every part's rows are bitwise independent of the batch.

        The filter's are: it decides each row on that row alone.
        """
        return all(getattr(part, "batch_invariant", False) for part in self._parts())

    def _parts(self) -> tuple:  # pragma: no cover - abstract
        raise NotImplementedError

    def _filter(self, obs: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The commands (B, n) float32 to send for ``action`` at observations ``obs``."""
        return self.loop(lambda: self.layout.state(obs), action).astype(np.float32)


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
        actions; e.g. :class:`~tether_gym_agents.baselines.smc.SlidingModeController`).
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
        if not isinstance(safety_filter, SafetyFilter):
            raise TypeError(f"safety_filter must be a SafetyFilter, got "
                            f"{type(safety_filter).__name__}")
        self.policy = require_predict("policy", policy)
        self._setup(safety_filter, policy, layout)

    def _parts(self) -> tuple:
        return (self.policy,)

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
        out = self._filter(batch, np.asarray(action, dtype=np.float64).reshape(batch.shape[0], -1))
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
        A trained model (any stable-baselines3 policy) whose deterministic
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
        self.base = require_predict("base", base)
        self.residual_model = require_predict("residual_model", residual_model)
        self.scale = check_scale(scale)
        self._setup(safety_filter, base, layout)

    def _parts(self) -> tuple:
        return (self.base, self.residual_model)

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


class HandoverPolicy(_Filtering):
    """A trained policy for the transient, then the sliding-mode law for good.

    Each episode starts with the *learned* policy in control. It hands over to the
    *base* law (the paper's sliding-mode controller) at the first step where the law
    would act as a linear feedback with reserve: every tether's sliding variable s
    (Eq. 12, :meth:`SlidingModeController.sliding_variable`) within ``enter`` of the
    surface (inside the boundary layer eps, where sat(s / eps) is linear) and every
    command of the law within ``command_bound`` of zero (not saturated: the paper's
    failures come with saturated commands in the first-orbit transient,
    docs/task_design.md). From then on the base law stays in control for the rest of
    the episode. Every command, learned or not, passes the safety filter when one is
    given. The design and what was tried before it are in docs/task_design.md
    ("The handover hybrid").

    Parameters
    ----------
    learned : TrainedAgent
        A trained agent (:class:`~tether_gym_agents.files.trained.TrainedAgent`) on this
        env's observation. Its action a becomes the command as the env it was trained
        in would make it (its recorded ``action_mode`` and ``increment_gain``, the env's
        defaults where absent), by the env's own update
        :func:`tether_gym.envs.actions.next_command`: with ``action_mode="increment"``
        u = clip(u_obs + increment_gain * a, -1, 1) from the observed command u_obs (so
        up to the float32 rounding of u_obs); in rate mode u = clip(a, -1, 1).
    base : SlidingModeController
        The base law (rate mode).
    safety_filter : SafetyFilter or None
        Filter of every command (None: unfiltered).
    enter : float or None
        Largest max_i |s_i| [rad/rad] at the handover, > 0; None: eps / 2.
    command_bound : float
        Largest max_i |u_i| [-] of the base law's normalised command at the handover,
        in (0, 1] (default 0.5).
    layout : ObservationLayout or None
        How to read the observation; None takes ``base.layout``.

    Notes
    -----
    The mode is the recurrent ``state`` of stable-baselines3's ``predict``: a (B,)
    float array, 1.0 where the base law is in control. ``episode_start`` (or
    ``state=None``) starts an episode with the learned policy. ``last_mode`` holds the
    mode of the last call's actions.
    """

    def __init__(self, learned, base, safety_filter: SafetyFilter | None = None,
                 enter: float | None = None, command_bound: float = 0.5,
                 layout: ObservationLayout | None = None):
        from ..baselines.smc import SlidingModeController

        require_predict("learned", learned)
        if not isinstance(base, SlidingModeController):
            raise TypeError(f"base must be a SlidingModeController, got "
                            f"{type(base).__name__}")
        self.learned = learned
        self.base = base
        self._setup(safety_filter, base, layout)
        self.enter = check_range("enter", base.eps / 2 if enter is None else enter, 0.0,
                                 low_open=True)
        self.command_bound = check_range("command_bound", command_bound, 0.0, 1.0,
                                         low_open=True)
        self.incremental, self.increment_gain = _action_of(learned)
        self.last_mode: np.ndarray | None = None

    def _parts(self) -> tuple:
        return (self.learned, self.base)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        """stable-baselines3 interface: (action, mode); the learned part is deterministic."""
        batch, single = self.layout.as_batch(observation)
        b = batch.shape[0]
        mode = (np.zeros(b, dtype=bool) if state is None
                else np.asarray(state, dtype=np.float64).reshape(b) > 0.5)
        if episode_start is not None:
            mode &= ~np.asarray(episode_start, dtype=bool).reshape(b)
        base, _ = self.base.predict(batch, deterministic=True)
        base = np.asarray(base, dtype=np.float64).reshape(b, -1)
        near = np.abs(self.base.sliding_variable(batch)).max(axis=1) <= self.enter
        mode |= near & (np.abs(base).max(axis=1) <= self.command_bound)
        action = base.copy()
        if not mode.all():
            rows = batch[~mode]
            a, _ = self.learned.predict(rows.astype(np.float32), deterministic=True)
            a = np.asarray(a, dtype=np.float64).reshape(-1, action.shape[1])
            action[~mode] = next_command(self.layout.split(rows).command, a,
                                         self.incremental, self.increment_gain)
        self.last_mode = mode.copy()
        out = self._filter(batch, action).astype(np.float32)
        return (out[0] if single else out), mode.astype(np.float64)

    def __repr__(self) -> str:
        return (f"HandoverPolicy(learned={self.learned!r}, base={self.base!r}, "
                f"enter={self.enter}, command_bound={self.command_bound}, "
                f"filtered={self.safety_filter is not None})")


def _action_of(learned) -> tuple[bool, float]:
    """(whether ``learned`` was trained with ``action_mode="increment"``, its gain [-]).

    Read from the recorded env arguments (``learned.env_kwargs``), the env's defaults
    where absent; a policy without recorded arguments is taken to command rates.
    """
    from tether_gym.envs.config import Action

    kwargs = getattr(learned, "env_kwargs", None)
    default = Action()
    if kwargs is None:
        return False, default.increment_gain
    return (kwargs.get("action_mode", default.mode) == INCREMENT,
            float(kwargs.get("increment_gain", default.increment_gain)))
