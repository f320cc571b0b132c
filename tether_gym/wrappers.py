"""Gymnasium wrappers of the TetherLibration env: the safety filter in the loop."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from .physics import STATE
from .safety import FilterResult, SafetyFilter

__all__ = ["SafetyFilterWrapper", "INFO_KEYS", "state_of"]

INFO_KEYS = ("filter_active", "filter_correction", "filter_feasible")
"""Entries the wrapper adds to every step's and reset's ``info``."""


def state_of(info: dict) -> tuple[float, np.ndarray]:
    """(nu [rad], state row ``[theta, theta', l, l']`` (4n,)) from an env ``info``.

    The env's ``info`` holds the true (noise-free) state; the observation may carry
    ``obs_noise``.
    """
    return float(info["nu"]), np.concatenate([np.asarray(info[key], dtype=float)
                                              for key in STATE.names])


class SafetyFilterWrapper(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Filter every action of a rate-mode TetherLibration env through a :class:`SafetyFilter`.

    The action (normalised reel-rate command in [-1, 1]^n) is replaced by
    ``filter.project(nu, state, action).command`` at the state the env is in (read from
    the last ``info``, the true state, not the possibly noisy observation), and ``info``
    gets ``filter_active`` (bool), ``filter_correction`` (float, |a_filtered - a| [-])
    and ``filter_feasible`` (bool) of that step (False, 0.0, True after a reset).

    Parameters
    ----------
    env : gymnasium.Env
        A ``tether_gym/TetherLibration`` env whose action is the command
        (``action_mode="rate"``; v0 has no other mode).
    safety_filter : SafetyFilter or None
        The filter; None builds ``SafetyFilter.for_env(env, **filter_kwargs)``.
    **filter_kwargs
        ``margin`` and ``length_margin`` of :meth:`SafetyFilter.for_env`.

    Raises
    ------
    ValueError
        If the env's actions are not reel-rate commands.
    """

    def __init__(self, env: gym.Env, safety_filter: SafetyFilter | None = None,
                 **filter_kwargs: Any):
        gym.utils.RecordConstructorArgs.__init__(self, safety_filter=safety_filter,
                                                 **filter_kwargs)
        gym.ActionWrapper.__init__(self, env)
        cfg = getattr(env.unwrapped, "config", None)
        if cfg is None:
            raise TypeError(f"env must be a TetherLibration env, got {env.unwrapped!r}")
        mode = getattr(cfg, "action_mode", "rate")
        if str(getattr(mode, "value", mode)) != "rate":
            raise ValueError(f"SafetyFilterWrapper filters reel-rate commands, but the env has "
                             f"action_mode={mode!r}; wrap a rate-mode env: gym.make(..., "
                             "action_mode='rate')")
        self.safety_filter = (safety_filter if safety_filter is not None
                              else SafetyFilter.for_env(env, **filter_kwargs))
        if self.safety_filter.n != cfg.n_tethers:
            raise ValueError(f"the filter is for {self.safety_filter.n} tethers, the env has "
                             f"{cfg.n_tethers}")
        self._state: tuple[float, np.ndarray] | None = None
        self.last_result: FilterResult | None = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Reset the env and remember its state; the info reports an idle filter."""
        obs, info = self.env.reset(seed=seed, options=options)
        self._state = state_of(info)
        self.last_result = None
        info.update(filter_active=False, filter_correction=0.0, filter_feasible=True)
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
        res = self.safety_filter.project(nu, y[None], act[None])
        self.last_result = res
        if not res.active[0]:
            return action
        return res.command[0]  # float64: the env takes any real dtype

    def step(self, action):
        """Step the env with the filtered action; add the filter's entries to ``info``."""
        obs, reward, terminated, truncated, info = self.env.step(self.action(action))
        self._state = state_of(info)
        res = self.last_result
        assert res is not None
        info.update(filter_active=bool(res.active[0]),
                    filter_correction=float(res.correction[0]),
                    filter_feasible=bool(res.feasible[0]))
        return obs, reward, terminated, truncated, info
