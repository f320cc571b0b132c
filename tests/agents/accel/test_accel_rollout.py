"""The GPU learner's rollout against stable-baselines3's: reward scaling, the truncation
bootstrap, GAE."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

import torch  # noqa: E402
from stable_baselines3.common.running_mean_std import RunningMeanStd  # noqa: E402

from tether_gym_agents.accel.ppo import MultiSeedPolicy, PPOSettings, RunningStats  # noqa: E402
from tether_gym_agents.accel.rollout import Rollout, normalize, scale_rewards  # noqa: E402


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


@torch.no_grad()  # as train_seeds runs the rollout
def test_rollout_bootstraps_truncations_and_computes_sb3s_gae():
    """Four steps of 2 seeds x 3 envs on made-up env steps. Each step's recorded reward is
    the scaled reward plus gamma V(final obs) on the truncated rows only (SB3's PPO
    ``collect_rollouts``); the advantages and returns are SB3's ``RolloutBuffer``'s
    (``compute_returns_and_advantage``) on the same rewards, values and starts, per seed."""
    import copy

    from gymnasium import spaces
    from stable_baselines3.common.buffers import RolloutBuffer

    S, N, T, d, a = 2, 3, 4, 5, 2
    s = PPOSettings(n_envs=N, n_steps=T, gamma=0.9, gae_lambda=0.8, net_arch=(8,),
                    log_std_init=-1.0)
    torch.manual_seed(0)
    policy = MultiSeedPolicy([0, 1], d, a, s, "cpu")
    rollout = Rollout(policy, s, d, a, "cpu")
    g = torch.Generator().manual_seed(4)
    rollout.start(torch.randn((S * N, d), generator=g, dtype=torch.float64))
    term = torch.tensor([[0, 0, 1, 0, 0, 0], [0, 0, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0],
                         [0, 0, 0, 0, 0, 0]], dtype=torch.bool)
    trunc = torch.tensor([[0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 1], [0, 0, 0, 0, 0, 0],
                          [0, 1, 0, 0, 0, 0]], dtype=torch.bool)
    for t in range(T):
        rollout.act()
        raw = torch.randn((S * N, d), generator=g, dtype=torch.float64)
        rew = torch.randn(S * N, generator=g, dtype=torch.float64)
        final = torch.randn((S * N, d), generator=g, dtype=torch.float64)
        rollout.take(raw, rew, term[t], trunc[t], final)
        ret_stats, returns = copy.deepcopy(rollout.ret_stats), rollout.returns.clone()
        scaled, _ = scale_rewards(rew.view(S, N), (term[t] | trunc[t]).view(S, N), returns,
                                  ret_stats, s)
        rollout.observe()
        # the statistics observe() folded the new observations into normalise final_obs
        boot = s.gamma * policy.value(normalize(final.view(S, N, d), rollout.obs_stats, s))
        want = scaled + torch.where(trunc[t].view(S, N), boot.double(), 0.0)
        assert torch.allclose(rollout.buf_rew[t], want.float(), rtol=1e-6, atol=1e-7)
        assert (rollout.buf_rew[t] != scaled.float()).sum() == int(trunc[t].sum())
    last_val = policy.value(rollout.obs)
    rollout.finish()
    for k in range(S):
        buf = RolloutBuffer(T, spaces.Box(-1, 1, (d,)), spaces.Box(-1, 1, (a,)), "cpu",
                            gae_lambda=s.gae_lambda, gamma=s.gamma, n_envs=N)
        for t in range(T):
            buf.add(rollout.buf_obs[t, k].numpy(), rollout.buf_act[t, k].numpy(),
                    rollout.buf_rew[t, k].numpy(), rollout.buf_start[t, k].numpy(),
                    rollout.buf_val[t, k], rollout.buf_logp[t, k])
        buf.compute_returns_and_advantage(last_val[k], rollout.episode_start[k].numpy())
        np.testing.assert_allclose(rollout.batch.adv[k].view(T, N).numpy(), buf.advantages,
                                   rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(rollout.batch.ret[k].view(T, N).numpy(), buf.returns,
                                   rtol=1e-5, atol=1e-6)
    assert rollout.buf_start[1:].sum() == int((term | trunc)[:-1].sum())
    assert int(rollout.t) == 0


@torch.no_grad()
def test_the_action_draws_are_normal_samples():
    """:meth:`Rollout.act` draws eagerly and makes the actions of the draws: the actions
    are bitwise ``Normal(mean, std).sample()`` from the same generator state, their
    log-probabilities and values the distribution's and the value net's."""
    S, N, d, a = 2, 5, 4, 3
    s = PPOSettings(n_envs=N, n_steps=2, net_arch=(8,), log_std_init=-1.0)
    policy = MultiSeedPolicy([5, 6], d, a, s, "cpu")
    rollout = Rollout(policy, s, d, a, "cpu")
    rollout.start(torch.randn((S * N, d), dtype=torch.float64))
    torch.manual_seed(11)
    rollout.act()
    dist = policy.distribution(rollout.obs)
    torch.manual_seed(11)
    want = dist.sample()
    assert torch.equal(rollout.buf_act[0], want)
    assert torch.equal(rollout.buf_logp[0], dist.log_prob(want).sum(-1))
    assert torch.equal(rollout.buf_val[0], policy.value(rollout.obs))
    assert torch.equal(rollout.action, torch.clamp(want, -1.0, 1.0))
    assert torch.equal(rollout.buf_obs[0], rollout.obs) and int(rollout.t) == 0


def _rollout_run(compiled: bool, shared: bool = False):
    """Two iterations of 6 steps, 2 seeds x 4 envs, on made-up env steps with ended and
    truncated rows; the rollout's state and batch after them. The observations are
    float32 values, as the env's. ``shared``: the rollout reads made-up env tensors in
    place (:meth:`Rollout.share`: float32 observations, a float64 action input) that
    each step writes, instead of :meth:`Rollout.take`'s copies."""
    S, N, T, d, a = 2, 4, 6, 5, 2
    s = PPOSettings(n_envs=N, n_steps=T, gamma=0.9, gae_lambda=0.8, net_arch=(8, 8),
                    log_std_init=-1.0)
    policy = MultiSeedPolicy([1, 2], d, a, s, "cpu")
    rollout = Rollout(policy, s, d, a, "cpu", compiled=compiled)
    env = (torch.zeros((S * N, d)), torch.zeros(S * N, dtype=torch.float64),
           torch.zeros(S * N, dtype=torch.bool), torch.zeros(S * N, dtype=torch.bool),
           torch.zeros((S * N, d)), torch.zeros((S * N, a), dtype=torch.float64))
    if shared:
        rollout.share(*env)
    g = torch.Generator().manual_seed(3)
    torch.manual_seed(7)

    def observation() -> torch.Tensor:
        return (3.0 * torch.randn((S * N, d), generator=g, dtype=torch.float64)).float()

    rollout.start(observation().double())
    for _ in range(2):
        for _ in range(T):
            rollout.act()
            raw = observation()
            rew = torch.randn(S * N, generator=g, dtype=torch.float64)
            ended = torch.rand(S * N, generator=g) < 0.3
            trunc = ended & (torch.rand(S * N, generator=g) < 0.5)
            final = torch.randn((S * N, d), generator=g, dtype=torch.float64).float()
            step = (raw, rew, ended & ~trunc, trunc, final)
            if shared:  # the env writes its step where it always does
                for dst, src in zip(env, step, strict=False):
                    dst.copy_(src)
                assert torch.equal(env[5], rollout.action.view(S * N, a))  # act wrote it
            else:
                rollout.take(*step)
            rollout.observe()
        rollout.finish()
    stats = (rollout.obs_stats.mean, rollout.obs_stats.var, rollout.obs_stats.count,
             rollout.ret_stats.mean, rollout.ret_stats.var, rollout.returns, rollout.ep_ret,
             rollout.done_eps, rollout.done_fail, rollout.done_ret)
    return ([x.clone() for x in stats], [x.clone() for x in rollout.batch.tensors()],
            [x.clone() for x in (rollout.obs, rollout.action, rollout.episode_start)],
            int(rollout.t))


