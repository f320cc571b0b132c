"""Paper reproduction: rollouts, through the benchmark's rollout path.

Every study runs one episode of a baseline with :func:`tether_gym_agents.evaluation.rollout.rollout`
on a one-env native vector env whose only time limit is the configured number of orbits
(``max_episode_steps=-1``), and keeps the whole
:class:`~tether_gym_agents.evaluation.rollout.Trajectory`.
"""

from __future__ import annotations

import gymnasium as gym

import tether_gym

from ..baselines.open_loop import PeriodicReel, ZeroStateReel
from ..baselines.smc import SlidingModeController
from ..common.obs import with_rate_mode
from ..evaluation.rollout import Trajectory, make_vector_env, rollout
from .settings import OPEN_LOOP_SETTINGS

__all__ = ["Trajectory", "make_env", "run_episode", "run_zero_state", "run_periodic",
           "run_smc"]


def make_env(orbits: float, **kwargs):
    """The registered single env with its own time limit only (``max_episode_steps=-1``)."""
    return gym.make(tether_gym.ENV_ID, max_episode_steps=-1, orbits_per_episode=orbits,
                    **kwargs)


def run_episode(policy_for_env, orbits: float, options: dict | None = None, seed: int = 0,
                **env_kwargs) -> Trajectory:
    """One episode of ``policy_for_env(env)`` over ``orbits`` orbits.

    Parameters
    ----------
    policy_for_env : callable
        Builds the policy for the env (e.g. ``SlidingModeController.for_env``).
    orbits : float
        Episode length [orbits].
    options : dict or None
        Reset options (initial state).
    seed : int
        Env seed.
    **env_kwargs
        Further env arguments (the paper's laws command reel rates:
        ``action_mode="rate"``; another mode is a ValueError).
    """
    kwargs = {**with_rate_mode(env_kwargs, "the paper's laws"), "orbits_per_episode": orbits}
    venv = make_vector_env(1, kwargs)
    try:
        return rollout(policy_for_env(venv), [seed], options=options, env=venv)[0]
    finally:
        venv.close()


def run_zero_state(orbits: float) -> Trajectory:
    """Eq. 7 from theta = theta' = 0 (Figs. 2-4)."""
    return run_episode(ZeroStateReel.for_env, orbits,
                       {"theta": [0.0, 0.0], "dtheta": [0.0, 0.0]},
                       amplitude=0.0, initial_theta=(0.0, 0.0), **OPEN_LOOP_SETTINGS)


def run_periodic(eccentricity: float, amplitude: float, orbits: float,
                 semi_latus_rectum: float | None = None) -> Trajectory:
    """Eq. 10 on the reference from theta = 0, theta' = A (w = 1), no accel limit."""
    kwargs = dict(OPEN_LOOP_SETTINGS, eccentricity=eccentricity, amplitude=amplitude,
                  initial_theta=(0.0, 0.0))
    if semi_latus_rectum is not None:
        kwargs["semi_latus_rectum"] = semi_latus_rectum
    return run_episode(PeriodicReel.for_env, orbits,
                       {"theta": [0.0, 0.0], "dtheta": [amplitude, amplitude]}, **kwargs)


def run_smc(orbits: float, settings: dict, **env_kwargs) -> Trajectory:
    """Sliding mode (c = k = 1, eps = 0.1) from the Sec. 4.3 state, accel limit on."""
    return run_episode(SlidingModeController.for_env, orbits, **settings, **env_kwargs)
