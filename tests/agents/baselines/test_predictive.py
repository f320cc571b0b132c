"""The one-step predictive law: s decays as designed on the nominal model; registry."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.baselines.prediction import NominalStep, reference_ahead
from tether_gym_agents.baselines.predictive import OneStepPredictive
from tether_gym_agents.evaluation.registry import make_policy
from tether_gym_agents.evaluation.scenarios import RANDOM_INIT, Scenario


def _env(**kwargs):
    return gym.make(tether_gym.ENV_ID, action_mode="rate", **kwargs)


def _predicted_s(law, obs):
    """(s now, s predicted one control step ahead under the law's command) (1, n) each."""
    batch = obs[None].astype(np.float64)
    nu, y = law.layout.state(batch)
    u = law.reel_rate(batch) / law.step.max_reel_rate
    nxt = law.step(nu, y, u).state
    st = law.layout.split(batch)
    th_d, dth_d = reference_ahead(st.theta_ref, st.dtheta_ref, law.layout.frequency,
                                  law.step.control_step)
    n = law.step.n_tethers
    s_next = (nxt[:, n:2 * n] - dth_d[:, None]) + law.c * (nxt[:, :n] - th_d[:, None])
    return law.sliding_variable(batch), s_next


def test_s_decays_by_exp_minus_lambda_dt_near_the_surface():
    """Half an orbit into the paper's case (|s| small, the reels unsaturated), the
    nominal step under the law's command gives s(k+1) = exp(-lam dt) s(k) per tether."""
    env = _env()
    policy = make_policy("predictive", env)
    law = policy.policy
    obs, _ = env.reset(seed=0)
    checked = 0
    for k in range(250):
        obs = env.step(policy.predict(obs)[0])[0]
        if k >= 120 and k % 10 == 0:
            s0, s1 = _predicted_s(law, obs)
            assert np.abs(s0).max() < 0.05
            np.testing.assert_allclose(s1, math.exp(-law.lam * law.step.control_step) * s0,
                                       rtol=1e-6, atol=1e-12)
            checked += 1
    assert checked == 13


def test_far_from_the_surface_s_decreases():
    """At the paper's reset state (s_1 = 0.2, the reels saturate) the predicted |s_1|
    decreases and s_2 stays near zero."""
    env = _env()
    law = OneStepPredictive.for_env(env)
    obs, _ = env.reset(seed=0)
    s0, s1 = _predicted_s(law, obs)
    assert s0[0, 0] == pytest.approx(0.2, abs=1e-6)
    assert abs(s1[0, 0]) < abs(s0[0, 0])
    assert abs(s1[0, 1]) < 0.05


def test_runs_by_name_and_a_batch_equals_its_rows():
    kwargs = dict(RANDOM_INIT, action_mode="rate", orbits_per_episode=0.05)
    env = gym.make(tether_gym.ENV_ID, **kwargs)
    policy = make_policy("predictive", env, Scenario("tiny", "", kwargs))
    assert policy.batch_invariant
    obs = []
    for seed in range(3):
        o, _ = env.reset(seed=seed)
        obs.append(o)
    batch = policy.predict(np.stack(obs))[0]
    for i, o in enumerate(obs):
        assert np.array_equal(policy.predict(o)[0], batch[i])
    o, _ = env.reset(seed=0)
    while True:
        o, _, terminated, truncated, info = env.step(policy.predict(o)[0])
        if terminated or truncated:
            break
    assert truncated and not terminated, info["failure"]


def test_nominal_step_is_the_env_step():
    env = _env(eccentricity=0.1)
    step = NominalStep.for_env(env)
    obs, info = env.reset(seed=2)
    y = np.concatenate([info["theta"], info["dtheta"], info["length"], info["dlength"]])
    u = np.array([0.3, -0.7], dtype=np.float32)
    _, _, _, _, info = env.step(u)
    out = step(np.array([0.0]), y[None], u[None].astype(np.float64))
    env_y = np.concatenate([info["theta"], info["dtheta"], info["length"], info["dlength"]])
    assert np.array_equal(out.state[0], env_y)


def test_reference_ahead_is_the_sine():
    a, w, nu, d = 0.2, 1.3, 0.7, np.array([0.025, 0.5])
    th, dth = reference_ahead(a * np.sin(w * nu), a * w * np.cos(w * nu), w, d)
    np.testing.assert_allclose(th, a * np.sin(w * (nu + d)), atol=1e-15)
    np.testing.assert_allclose(dth, a * w * np.cos(w * (nu + d)), atol=1e-15)
