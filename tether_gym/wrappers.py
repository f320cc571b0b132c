"""The safety filter in the loop: one filter step for every user, and its gymnasium wrapper.

:class:`FilterInTheLoop` is the one place where a reel-rate command meets a
:class:`~tether_gym.safety.SafetyFilter`: given the state the filter predicts from and
the desired commands, it returns the commands to send with the filter's
:class:`~tether_gym.safety.FilterResult`, counts the interventions and gives each row's
``info`` entries (:data:`INFO_KEYS`). The caller chooses the state source: the env's
true state from its ``info`` (:func:`state_of`) or the state read from an observation
(``tether_gym_agents.common.obs.ObservationLayout.state``).
:class:`SafetyFilterWrapper` puts it around a gymnasium env (true state); the hybrid
policies and the residual training of ``tether_gym_agents`` use it on observations.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from types import MappingProxyType
from typing import Any

import gymnasium as gym
import numpy as np

from .envs.actions import require_rate_mode
from .envs.config import env_config
from .physics import STATE
from .safety import FilterResult, SafetyFilter

__all__ = ["SafetyFilterWrapper", "FilterInTheLoop", "INFO_KEYS", "IDLE_INFO", "state_of",
           "INFEASIBLE_WARNING", "InfeasibleCommandWarning"]

IDLE_INFO = MappingProxyType({"filter_active": False, "filter_correction": 0.0,
                              "filter_feasible": True})
"""The filter's ``info`` entries of a step it did not filter (after a reset, or no filter)."""

INFO_KEYS = tuple(IDLE_INFO)
"""Entries a filter in the loop adds to every step's ``info``: ``filter_active`` (bool,
the command was changed), ``filter_correction`` (float, |u_filtered - u| [-]) and
``filter_feasible`` (bool, the command sent meets every predicted constraint)."""

INFEASIBLE_WARNING = (
    "no reel command met every predicted constraint (tension >= margin, braking-stop "
    "length inside the bounds), so the filter sent the command of largest predicted "
    "tension margin inside the length box, which may still let a tether go slack. Said "
    "once per process for these filter settings (warnings.filterwarnings('ignore', "
    "category=tether_gym.wrappers.InfeasibleCommandWarning) silences it); every such step "
    "has info['filter_feasible'] False and is counted by FilterInTheLoop.infeasible")
"""What the warning of an infeasible command means (its message's fixed part)."""


class InfeasibleCommandWarning(UserWarning):
    """A safety filter found no command meeting every predicted constraint.

    Raised by :class:`FilterInTheLoop` once per process and filter settings (the
    filter's ``repr``), whichever policy or env the filter serves: Python's own
    once-per-location registry is reset whenever any library enters
    ``warnings.catch_warnings``, which showed the same warning again and again.
    """


_WARNED: set[str] = set()
"""The filter settings (``repr``) whose infeasible command was warned of in this process."""

State = tuple[float | np.ndarray, np.ndarray]
"""(nu [rad], scalar or (B,); state rows (B, 4n) in the STATE layout)."""


def state_of(info: dict) -> tuple[float, np.ndarray]:
    """(nu [rad], state row ``[theta, theta', l, l']`` (4n,)) from an env ``info``.

    The env's ``info`` holds the true (noise-free) state; the observation may carry
    ``obs_noise``.
    """
    return float(info["nu"]), np.concatenate([np.asarray(info[key], dtype=float)
                                              for key in STATE.names])


