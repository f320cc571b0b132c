"""FilteredPolicy, ResidualPolicy and HandoverPolicy: SB3's evaluate_policy, the filter's
effect, the handover rule, batch invariance and the filter_rate metric of the rollouts."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

import tether_gym
from tether_gym.safety import SafetyFilter
from tether_gym_agents import SlidingModeController
from tether_gym_agents.common.obs import ObservationLayout
from tether_gym_agents.evaluation.metrics import METRICS, episode_metrics
from tether_gym_agents.evaluation.rollout import rollout
from tether_gym_agents.hybrids.policies import (
    FilteredPolicy,
    HandoverPolicy,
    ResidualPolicy,
)

SHORT = {"orbits_per_episode": 0.1, "action_mode": "rate"}


@pytest.fixture
def env():
    e = Monitor(gym.make(tether_gym.ENV_ID, **SHORT))  # evaluate_policy asks for it
    yield e
    e.close()


class Constant:
    """A policy (or residual model) with a fixed action."""

    batch_invariant = True

    def __init__(self, action):
        self.action = np.asarray(action, dtype=np.float32)

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(observation)
        return (np.broadcast_to(self.action, obs.shape[:-1] + self.action.shape).copy(),
                None)


def test_the_observed_state_matches_the_info(env):
    obs, info = env.reset(seed=1)
    nu, y = ObservationLayout.from_env(env).state(obs[None])
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
    assert not policy.last_filter_active.any() and np.array_equal(a, b) and a.dtype == b.dtype


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


class Increments(Constant):
    """A constant 'learned' policy recorded as trained in increment mode."""

    def __init__(self, action, gain=0.5):
        super().__init__(action)
        self.env_kwargs = {"action_mode": "increment", "increment_gain": gain}


def test_handover_runs_the_learned_increments_as_the_increment_env_would():
    """Never handing over, the hybrid in a rate-mode env replays the increment env."""
    kwargs = {"orbits_per_episode": 0.1, "init_theta_range": 0.1, "max_episode_steps": -1}
    learned = Increments([0.3, -0.2])
    inc = rollout(learned, [3], {**kwargs, "action_mode": "increment",
                                 "increment_gain": 0.5})[0]
    env = gym.make(tether_gym.ENV_ID, action_mode="rate", **kwargs)
    never = HandoverPolicy(learned, SlidingModeController.for_env(env), enter=1e-12)
    rate = rollout(never, [3], {**kwargs, "action_mode": "rate"})[0]
    np.testing.assert_allclose(rate.command, inc.command, atol=1e-7)
    np.testing.assert_allclose(rate.theta, inc.theta, atol=1e-7)
    assert not never.last_mode.any()
    env.close()


def test_handover_hands_over_once_and_for_good(env):
    smc = SlidingModeController.for_env(env)
    policy = HandoverPolicy(Increments([1.0, -1.0]), smc, enter=1e3, command_bound=1.0)
    obs, _ = env.reset(seed=0)
    a, mode = policy.predict(obs[None], episode_start=np.array([True]))
    assert mode.tolist() == [1.0] and np.array_equal(a, smc.predict(obs[None])[0])
    strict = HandoverPolicy(Increments([1.0, -1.0]), smc, enter=1e-12)
    a, mode = strict.predict(obs[None], state=np.array([1.0]),
                             episode_start=np.array([False]))
    assert mode.tolist() == [1.0] and np.array_equal(a, smc.predict(obs[None])[0])
    a, mode = strict.predict(obs[None], state=np.array([1.0]),
                             episode_start=np.array([True]))
    u = ObservationLayout.from_env(env).split(obs[None]).command
    assert mode.tolist() == [0.0]
    np.testing.assert_allclose(a, np.clip(u + 0.5 * np.array([1.0, -1.0]), -1, 1), atol=1e-7)


def test_handover_rule_is_the_boundary_layer_and_an_unsaturated_command(env):
    smc = SlidingModeController.for_env(env)
    policy = HandoverPolicy(Increments([0.0, 0.0]), smc)
    assert policy.enter == smc.eps / 2 and policy.command_bound == 0.5
    venv = gym.make_vec(tether_gym.ENV_ID, num_envs=32, vectorization_mode="vector_entry_point",
                        action_mode="rate", init_theta_range=0.1, init_dtheta_range=0.1)
    obs, _ = venv.reset(seed=2)
    _, mode = policy.predict(obs)
    s = np.abs(smc.sliding_variable(obs)).max(axis=1)
    u = np.abs(smc.predict(obs)[0]).max(axis=1)
    np.testing.assert_array_equal(mode > 0.5, (s <= smc.eps / 2) & (u <= 0.5))
    assert 0 < mode.sum() < 32  # the draw exercises both branches
    venv.close()


@pytest.mark.parametrize("kind", ["smc", "filtered", "residual", "handover"])
def test_rows_do_not_depend_on_the_batch(kind):
    venv = gym.make_vec(tether_gym.ENV_ID, num_envs=24, vectorization_mode="vector_entry_point",
                        action_mode="rate", init_theta_range=0.3, init_dtheta_range=0.2,
                        initial_lengths=(0.06, 0.9))
    obs, _ = venv.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(20):
        obs, *_ = venv.step(rng.uniform(-1, 1, (24, 2)).astype(np.float32))
    smc = SlidingModeController.for_env(venv)
    flt = SafetyFilter.for_env(venv)
    layout = ObservationLayout.from_env(venv)
    policy = {"smc": smc, "filtered": FilteredPolicy(Constant([-1.0, 0.5]), flt, layout),
              "residual": ResidualPolicy(smc, Increments([0.4, -0.4]), 0.2, flt),
              "handover": HandoverPolicy(Increments([0.4, -0.4]), smc, flt)}[kind]
    assert policy.batch_invariant
    state = (rng.uniform(size=24) > 0.5).astype(float)
    whole, _ = policy.predict(obs, state=state, episode_start=np.zeros(24, bool))
    flags = getattr(policy, "last_filter_active", None)
    for i in range(24):
        alone, _ = policy.predict(obs[i:i + 1], state=state[i:i + 1],
                                  episode_start=np.zeros(1, bool))
        assert np.array_equal(alone[0], whole[i]), i
    if flags is not None:
        assert 0 < flags.sum() < 24  # the filter acted on some rows only
    venv.close()


def test_handover_under_evaluate_policy(env):
    policy = HandoverPolicy(Increments([0.1, 0.1]), SlidingModeController.for_env(env),
                            SafetyFilter.for_env(env))
    mean, _ = evaluate_policy(policy, env, n_eval_episodes=2, deterministic=True)
    assert np.isfinite(mean) and policy.steps == 2 * env.unwrapped.max_episode_steps


def test_handover_validation(env):
    smc = SlidingModeController.for_env(env)
    with pytest.raises(ValueError, match="enter"):
        HandoverPolicy(Increments([0.0, 0.0]), smc, enter=0.0)
    with pytest.raises(ValueError, match="command_bound"):
        HandoverPolicy(Increments([0.0, 0.0]), smc, command_bound=1.5)
    with pytest.raises(TypeError, match="SlidingModeController"):
        HandoverPolicy(Increments([0.0, 0.0]), Constant([0.0, 0.0]))
    with pytest.raises(TypeError, match="predict"):
        HandoverPolicy(object(), smc)
