"""The GPU learner's pieces against stable-baselines3's: reward scaling."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

import torch  # noqa: E402
from stable_baselines3.common.running_mean_std import RunningMeanStd  # noqa: E402

from tether_gym_agents.accel.ppo import PPOSettings, RunningStats  # noqa: E402
from tether_gym_agents.accel.rollout import scale_rewards  # noqa: E402


def test_scale_rewards_is_vecnormalize_per_seed():
    """Two seeds of 5 envs over 40 steps: each seed's rewards scaled as VecNormalize does."""
    s = PPOSettings(gamma=0.9, clip_reward=1.0)
    rng = np.random.default_rng(0)
    rew = rng.normal(2.0, 5.0, (40, 2, 5))
    done = rng.random((40, 2, 5)) < 0.1
    stats, returns = RunningStats(2, 1, "cpu"), torch.zeros((2, 5), dtype=torch.float64)
    sb3 = [(RunningMeanStd(shape=()), np.zeros(5)) for _ in range(2)]
    clipped = unclipped = 0
    for t in range(40):
        got, returns = scale_rewards(torch.as_tensor(rew[t]), torch.as_tensor(done[t]),
                                     returns, stats, s)
        for k, (rms, ret) in enumerate(sb3):
            # stable_baselines3.common.vec_env.VecNormalize.step_wait / normalize_reward
            ret[:] = ret * s.gamma + rew[t, k]
            rms.update(ret)
            want = np.clip(rew[t, k] / np.sqrt(rms.var + s.norm_epsilon), -s.clip_reward,
                           s.clip_reward)
            ret[done[t, k]] = 0.0
            np.testing.assert_allclose(got[k].numpy(), want, rtol=1e-12)
            np.testing.assert_allclose(returns[k].numpy(), ret, rtol=1e-12, atol=0)
        at_clip = int((np.abs(got.numpy()) == s.clip_reward).sum())
        clipped, unclipped = clipped + at_clip, unclipped + got.numel() - at_clip
    assert clipped > 0 and unclipped > 0  # both branches of the clip were compared