@pytest.mark.slow
@torch.no_grad()
def test_the_compiled_rollout_is_the_eager_one():
    """``compiled=True`` (``train.py gpu --compile-rollout``; Inductor on the CPU): after
    two iterations the statistics and counts (float64) equal the eager rollout's to
    1e-12, the batch, observations and actions (float32) to float32 rounding, the start
    flags and ``t`` exactly; and the three pieces ran compiled."""
    from torch._dynamo.utils import counters

    torch._dynamo.reset()
    before = counters["stats"]["unique_graphs"]
    want = _rollout_run(compiled=False)
    got = _rollout_run(compiled=True)
    assert counters["stats"]["unique_graphs"] - before >= 3  # record, observe, finish
    for x, y in zip(got[0], want[0], strict=True):
        torch.testing.assert_close(x, y, rtol=1e-12, atol=1e-12)
    assert float(want[0][7].sum()) > 0 and float(want[0][8].sum()) > 0  # episodes ended
    for x, y in zip(got[1] + got[2][:2], want[1] + want[2][:2], strict=True):
        torch.testing.assert_close(x, y, rtol=1e-5, atol=1e-5 * float(y.abs().max()))
    assert torch.equal(got[2][2], want[2][2]) and got[3] == want[3] == 0


@torch.no_grad()
def test_a_shared_rollout_is_the_copying_one():
    """:meth:`Rollout.share` (as ``RolloutStep`` uses it: no copies of the env's step,
    the actions written into the env's float64 input): two iterations end with bitwise
    the statistics, counts, batch, observations and start flags of :meth:`Rollout.take`'s
    copies, and the actions cast exactly."""
    want = _rollout_run(compiled=False)
    got = _rollout_run(compiled=False, shared=True)
    for x, y in zip(got[0] + got[1], want[0] + want[1], strict=True):
        assert x.dtype == y.dtype and torch.equal(x, y)
    (obs, act, start), (obs0, act0, start0) = got[2], want[2]
    assert act.dtype == torch.float64 and act0.dtype == torch.float32
    assert torch.equal(obs, obs0) and torch.equal(act, act0.double())
    assert torch.equal(start, start0) and got[3] == want[3] == 0
    assert float(want[0][7].sum()) > 0  # episodes ended


def test_share_refuses_wrong_tensors_and_take_after_it():
    S, N, d, a = 2, 3, 4, 2
    s = PPOSettings(n_envs=N, n_steps=2, net_arch=(8,))
    rollout = Rollout(MultiSeedPolicy([0, 1], d, a, s, "cpu"), s, d, a, "cpu")
    good = [torch.zeros((S * N, d)), torch.zeros(S * N, dtype=torch.float64),
            torch.zeros(S * N, dtype=torch.bool), torch.zeros(S * N, dtype=torch.bool),
            torch.zeros((S * N, d)), torch.zeros((S * N, a), dtype=torch.float64)]
    bad = list(good)
    bad[5] = torch.zeros((S * N, a + 1), dtype=torch.float64)
    with pytest.raises(ValueError, match=r"action must have shape \(6, 2\) on cpu, got "
                                         r"\(6, 3\)"):
        rollout.share(*bad)
    rollout.share(*good)
    with pytest.raises(RuntimeError, match="take\\(\\) after share\\(\\)"):
        rollout.take(*good[:5])
