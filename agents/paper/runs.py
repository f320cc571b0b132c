"""Paper reproduction: rollouts."""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

import tether_gym

from ..open_loop import PeriodicReel, ZeroStateReel
from ..smc import SlidingModeController
from .settings import OPEN_LOOP_SETTINGS, ORBIT


@dataclass
class Trajectory:
    """One episode: the reset state (row 0) and the state after every control step.

    Arrays have one row per sample (K + 1 rows for K steps), except ``command``
    (K rows: the commanded reel rate l'_cmd [-] held over step k, after clipping).
    ``tension`` is T^ at the sample, ``tension_min`` the smallest T^ at the physics
    substep boundaries of the step that ended there.
    """

    nu: np.ndarray
    theta: np.ndarray
    dtheta: np.ndarray
    length: np.ndarray
    dlength: np.ndarray
    tension: np.ndarray
    tension_min: np.ndarray
    theta_ref: np.ndarray
    reel_accel: np.ndarray
    command: np.ndarray
    failure: str | None
    settings: dict = field(default_factory=dict)

    @property
    def orbits(self) -> np.ndarray:
        """nu / 2 pi [orbits] of each sample (from the start of the episode)."""
        return (self.nu - self.nu[0]) / ORBIT

    @property
    def tracking_error(self) -> np.ndarray:
        """max_i |theta_i - theta_d| [rad] per sample."""
        return np.abs(self.theta - self.theta_ref[:, None]).max(axis=1)

    @property
    def duration(self) -> float:
        """Orbits actually simulated."""
        return float(self.orbits[-1])


def make_env(orbits: float, **kwargs):
    """The registered env with its own time limit only (``max_episode_steps=-1``)."""
    return gym.make(tether_gym.ENV_ID, max_episode_steps=-1, orbits_per_episode=orbits,
                    **kwargs)


def rollout(env, policy, options: dict | None = None, seed: int = 0) -> Trajectory:
    """Run one episode of ``policy`` (``predict`` interface) and record it."""
    obs, info = env.reset(seed=seed, options=options)
    cfg = env.unwrapped.config
    infos = [info]
    commands = []
    while True:
        action, _ = policy.predict(obs, deterministic=True)
        commands.append(np.clip(np.asarray(action, dtype=float), -1.0, 1.0) * cfg.max_reel_rate)
        obs, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        if terminated or truncated:
            break

    def stack(key):
        return np.array([i[key] for i in infos], dtype=float)

    return Trajectory(stack("nu"), stack("theta"), stack("dtheta"), stack("length"),
                      stack("dlength"), stack("tension"), stack("tension_min"),
                      stack("theta_ref"), stack("reel_accel"), np.array(commands),
                      infos[-1]["failure"],
                      {"control_step": cfg.control_step, "physics_step": cfg.physics_step,
                       "reel_time_constant": cfg.reel_time_constant,
                       "accel_limit": cfg.accel_limit, "eccentricity": cfg.eccentricity,
                       "amplitude": cfg.amplitude, "max_reel_rate": cfg.max_reel_rate,
                       "total_tether_length": cfg.total_tether_length})


def run_zero_state(orbits: float) -> Trajectory:
    """Eq. 7 from theta = theta' = 0 (Figs. 2-4)."""
    env = make_env(orbits, amplitude=0.0, initial_theta=(0.0, 0.0), **OPEN_LOOP_SETTINGS)
    try:
        return rollout(env, ZeroStateReel.for_env(env),
                       {"theta": [0.0, 0.0], "dtheta": [0.0, 0.0]})
    finally:
        env.close()


def run_periodic(eccentricity: float, amplitude: float, orbits: float,
                 semi_latus_rectum: float | None = None) -> Trajectory:
    """Eq. 10 on the reference from theta = 0, theta' = A (w = 1), no accel limit."""
    kwargs = dict(OPEN_LOOP_SETTINGS, eccentricity=eccentricity, amplitude=amplitude,
                  initial_theta=(0.0, 0.0))
    if semi_latus_rectum is not None:
        kwargs["semi_latus_rectum"] = semi_latus_rectum
    env = make_env(orbits, **kwargs)
    try:
        return rollout(env, PeriodicReel.for_env(env),
                       {"theta": [0.0, 0.0], "dtheta": [amplitude, amplitude]})
    finally:
        env.close()


def run_smc(orbits: float, settings: dict, **env_kwargs) -> Trajectory:
    """Sliding mode (c = k = 1, eps = 0.1) from the Sec. 4.3 state, accel limit on."""
    env = make_env(orbits, **settings, **env_kwargs)
    try:
        return rollout(env, SlidingModeController.for_env(env))
    finally:
        env.close()
