"""SlidingModeController: the paper's Sec. 4.3 case, the SB3 interface, input validation."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.physics import TetherChain
from tether_gym_agents import ObservationLayout, SlidingModeController

ORBIT = 2.0 * math.pi
TOL = 1e-3  # [rad], the convergence tolerance of the tracker issue


def _episode(env, policy, options=None):
    obs, info = env.reset(seed=0, options=options)
    infos = [info]
    while True:
        action, _ = policy.predict(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        assert np.isfinite(reward)
        infos.append(info)
        if terminated or truncated:
            return infos, terminated, truncated


def test_converges_in_first_orbit_and_stays_in_default_env():
    """From the Sec. 4.3 state in the default env (accel limit 0.01 m/s^2 on, L0 = 20 km,
    control step 0.025 rad), max|theta - theta_d| falls below 1e-3 rad before the end of
    orbit 1 and stays there to the end of orbit 3, with every tether taut throughout."""
    env = gym.make(tether_gym.ENV_ID, action_mode="rate")  # registered time limit = 3 orbits
    cfg = env.unwrapped.config
    assert cfg.accel_limit == 0.01 and cfg.orbits_per_episode == 3.0
    infos, terminated, truncated = _episode(env, SlidingModeController.for_env(env))
    assert not terminated and truncated, infos[-1]["failure"]
    nu = np.array([i["nu"] for i in infos])
    err = np.array([np.abs(i["theta"] - i["theta_ref"]).max() for i in infos])
    tension_min = np.array([i["tension_min"].min() for i in infos[1:]])
    assert nu[-1] >= 3 * ORBIT - 1e-9
    assert err[0] == pytest.approx(0.1, abs=1e-6)  # the initial perturbation theta_1(0) = 0.1
    above = np.nonzero(err >= TOL)[0]
    converged_at = nu[above[-1] + 1]  # first sample of the final run below TOL
    assert converged_at < ORBIT, f"converged only at {converged_at / ORBIT:.3f} orbits"
    assert err[nu >= ORBIT].max() < TOL
    assert tension_min.min() > 0.0
    # the accel limit is honoured (it binds during the transient)
    accel = np.array([np.abs(i["reel_accel"]).max() for i in infos])
    assert accel.max() <= 0.01 * (1 + 1e-9)
    assert accel.max() >= 0.01 * (1 - 1e-6)


def test_evaluate_policy_gives_finite_rewards():
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    env = Monitor(gym.make(tether_gym.ENV_ID, max_episode_steps=-1, orbits_per_episode=0.1,
                           action_mode="rate"))
    policy = SlidingModeController.for_env(env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "not wrapped with a Monitor" or other warning
        rewards, lengths = evaluate_policy(policy, env, n_eval_episodes=2,
                                           return_episode_rewards=True)
    steps = env.unwrapped.config.max_episode_steps
    assert lengths == [steps, steps]
    assert len(rewards) == 2 and np.all(np.isfinite(rewards))


def test_batch_and_single_observations_agree():
    env = gym.make(tether_gym.ENV_ID, action_mode="rate")
    obs, _ = env.reset(seed=0)
    obs2, _ = env.step(env.action_space.sample() * 0.0)[:2]
    policy = SlidingModeController.for_env(env)
    batch, state = policy.predict(np.stack([obs, obs2]))
    assert state is None
    assert batch.shape == (2, 2) and batch.dtype == np.float32
    np.testing.assert_array_equal(batch[0], policy.predict(obs)[0])
    np.testing.assert_array_equal(batch[1], policy.predict(obs2)[0])
    assert np.all(np.abs(batch) <= 1.0)


@pytest.mark.parametrize("name", ["c", "k", "eps"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf])
def test_bad_gains_raise_value_error_naming_the_value(name, value):
    env = gym.make(tether_gym.ENV_ID, action_mode="rate")
    with pytest.raises(ValueError, match=rf"{name}={value!r}"):
        SlidingModeController.for_env(env, **{name: value})


def test_non_numeric_gain_raises_type_error():
    env = gym.make(tether_gym.ENV_ID, action_mode="rate")
    with pytest.raises(TypeError, match="c must be a real number"):
        SlidingModeController.for_env(env, c="1")


def test_model_with_wrong_tether_count_is_rejected():
    layout = ObservationLayout(n_tethers=2, frequency=1.0, max_reel_rate=0.5)
    with pytest.raises(ValueError, match="1 tethers, the env 2"):
        SlidingModeController(TetherChain((1.0,), 0.2), layout)
    with pytest.raises(TypeError, match="TetherChain"):
        SlidingModeController("model", layout)


@pytest.mark.parametrize("shape", [(19,), (21,), (1, 19), (2, 3, 20), ()])
def test_wrong_observation_shape_raises_value_error(shape):
    env = gym.make(tether_gym.ENV_ID, action_mode="rate")
    policy = SlidingModeController.for_env(env)
    with pytest.raises(ValueError, match=r"observation must have shape \(20,\) or \(B, 20\)"):
        policy.predict(np.zeros(shape, dtype=np.float32))


def test_observed_eccentricity_alone_is_used_with_the_model_masses():
    """With observe_params="eccentricity" the law takes e from the observation and the
    masses from its model: on a fixed e equal to the model's it acts as with no params."""
    kwargs = {"action_mode": "rate", "eccentricity_range": (0.2, 0.2)}
    seeing = gym.make("tether_gym/TetherLibration-v2", observe_params="eccentricity", **kwargs)
    blind = gym.make("tether_gym/TetherLibration-v2", observe_params=False, **kwargs)
    obs_s, _ = seeing.reset(seed=0)
    obs_b, _ = blind.reset(seed=0)
    smc_s = SlidingModeController.for_env(seeing)
    smc_b = SlidingModeController.for_env(blind)
    assert smc_s.layout.split(obs_s[None]).mass_fractions is None
    for _ in range(5):
        act_s, _ = smc_s.predict(obs_s)
        act_b, _ = smc_b.predict(obs_b)
        np.testing.assert_allclose(act_s, act_b, rtol=0, atol=1e-6)
        obs_s, *_ = seeing.step(act_s)
        obs_b, *_ = blind.step(act_b)
