"""The rollout of ``train.py gpu`` on the device: its state, its two halves of a step, its GAE.

A rollout step is the policy's half (:meth:`Rollout.act`: sample the action, record
the step), the env's step, and the learner's half (:meth:`Rollout.observe`: normalise
the observation and the reward, bootstrap truncated episodes, count the episodes
ended). After ``n_steps`` of them, :meth:`Rollout.finish` computes the advantages
and fills the :class:`RolloutBatch` that the minibatch steps read. All three read and
write only tensors that stay in the same storage for the whole run: this object's,
the policy's weights and the normalisation statistics, each updated in place. The
step index ``t`` is a tensor too. So each of the three can be captured as a CUDA graph
and replayed (:mod:`.graphs`, ``train.py gpu --cuda-graphs``), and called eagerly
they compute exactly what they compute in a graph. With ``compiled`` (``train.py gpu
--compile-rollout``) the three run through ``torch.compile``, the action draws aside.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from .ppo import MultiSeedPolicy, PPOSettings, RunningStats

__all__ = ["Rollout", "RolloutBatch", "normalize", "scale_rewards"]


def normalize(obs: torch.Tensor, stats: RunningStats, s: PPOSettings) -> torch.Tensor:
    """VecNormalize's observation formula, per seed: clip((x - mean) / sqrt(var + eps))."""
    x = (obs.to(stats.mean.dtype) - stats.mean[:, None, :]) \
        / torch.sqrt(stats.var[:, None, :] + s.norm_epsilon)
    return torch.clamp(x, -s.clip_obs, s.clip_obs).to(torch.float32)


def scale_rewards(rew, done, returns, stats: RunningStats, s: PPOSettings):
    """VecNormalize's reward scaling, per seed: (scaled rewards, updated returns).

    rew, done, returns (S, N): the running discounted return takes the step's reward,
    its statistics ``stats`` (S, 1) are updated, the reward is divided by the return's
    standard deviation and clipped to +-``clip_reward``, and ended rows' returns restart.
    """
    returns = returns * s.gamma + rew
    stats.update(returns[..., None])
    scale = torch.sqrt(stats.var[:, :1] + s.norm_epsilon)
    scaled = torch.clamp(rew / scale, -s.clip_reward, s.clip_reward)
    return scaled, torch.where(done, torch.zeros_like(returns), returns)


class RolloutBatch:
    """One iteration's samples per seed, flattened (S, T N, ...), in tensors kept for the run.

    The minibatch steps read them where they are: a captured CUDA graph
    (:class:`~.graphs.GraphedUpdate`) reads them again at every replay, so
    :meth:`fill` writes each rollout into the same storage.
    """

    def __init__(self, T: int, S: int, N: int, d: int, a: int, device):
        M = T * N
        self.T, self.N = T, N
        self.obs = torch.zeros((S, M, d), device=device)
        self.act = torch.zeros((S, M, a), device=device)
        self.logp = torch.zeros((S, M), device=device)
        self.adv = torch.zeros((S, M), device=device)
        self.ret = torch.zeros((S, M), device=device)

    def tensors(self) -> tuple[torch.Tensor, ...]:
        """(obs, act, old log-prob, advantage, return), as the minibatch step takes them."""
        return self.obs, self.act, self.logp, self.adv, self.ret

    def fill(self, obs, act, old_logp, adv, ret) -> None:
        """Copy a rollout's buffers (T, S, N, ...) in, seed-major, (time, env) order."""
        for dst, src in zip(self.tensors(), (obs, act, old_logp, adv, ret), strict=True):
            S = src.shape[1]
            dst.view(S, self.T, self.N, *src.shape[3:]).copy_(src.transpose(0, 1))


