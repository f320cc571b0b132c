"""The command update of tether_gym.envs.actions: one copy, the env's and Python's."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.envs.actions import RATE, next_command, require_rate_mode


@pytest.mark.parametrize("mode", ["increment", "rate"])
def test_python_callers_get_the_command_the_env_sets(mode):
    """Called with numpy arrays, next_command gives bit for bit the env's u (info)."""
    env = gym.make(tether_gym.ENV_ID, action_mode=mode, increment_gain=0.3,
                   orbits_per_episode=0.1)
    _, info = env.reset(seed=4)
    rng = np.random.default_rng(4)
    for _ in range(25):
        action = rng.uniform(-1.5, 1.5, 2).astype(np.float32)  # clipped by the env too
        expected = next_command(info["command"], action.astype(np.float64),
                                mode == "increment", 0.3)
        _, _, terminated, truncated, info = env.step(action)
        assert info["command"].tobytes() == expected.tobytes()
        assert not terminated
    env.close()


def test_the_update_on_scalars_and_batches():
    assert next_command(0.5, 2.0, True, 0.25) == 0.75
    assert next_command(0.9, 1.0, True, 0.25) == 1.0
    assert next_command(0.9, -3.0, False, 0.25) == -1.0
    u = np.array([[0.0, -1.0], [0.5, 0.25]])
    a = np.array([[1.0, -1.0], [-4.0, 0.5]])
    np.testing.assert_array_equal(next_command(u, a, True, 0.5), [[0.5, -1.0], [0.0, 0.5]])
    np.testing.assert_array_equal(next_command(u, a, False, 0.5), np.clip(a, -1, 1))


def test_require_rate_mode():
    require_rate_mode(RATE, "X")
    with pytest.raises(ValueError, match=r"X commands reel rates, but the env has "
                                         r"action_mode='increment'.*action_mode='rate'"):
        require_rate_mode("increment", "X")
