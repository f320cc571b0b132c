"""v2 is v1 plus the cost entries of info: everything else bitwise the same."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.tasks.cost import COST_NAMES

pytestmark = pytest.mark.filterwarnings("ignore:.*is out of date")

KWARGS = {"init_theta_range": 0.15, "eccentricity_range": (0.0, 0.35), "disturbance": 0.1,
          "obs_noise": 0.001, "mass_range": 0.25}


def test_v1_and_v2_return_the_same_but_the_cost():
    v1 = gym.make(tether_gym.ENV_ID_V1, **KWARGS)
    v2 = gym.make(tether_gym.ENV_ID, **KWARGS)
    rng = np.random.default_rng(0)
    for seed in (0, 1):
        o1, i1 = v1.reset(seed=seed)
        o2, i2 = v2.reset(seed=seed)
        steps = 0
        while True:
            assert np.array_equal(o1, o2)
            assert set(i2) - set(i1) == set(COST_NAMES) and set(i1) <= set(i2)
            for key in i1:
                np.testing.assert_array_equal(np.asarray(i1[key]), np.asarray(i2[key]))
            a = rng.uniform(-1, 1, 2)
            o1, r1, t1, u1, i1 = v1.step(a)
            o2, r2, t2, u2, i2 = v2.step(a)
            assert (r1, t1, u1) == (r2, t2, u2)
            steps += 1
            if t1 or u1:
                break
        assert steps > 10


def test_the_vector_envs_differ_only_by_the_cost():
    v1 = gym.make_vec(tether_gym.ENV_ID_V1, num_envs=4, vectorization_mode="vector_entry_point")
    v2 = gym.make_vec(tether_gym.ENV_ID, num_envs=4, vectorization_mode="vector_entry_point")
    _, i1 = v1.reset(seed=5)
    _, i2 = v2.reset(seed=5)
    for _ in range(30):
        a = np.full((4, 2), 0.3)
        o1, r1, _, _, i1 = v1.step(a)
        o2, r2, _, _, i2 = v2.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
    extra = set(i2) - set(i1)
    assert extra == set(COST_NAMES) | {"_" + k for k in COST_NAMES}
    assert i2["cost"].shape == (4,)


def test_v1_refuses_the_cost_argument_and_is_marked_out_of_date():
    with pytest.raises(ValueError, match="argument of tether_gym/TetherLibration-v2"):
        gym.make(tether_gym.ENV_ID_V1, cost_thresholds={"tension": 0.3})
    assert tether_gym.ENV_ID.endswith("-v2")