class Rollout:
    """``n_steps`` steps of ``S`` seeds x ``N`` envs on the device (SB3's PPO rollout).

    SB3's rollout with VecNormalize's observation and reward normalisation, per seed.

    Parameters
    ----------
    policy : MultiSeedPolicy
        The policy whose actions are sampled.
    settings : PPOSettings
        gamma, GAE lambda, normalisation constants, ``n_steps``.
    obs_dim, act_dim : int
        Observation and action sizes of one env.
    device : torch.device
        Where every tensor lives.
    compiled : bool
        Run :meth:`record_step`, :meth:`observe_step` and :meth:`finish_step` through
        ``torch.compile`` (``train.py gpu --compile-rollout``; default False). The
        action draws stay eager (:meth:`draw`), so a seed draws the same numbers
        compiled or not; the arithmetic equals the eager one to float32 rounding
        (Inductor fuses and reorders it). Each compiles at its first call.

    Attributes
    ----------
    obs_stats, ret_stats : RunningStats
        The observation (S, d) and discounted-return (S, 1) statistics.
    action : torch.Tensor
        (S, N, act) float32: the clipped action :meth:`act` chose, for the env's step
        (after :meth:`share`, a view of the env's own action input, in its dtype).
    raw, rew, term, trunc, final_obs : torch.Tensor
        The env's step, copied in by :meth:`take` for :meth:`observe` (after
        :meth:`share`, the env's own tensors): raw observations (S N, d) and rewards
        (S N,), ended flags (S N,) [bool], and the last observations of the episodes
        that ended (S N, d).
    done_eps, done_fail, done_ret : torch.Tensor
        Per seed since the last :meth:`clear_counts`: episodes ended, episodes failed
        (terminated) and the sum of their raw returns.
    """

    def __init__(self, policy: MultiSeedPolicy, settings: PPOSettings, obs_dim: int,
                 act_dim: int, device, compiled: bool = False):
        S, N, T = len(policy.seeds), settings.n_envs, settings.n_steps
        d, a = obs_dim, act_dim
        f64 = torch.float64
        self.policy, self.settings = policy, settings
        self.obs_stats = RunningStats(S, d, device)
        self.ret_stats = RunningStats(S, 1, device)
        self.t = torch.zeros(1, dtype=torch.int64, device=device)
        self.obs = torch.zeros((S, N, d), device=device)
        self.episode_start = torch.ones((S, N), dtype=torch.bool, device=device)
        self.returns = torch.zeros((S, N), dtype=f64, device=device)
        self.action = torch.zeros((S, N, a), device=device)
        self.raw = torch.zeros((S * N, d), dtype=f64, device=device)
        self.rew = torch.zeros(S * N, dtype=f64, device=device)
        self.term = torch.zeros(S * N, dtype=torch.bool, device=device)
        self.trunc = torch.zeros(S * N, dtype=torch.bool, device=device)
        self.final_obs = torch.zeros((S * N, d), dtype=f64, device=device)
        self.buf_obs = torch.zeros((T, S, N, d), device=device)
        self.buf_act = torch.zeros((T, S, N, a), device=device)
        self.buf_logp = torch.zeros((T, S, N), device=device)
        self.buf_val = torch.zeros((T, S, N), device=device)
        self.buf_rew = torch.zeros((T, S, N), device=device)
        self.buf_start = torch.zeros((T, S, N), device=device)
        self.ep_ret = torch.zeros((S, N), dtype=f64, device=device)
        self.done_eps = torch.zeros(S, device=device)
        self.done_fail = torch.zeros(S, device=device)
        self.done_ret = torch.zeros(S, dtype=f64, device=device)
        self.batch = RolloutBatch(T, S, N, d, a, device)
        self._shared = False
        self._record: Callable[[torch.Tensor], None] = self.record_step
        self._observe: Callable[[], None] = self.observe_step
        self._finish: Callable[[], None] = self.finish_step
        if compiled:  # each compiled at its first call, fused by Inductor
            self._record, self._observe, self._finish = (
                torch.compile(f, fullgraph=True, dynamic=False)
                for f in (self.record_step, self.observe_step, self.finish_step))

    def start(self, raw: torch.Tensor) -> None:
        """The first observations (S N, d) of the run: into the statistics, normalised."""
        S, N, d = self.obs.shape
        obs_raw = raw.view(S, N, d)
        self.obs_stats.update(obs_raw)
        self.obs.copy_(normalize(obs_raw, self.obs_stats, self.settings))

    def act(self) -> None:
        """Sample each env's action and record the step at ``t``.

        The standard normal draws come first (:meth:`draw`, eager), then
        :meth:`record_step` (compiled with ``compiled``) makes the actions of them.
        """
        self._record(self.draw())

    def draw(self) -> torch.Tensor:
        """The step's standard normal draws (S, N, act) from torch's default generator.

        ``torch.distributions.Normal.sample`` draws the same numbers (``normal_(0, 1)``
        of the output, then times the scale plus the mean): tested equal.
        """
        return torch.randn(self.action.shape, device=self.action.device)

    def record_step(self, noise: torch.Tensor) -> None:
        """The actions mean + std ``noise``, their records at row ``t``, the clipped action.

        The observation, action, start flag, log-probability and value go into the
        buffers at row ``t``; the clipped action into :attr:`action`.
        """
        policy, t = self.policy, self.t
        dist = policy.distribution(self.obs)
        act = noise * dist.scale + dist.loc  # Normal.sample's arithmetic on its draws
        self.buf_obs.index_copy_(0, t, self.obs[None])
        self.buf_act.index_copy_(0, t, act[None])
        self.buf_start.index_copy_(0, t, self.episode_start.float()[None])
        self.buf_logp.index_copy_(0, t, dist.log_prob(act).sum(-1)[None])
        self.buf_val.index_copy_(0, t, policy.value(self.obs)[None])
        self.action.copy_(torch.clamp(act, -1.0, 1.0))

    def share(self, raw, rew, term, trunc, final_obs, action) -> None:
        """Read the env's step where the env writes it, and act where the env reads.

        ``raw`` .. ``final_obs``: the env's own tensors that a same-step autoreset step
        leaves its step in (``TorchTetherVecEnv.obs`` and ``outputs``: (S N, d),
        (S N,), ...); ``action``: its action input (S N, act). From then on
        :meth:`observe` reads the first five where they are, instead of :meth:`take`'s
        copies of them, and :meth:`act` writes the clipped actions into ``action`` (cast
        to its dtype): six copies fewer per rollout step, and the same numbers (a copy
        and a cast are exact). Call it once, before the first :meth:`act`; the tensors
        must stay in their storage for the run (the env's do).
        """
        S, N, d = self.obs.shape
        a = self.action.shape[-1]
        for name, t, shape in (("raw", raw, (S * N, d)), ("rew", rew, (S * N,)),
                               ("term", term, (S * N,)), ("trunc", trunc, (S * N,)),
                               ("final_obs", final_obs, (S * N, d)),
                               ("action", action, (S * N, a))):
            if tuple(t.shape) != shape or t.device != self.obs.device:
                raise ValueError(f"share: {name} must have shape {shape} on "
                                 f"{self.obs.device}, got {tuple(t.shape)} on {t.device}")
        self.raw, self.rew, self.term, self.trunc, self.final_obs = (
            raw, rew, term, trunc, final_obs)
        self.action = action.view(S, N, a)
        self._shared = True

    def take(self, raw, rew, term, trunc, final_obs) -> None:
        """Copy the env's step (``TorchTetherVecEnv.step`` in same-step autoreset) in."""
        if self._shared:
            raise RuntimeError("take() after share(): observe() reads the env's own "
                               "tensors, which take() would overwrite")
        for dst, src in ((self.raw, raw), (self.rew, rew), (self.term, term),
                         (self.trunc, trunc), (self.final_obs, final_obs)):
            dst.copy_(src)

    def observe(self) -> None:
        """Take the env's step in (:meth:`observe_step`, compiled with ``compiled``)."""
        self._observe()

    def observe_step(self) -> None:
        """Take the env's step in: observations, rewards, ended episodes; then ``t`` + 1.

        Normalises the new observations and the rewards, bootstraps the truncated
        episodes' values (SB3's PPO: + gamma V(final obs)), records the reward at row
        ``t`` and counts the ended episodes.
        """
        s, policy = self.settings, self.policy
        S, N, d = self.obs.shape
        rew, term, trunc = self.rew.view(S, N), self.term.view(S, N), self.trunc.view(S, N)
        done = term | trunc
        obs_raw = self.raw.view(S, N, d).to(self.obs_stats.mean.dtype)  # cast once
        self.obs_stats.update(obs_raw)
        self.obs.copy_(normalize(obs_raw, self.obs_stats, s))
        scaled, returns = scale_rewards(rew, done, self.returns, self.ret_stats, s)
        self.returns.copy_(returns)
        last_obs = normalize(self.final_obs.view(S, N, d), self.obs_stats, s)
        boot = s.gamma * policy.value(last_obs)
        scaled = scaled + torch.where(trunc, boot.to(scaled.dtype), torch.zeros_like(scaled))
        self.buf_rew.index_copy_(0, self.t, scaled.float()[None])
        self.ep_ret += rew
        self.done_eps += done.sum(dim=1)
        self.done_fail += term.sum(dim=1)
        self.done_ret += torch.where(done, self.ep_ret, torch.zeros_like(self.ep_ret)).sum(dim=1)
        self.ep_ret.copy_(torch.where(done, torch.zeros_like(self.ep_ret), self.ep_ret))
        self.episode_start.copy_(done)
        self.t.add_(1)

    def finish(self) -> None:
        """GAE(lambda) into :attr:`batch`, and ``t`` back to 0 (:meth:`finish_step`)."""
        self._finish()

    def finish_step(self) -> None:
        """GAE(lambda) into :attr:`batch`, and ``t`` back to 0.

        SB3's ``compute_returns_and_advantage`` over the recorded rollout.
        """
        s = self.settings
        T = self.buf_rew.shape[0]
        last_val = self.policy.value(self.obs)
        adv = torch.zeros_like(self.buf_rew)
        gae = torch.zeros_like(self.buf_rew[0])
        for t in range(T - 1, -1, -1):
            if t == T - 1:
                nonterminal, next_val = 1.0 - self.episode_start.float(), last_val
            else:
                nonterminal, next_val = 1.0 - self.buf_start[t + 1], self.buf_val[t + 1]
            delta = self.buf_rew[t] + s.gamma * next_val * nonterminal - self.buf_val[t]
            gae = delta + s.gamma * s.gae_lambda * nonterminal * gae
            adv[t] = gae
        self.batch.fill(self.buf_obs, self.buf_act, self.buf_logp, adv, adv + self.buf_val)
        self.t.zero_()

    def clear_counts(self) -> None:
        """Start the episode counts again (after a checkpoint)."""
        for x in (self.done_eps, self.done_fail, self.done_ret):
            x.zero_()
