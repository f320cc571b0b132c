"""The one rollout path: recorded trajectories, batch invariance, action scaling."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.baselines.smc import SlidingModeController
from tether_gym_agents.common.obs import ObservationLayout
from tether_gym_agents.evaluation.rollout import RECORDED_KEYS, make_vector_env, rollout

KWARGS = {"orbits_per_episode": 0.1, "initial_theta": (0.0, 0.0), "init_theta_range": 0.15,
          "init_dtheta_range": 0.1, "action_mode": "rate"}


def test_to_reel_rate_inverts_to_action_inside_the_box():
    layout = ObservationLayout(2, 1.0, 0.5)
    rate = np.array([[0.3, -0.45], [0.0, 0.5]])
    np.testing.assert_allclose(layout.to_reel_rate(layout.to_action(rate)), rate, rtol=1e-7)
    np.testing.assert_array_equal(layout.to_reel_rate([[2.0, -3.0]]), [[0.5, -0.5]])


def test_rollout_matches_the_single_env_driven_by_hand():
    venv = make_vector_env(3, KWARGS)
    policy = SlidingModeController.for_env(venv)
    trajs = rollout(policy, [4, 5, 6], env=venv)
    venv.close()
    env = gym.make(tether_gym.ENV_ID, max_episode_steps=-1, **KWARGS)
    obs, info = env.reset(seed=5)
    rows = [info]
    actions = []
    done = False
    while not done:
        action, _ = policy.predict(obs)
        actions.append(action)
        obs, _, terminated, truncated, info = env.step(action)
        rows.append(info)
        done = terminated or truncated
    traj = trajs[1]
    assert traj.seed == 5 and traj.steps == len(actions) and traj.truncated == truncated
    for key in RECORDED_KEYS:
        np.testing.assert_array_equal(getattr(traj, key), np.array([r[key] for r in rows],
                                                                   dtype=float), err_msg=key)
    np.testing.assert_array_equal(traj.action, np.array(actions))
    np.testing.assert_array_equal(traj.command, np.clip(np.array(actions, dtype=float), -1, 1)
                                  * env.unwrapped.config.max_reel_rate)


def test_an_episode_does_not_depend_on_its_neighbours():
    venv1 = make_vector_env(1, KWARGS)
    policy = SlidingModeController.for_env(venv1)
    alone = rollout(policy, [7], env=venv1)[0]
    venv1.close()
    crowd = rollout(policy, [1, 2, 7, 9], KWARGS)[2]
    for key in RECORDED_KEYS + ("action", "reward"):
        np.testing.assert_array_equal(getattr(alone, key), getattr(crowd, key), err_msg=key)


class _Wrong:
    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.zeros((1, 3), dtype=np.float32), None


def test_rollout_rejects_bad_policies():
    with pytest.raises(ValueError, match="2 policies for 3 seeds"):
        rollout([_Wrong(), _Wrong()], [0, 1, 2], KWARGS)
    with pytest.raises(ValueError, match=r"action of shape \(1, 3\)"):
        rollout(_Wrong(), [0], KWARGS)


class _Counter:
    """A batch-invariant policy with memory: its state counts its calls per episode."""

    batch_invariant = True

    def __init__(self):
        self.calls = []

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        b = obs.shape[0]
        count = np.zeros(b) if state is None else np.asarray(state).copy()
        count[np.asarray(episode_start, dtype=bool)] = 0.0
        self.calls.append((b, None if state is None else np.asarray(state).copy(),
                           np.asarray(episode_start, dtype=bool).copy()))
        return np.zeros((b, 2), dtype=np.float32), count + 1.0


def test_recurrent_state_rows_come_back_to_their_episode():
    counter = _Counter()
    kwargs = {**KWARGS, "orbits_per_episode": 0.05}
    trajs = rollout(counter, [0, 1, 2], kwargs)
    assert len(counter.calls) == trajs[0].steps  # one batched call per step
    first, *rest = counter.calls
    assert first[0] == 3 and first[1] is None and first[2].all()
    for k, (b, state, start) in enumerate(rest, start=1):
        assert b == 3 and not start.any()
        np.testing.assert_array_equal(state, [k, k, k])
