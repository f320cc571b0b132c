"""SafetyFilterWrapper: gymnasium's env checker, the info entries, rate mode only."""

from __future__ import annotations

import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tether_gym
from tether_gym.wrappers import INFO_KEYS, SafetyFilterWrapper, state_of


def _env(**kwargs):
    return gym.make(tether_gym.ENV_ID, orbits_per_episode=0.2, action_mode="rate", **kwargs)


# the env's own (tests/envs/conftest.py: theta' and l' are unbounded), and the checker's
# advice to check the unwrapped env: here the wrapper is what is checked
ALLOWED = (r"A Box observation space (minimum|maximum) value is -?infinity",
           r"is different from the unwrapped version")


def test_passes_check_env_without_unexpected_warnings():
    env = SafetyFilterWrapper(_env())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    bad = [str(w.message) for w in caught
           if not any(re.search(rx, str(w.message)) for rx in ALLOWED)]
    assert bad == []
    env.close()


def test_info_reports_the_filter_and_unsafe_actions_are_changed():
    env = SafetyFilterWrapper(_env(initial_lengths=(0.1, 0.9)))
    obs, info = env.reset(seed=0)
    assert (info["filter_active"], info["filter_correction"], info["filter_feasible"]) == (
        False, 0.0, True)
    active = []
    for _ in range(40):  # reel tether 1 in at full rate towards its 0.05 bound
        obs, _, terminated, truncated, info = env.step(np.array([-1.0, 0.0], np.float32))
        assert set(INFO_KEYS) <= set(info)
        assert isinstance(info["filter_active"], bool)
        assert isinstance(info["filter_correction"], float)
        assert isinstance(info["filter_feasible"], bool)
        active.append(info["filter_active"])
        assert info["failure"] is None
    assert any(active)
    res = env.last_result
    assert res is not None and res.command[0, 0] > -1.0
    env.close()


def test_safe_actions_pass_unchanged():
    env = SafetyFilterWrapper(_env())
    _, info = env.reset(seed=0)
    action = np.array([0.1, -0.1], np.float32)
    assert env.action(action) is action
    env.close()


def test_state_of_reads_the_true_state():
    env = _env()
    _, info = env.reset(seed=0)
    nu, y = state_of(info)
    assert nu == info["nu"] and y.shape == (8,)
    np.testing.assert_array_equal(y[4:6], info["length"])
    env.close()


def test_rejects_other_action_modes():
    env = gym.make(tether_gym.ENV_ID)  # v1's default: increments of the command
    with pytest.raises(ValueError, match="action_mode='rate'"):
        SafetyFilterWrapper(env)
    env.close()
