"""FilteredPolicy and ResidualPolicy: SB3's evaluate_policy, the filter's effect, and the
filter_rate metric of the rollouts."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

import tether_gym
from tether_gym.safety import SafetyFilter
from tether_gym_agents import SlidingModeController
from tether_gym_agents.hybrid import FilteredPolicy, ResidualPolicy, state_from_observation
from tether_gym_agents.metrics import METRICS, episode_metrics
from tether_gym_agents.obs import ObservationLayout
from tether_gym_agents.rollout import rollout

SHORT = {"orbits_per_episode": 0.1, "action_mode": "rate"}


@pytest.fixture
def env():
    e = Monitor(gym.make(tether_gym.ENV_ID, **SHORT))  # evaluate_policy asks for it
    yield e
    e.close()


class Constant:
    """A policy (or residual model) with a fixed action."""

    def __init__(self, action):
        self.action = np.asarray(action, dtype=np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(observation)
        return (np.broadcast_to(self.action, obs.shape[:-1] + self.action.shape).copy(),
                None)


def test_state_from_observation_matches_the_info(env):
    obs, info = env.reset(seed=1)
    nu, y = state_from_observation(ObservationLayout.from_env(env), obs[None])
    np.testing.assert_allclose(nu[0], info["nu"], atol=1e-6)
    np.testing.assert_allclose(y[0], np.concatenate(
        [info["theta"], info["dtheta"], info["length"], info["dlength"]]), atol=1e-6)


def test_filtered_smc_under_evaluate_policy(env):
    policy = FilteredPolicy.for_env(SlidingModeController.for_env(env), env)
    mean, _ = evaluate_policy(policy, env, n_eval_episodes=2, deterministic=True)
    assert np.isfinite(mean) and mean > 0.0
    assert policy.steps == 2 * env.unwrapped.max_episode_steps
    assert 0.0 <= policy.filter_rate <= 1.0


def test_safe_actions_pass_bit_for_bit(env):
    smc = SlidingModeController.for_env(env)
    policy = FilteredPolicy.for_env(smc, env)
    obs, _ = env.reset(seed=0)
    a, _ = policy.predict(obs)
    b, _ = smc.predict(obs)
    assert not policy.last_filter_active and np.array_equal(a, b) and a.dtype == b.dtype


def test_the_filter_changes_a_reel_in_that_would_end_too_short():
    env = gym.make(tether_gym.ENV_ID, initial_lengths=(0.1, 0.9), orbits_per_episode=0.3,
                   action_mode="rate")
    raw = Constant([-1.0, 0.0])
    kwargs = {"initial_lengths": (0.1, 0.9), "orbits_per_episode": 0.3, "action_mode": "rate"}
    plain = rollout(raw, [0], kwargs)[0]
    assert plain.failure == "length"
    policy = FilteredPolicy(raw, SafetyFilter.for_env(env), ObservationLayout.from_env(env))
    traj = rollout(policy, [0], kwargs)[0]
    assert traj.failure is None and traj.length[:, 0].min() >= 0.05
    m = episode_metrics(traj)
    assert 0.0 < m["filter_rate"] < 1.0
    assert m["filter_rate"] == pytest.approx(policy.interventions / policy.steps)
    assert "filter_rate" not in episode_metrics(plain) and "filter_rate" not in METRICS
    env.close()


def test_residual_policy_under_evaluate_policy(env):
    from stable_baselines3 import PPO

    smc = SlidingModeController.for_env(env)
    model = PPO("MlpPolicy", env, n_steps=16, batch_size=16, seed=0, device="cpu")
    for flt in (None, SafetyFilter.for_env(env)):
        policy = ResidualPolicy(smc, model, scale=0.1, safety_filter=flt)
        mean, _ = evaluate_policy(policy, env, n_eval_episodes=1, deterministic=True)
        assert np.isfinite(mean)


def test_residual_is_base_plus_scaled_residual(env):
    obs, _ = env.reset(seed=0)
    smc = SlidingModeController.for_env(env)
    policy = ResidualPolicy(smc, Constant([0.5, -0.5]), scale=0.2)
    a, state = policy.predict(obs)
    base, _ = smc.predict(obs)
    np.testing.assert_allclose(a, np.clip(base + 0.2 * np.array([0.5, -0.5]), -1, 1),
                               atol=1e-7)
    assert state is None and policy.last_filter_active is None
    assert np.array_equal(ResidualPolicy(smc, Constant([1.0, 1.0]), 0.0).predict(obs)[0], base)


def test_validation(env):
    smc = SlidingModeController.for_env(env)
    with pytest.raises(ValueError, match="scale"):
        ResidualPolicy(smc, Constant([0.0, 0.0]), scale=-1.0)
    with pytest.raises(TypeError, match="predict"):
        FilteredPolicy(object(), SafetyFilter.for_env(env))
    with pytest.raises(TypeError, match="layout"):
        FilteredPolicy(Constant([0.0, 0.0]), SafetyFilter.for_env(env))
