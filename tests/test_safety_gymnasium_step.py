"""Safety-Gymnasium's step loop on tether_gym/TetherLibration-v2 (tether_gym.safety_gymnasium).

The loop a safe-RL user writes, ``obs, reward, cost, terminated, truncated, info =
env.step(a)``, on the wrapped env: the cost is ``info["cost"]``, the sum of its parts;
a random reel-rate policy is charged for the slack it runs into before the tether goes
slack and on the step that ends the episode; holding the reels costs nothing; the
wrapper changes nothing else; v1 (no cost) is refused at the reset.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.safety_gymnasium import SafetyGymnasiumStep, SafetyGymnasiumVectorStep
from tether_gym.tasks.cost import COST_LIMIT

PARTS = ("cost_slack", "cost_length", "cost_tumble")
V1_OUT_OF_DATE = "ignore:.*TetherLibration-v1 is out of date:DeprecationWarning"


def _episode(env, seed, policy):
    """One episode of the Safety-Gymnasium loop: a list of (cost, info) per step."""
    obs, info = env.reset(seed=seed)
    assert info["cost"] == 0.0
    steps = []
    while True:
        obs, reward, cost, terminated, truncated, info = env.step(policy(obs))
        steps.append((cost, info))
        if terminated or truncated:
            return steps


def _check_parts(cost, info):
    assert isinstance(cost, float) and np.isfinite(cost)
    assert cost == info["cost"]
    assert all(info[p] in (0.0, 1.0) for p in PARTS)
    assert cost == sum(info[p] for p in PARTS)


def test_random_rate_policy_pays_for_slack_before_it_fails():
    env = SafetyGymnasiumStep(gym.make(tether_gym.ENV_ID, action_mode="rate"))
    rng = np.random.default_rng(1)
    steps = _episode(env, 1, lambda obs: rng.uniform(-1.0, 1.0, env.action_space.shape))
    for cost, info in steps:
        _check_parts(cost, info)
    last_cost, last = steps[-1]
    assert last["failure"] == "slack" and len(steps) < tether_gym.DEFAULT_MAX_EPISODE_STEPS
    assert last_cost >= 1.0 and last["cost_slack"] == 1.0
    warned = sum(info["cost_slack"] for _, info in steps[:-1])
    assert warned >= 1.0  # cost_slack came on before the tether went slack
    assert steps[0][0] == 0.0  # the first steps from a healthy start are free
    total = sum(cost for cost, _ in steps)
    assert total / len(steps) > COST_LIMIT  # over the benchmark's limit


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_holding_the_reels_costs_nothing(seed):
    """Zero increments hold the periodic reel command: the chain stays far from every bound."""
    env = SafetyGymnasiumStep(gym.make(tether_gym.ENV_ID))
    steps = _episode(env, seed, lambda obs: np.zeros(env.action_space.shape))
    assert len(steps) == tether_gym.DEFAULT_MAX_EPISODE_STEPS and steps[-1][1]["failure"] is None
    for cost, info in steps:
        _check_parts(cost, info)
        assert cost == 0.0


def test_wrapper_changes_nothing_but_the_tuple():
    plain = gym.make(tether_gym.ENV_ID, action_mode="rate")
    wrapped = SafetyGymnasiumStep(gym.make(tether_gym.ENV_ID, action_mode="rate"))
    o1, i1 = plain.reset(seed=4)
    o2, i2 = wrapped.reset(seed=4)
    np.testing.assert_array_equal(o1, o2)
    rng = np.random.default_rng(4)
    for _ in range(40):
        a = rng.uniform(-1.0, 1.0, plain.action_space.shape)
        o1, r1, te1, tr1, i1 = plain.step(a)
        o2, r2, c2, te2, tr2, i2 = wrapped.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert (r1, te1, tr1, i1["cost"]) == (r2, te2, tr2, c2)
        assert i1.keys() == i2.keys()


@pytest.mark.filterwarnings(V1_OUT_OF_DATE)
def test_v1_has_no_cost_and_is_refused_at_reset():
    env = SafetyGymnasiumStep(gym.make(tether_gym.ENV_ID_V1))
    with pytest.raises(ValueError, match=r"no 'cost'.*TetherLibration-v2"):
        env.reset(seed=0)


def test_vector_costs_are_the_infos_cost():
    venv = SafetyGymnasiumVectorStep(gym.make_vec(
        tether_gym.ENV_ID, num_envs=6, vectorization_mode="vector_entry_point",
        parallel=False, action_mode="rate"))
    venv.reset(seed=3)
    rng = np.random.default_rng(3)
    charged = 0.0
    for _ in range(150):
        obs, rewards, costs, terminations, truncations, infos = venv.step(
            rng.uniform(-1.0, 1.0, venv.action_space.shape))
        assert costs.shape == (6,) and costs.dtype == np.float64
        np.testing.assert_array_equal(costs, infos["cost"])
        np.testing.assert_array_equal(costs, sum(infos[p] for p in PARTS))
        assert rewards.shape == terminations.shape == truncations.shape == (6,)
        charged += costs.sum()
    assert charged > 0.0


@pytest.mark.filterwarnings(V1_OUT_OF_DATE)
def test_vector_env_without_cost_is_refused():
    venv = SafetyGymnasiumVectorStep(gym.make_vec(
        tether_gym.ENV_ID_V1, num_envs=2, vectorization_mode="vector_entry_point",
        parallel=False))
    with pytest.raises(ValueError, match="no 'cost'"):
        venv.reset(seed=0)
