"""SafetyFilterWrapper: gymnasium's env checker, the info entries, rate mode only; the
filter in the loop (FilterInTheLoop) that it shares with the agents' hybrids."""

from __future__ import annotations

import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import tether_gym
from tether_gym import wrappers
from tether_gym.safety import SafetyFilter
from tether_gym.wrappers import (
    IDLE_INFO,
    INFEASIBLE_WARNING,
    INFO_KEYS,
    FilterInTheLoop,
    SafetyFilterWrapper,
    state_of,
)


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
    env = gym.make(tether_gym.ENV_ID)  # the default: increments of the command
    with pytest.raises(ValueError, match="action_mode='rate'"):
        SafetyFilterWrapper(env)
    env.close()


def test_rejects_a_filter_for_another_number_of_tethers():
    four = gym.make(tether_gym.ENV_ID, n_bodies=4, action_mode="rate")
    env = _env()
    with pytest.raises(ValueError, match="filter is for 3 tethers, the env has 2"):
        SafetyFilterWrapper(env, SafetyFilter.for_env(four))
    with pytest.raises(TypeError, match="TetherLibration"):
        SafetyFilterWrapper(gym.make("Pendulum-v1"))
    env.close()
    four.close()


# -- the filter in the loop ------------------------------------------------------------

def _states(env, rows):
    """(nu (rows,), y (rows, 8)) of the first ``rows`` steps of a filtered full reel-in."""
    env = SafetyFilterWrapper(env)
    _, info = env.reset(seed=0)
    nus, ys = [], []
    for _ in range(rows):
        nu, y = state_of(info)
        nus.append(nu)
        ys.append(y)
        _, _, _, _, info = env.step(np.array([-1.0, 0.0], np.float32))
    return np.array(nus), np.array(ys)


def test_filter_in_the_loop_is_the_filter_with_counters():
    env = _env(initial_lengths=(0.1, 0.9))
    flt = SafetyFilter.for_env(env)
    nu, y = _states(env, 40)
    desired = np.tile([-1.0, 0.0], (40, 1))
    loop = FilterInTheLoop(flt, 2)
    assert np.isnan(loop.filter_rate) and loop.info() == dict(IDLE_INFO)
    out = loop((nu, y), desired)
    res = flt.project(nu, y, desired)
    np.testing.assert_array_equal(out, res.command)
    np.testing.assert_array_equal(loop.last_active, res.active)
    assert 0 < loop.interventions == int(res.active.sum()) < loop.steps == 40
    assert loop.filter_rate == loop.interventions / 40
    i = int(np.flatnonzero(res.active)[0])
    assert loop.info(i) == {"filter_active": True, "filter_correction": float(res.correction[i]),
                            "filter_feasible": bool(res.feasible[i])}
    assert tuple(loop.info(i)) == INFO_KEYS
    loop.reset_counts()
    assert (loop.steps, loop.interventions, loop.infeasible, loop.last_result) == (0, 0, 0, None)
    env.close()


def test_infeasible_commands_warn_once_and_are_counted(monkeypatch):
    monkeypatch.setattr(wrappers, "_WARNED", set())  # once per process: forget earlier tests'
    # row 0 lies near the horizontal (theta = 1.4 rad) with theta' = -1: T^ ~ l (3 cos^2
    # theta - 1) < 0 for every command (a reel-in's -l'' is capped by the acceleration
    # limit); row 1 hangs still and is safe
    env = _env()
    y = np.array([[1.4, 1.4, -1.0, -1.0, 0.5, 0.5, 0.0, 0.0],
                  [0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0]])
    nu, desired = np.zeros(2), np.zeros((2, 2))
    res = SafetyFilter.for_env(env).project(nu, y, desired)
    assert res.feasible.tolist() == [False, True]
    loop = FilterInTheLoop(SafetyFilter.for_env(env), 2)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loop((nu, y), desired)
        loop((nu, y), desired)  # a second infeasible call: counted, not warned again
    assert len(caught) == 1 and INFEASIBLE_WARNING in str(caught[0].message)
    assert issubclass(caught[0].category, UserWarning)
    assert (loop.steps, loop.infeasible) == (4, 2)
    assert loop.info(0)["filter_feasible"] is False and loop.info(1)["filter_feasible"] is True
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loop((nu[1:], y[1:]), desired[1:])  # feasible: no warning
    env.close()


def test_without_a_filter_commands_pass_and_the_state_is_not_read():
    loop = FilterInTheLoop(None, 2)
    command = np.array([[0.3, -2.0]])

    def state():
        raise AssertionError("the state source is read only when there is a filter")

    np.testing.assert_array_equal(loop(state, command), command)
    assert loop.steps == 0 and loop.last_active is None and loop.info() == dict(IDLE_INFO)


def test_filter_in_the_loop_checks_its_filter():
    with pytest.raises(TypeError, match="SafetyFilter or None"):
        FilterInTheLoop("filter", 2)  # type: ignore[arg-type]
    env = _env()
    with pytest.raises(ValueError, match="filter is for 2 tethers, the env has 3"):
        FilterInTheLoop(SafetyFilter.for_env(env), 3)
    env.close()