class FilterInTheLoop:
    """A safety filter (or none) between the commands of a policy and a rate-mode env.

    Parameters
    ----------
    safety_filter : SafetyFilter or None
        The filter; None passes every command through unchanged.
    n_tethers : int
        n = N - 1 of the env the commands go to (the filter must be for as many).

    Raises
    ------
    TypeError
        If ``safety_filter`` is neither a SafetyFilter nor None.
    ValueError
        If the filter is for another number of tethers.

    Notes
    -----
    Counters since construction or :meth:`reset_counts`: ``steps`` (filtered commands,
    one per row), ``interventions`` (of those, the ones the filter changed),
    ``infeasible`` (the ones with no command meeting every constraint); ``last_result``
    and ``last_active`` ((B,) bool) describe the last call (None without a filter).

    The first infeasible command of a filter's settings in the process also raises an
    :class:`InfeasibleCommandWarning` naming the filter, the step and the rows, then
    :data:`INFEASIBLE_WARNING`: the command sent then is the one of largest predicted
    tension, which may still go slack.
    """

    def __init__(self, safety_filter: SafetyFilter | None, n_tethers: int):
        if not (safety_filter is None or isinstance(safety_filter, SafetyFilter)):
            raise TypeError(f"safety_filter must be a SafetyFilter or None, got "
                            f"{type(safety_filter).__name__}")
        if safety_filter is not None and safety_filter.n != n_tethers:
            raise ValueError(f"the filter is for {safety_filter.n} tethers, the env has "
                             f"{n_tethers}")
        self.safety_filter = safety_filter
        self.n_tethers = int(n_tethers)
        self.reset_counts()

    def reset_counts(self) -> None:
        """Set the counters to zero and forget the last result."""
        self.steps = 0
        self.interventions = 0
        self.infeasible = 0
        self.last_result: FilterResult | None = None
        self.last_active: np.ndarray | None = None

    @property
    def filter_rate(self) -> float:
        """interventions / steps (NaN before the first filtered command)."""
        return self.interventions / self.steps if self.steps else float("nan")

    def __call__(self, state: State | Callable[[], State], command) -> np.ndarray:
        """The commands to send (B, n) float64 for the desired ``command`` (B, n).

        ``state`` is the state the filter predicts from, or a function returning it
        (called only when there is a filter). Without a filter the commands come back
        unchanged; with one, as :meth:`SafetyFilter.project` returns them.
        """
        command = np.asarray(command, dtype=np.float64)
        if self.safety_filter is None:
            return command
        nu, y = state() if callable(state) else state
        res = self.safety_filter.project(nu, y, command)
        self.last_result = res
        self.last_active = res.active.copy()
        self.steps += int(res.active.shape[0])
        self.interventions += int(res.active.sum())
        infeasible = int((~res.feasible).sum())
        if infeasible:
            self._warn_infeasible(infeasible, int(res.active.shape[0]))
        self.infeasible += infeasible
        return res.command

    def _warn_infeasible(self, rows: int, batch: int) -> None:
        settings = repr(self.safety_filter)
        if settings in _WARNED:
            return
        _WARNED.add(settings)
        warnings.warn(f"tether_gym safety filter {settings}: {rows} of the {batch} "
                      f"command(s) of one call infeasible ({self.steps} commands filtered "
                      f"since its counters were reset): {INFEASIBLE_WARNING}",
                      InfeasibleCommandWarning, stacklevel=3)

    def info(self, row: int = 0) -> dict[str, Any]:
        """Row ``row``'s :data:`INFO_KEYS` entries of the last call (idle without one)."""
        res = self.last_result
        if res is None:
            return dict(IDLE_INFO)
        return {"filter_active": bool(res.active[row]),
                "filter_correction": float(res.correction[row]),
                "filter_feasible": bool(res.feasible[row])}


class SafetyFilterWrapper(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Filter every action of a rate-mode TetherLibration env through a :class:`SafetyFilter`.

    The action (normalised reel-rate command in [-1, 1]^n) is replaced by the
    filtered command (:class:`FilterInTheLoop`) at the state the env is in (read from
    the last ``info``, the true state, not the possibly noisy observation), and ``info``
    gets :data:`INFO_KEYS` of that step (:data:`IDLE_INFO` after a reset).

    Parameters
    ----------
    env : gymnasium.Env
        A ``tether_gym/TetherLibration`` env whose action is the command
        (``action_mode="rate"``).
    safety_filter : SafetyFilter or None
        The filter; None builds ``SafetyFilter.for_env(env, **filter_kwargs)``.
    **filter_kwargs
        ``margin`` and ``length_margin`` of :meth:`SafetyFilter.for_env`.

    Raises
    ------
    TypeError
        If ``env`` is not a TetherLibration env.
    ValueError
        If the env's actions are not reel-rate commands, or the filter is for another
        number of tethers.
    """

    def __init__(self, env: gym.Env, safety_filter: SafetyFilter | None = None,
                 **filter_kwargs: Any):
        gym.utils.RecordConstructorArgs.__init__(self, safety_filter=safety_filter,
                                                 **filter_kwargs)
        gym.ActionWrapper.__init__(self, env)
        cfg = env_config(env)
        require_rate_mode(cfg.action_mode, type(self).__name__)
        if safety_filter is None:
            safety_filter = SafetyFilter.for_env(env, **filter_kwargs)
        self.loop = FilterInTheLoop(safety_filter, cfg.n_tethers)
        self._state: tuple[float, np.ndarray] | None = None

    @property
    def safety_filter(self) -> SafetyFilter:
        """The filter."""
        assert self.loop.safety_filter is not None
        return self.loop.safety_filter

    @property
    def last_result(self) -> FilterResult | None:
        """The filter's answer for the last action (None after a reset)."""
        return self.loop.last_result

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Reset the env and remember its state; the info reports an idle filter."""
        obs, info = self.env.reset(seed=seed, options=options)
        self._state = state_of(info)
        self.loop.last_result = None
        info.update(IDLE_INFO)
        return obs, info

    def action(self, action):
        """The filtered action for the current state (the action itself when it is safe)."""
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        act = np.asarray(action, dtype=np.float64)
        if act.shape != self.action_space.shape:
            raise ValueError(f"action must have shape {self.action_space.shape}, got "
                             f"{act.shape}: {action!r}")
        nu, y = self._state
        command = self.loop((nu, y[None]), act[None])
        if not self.loop.info()["filter_active"]:
            return action
        return command[0]  # float64: the env takes any real dtype

    def step(self, action):
        """Step the env with the filtered action; add the filter's entries to ``info``."""
        obs, reward, terminated, truncated, info = self.env.step(self.action(action))
        self._state = state_of(info)
        info.update(self.loop.info())
        return obs, reward, terminated, truncated, info
