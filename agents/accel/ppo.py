"""PPO on a torch device, several seeds trained at once, exporting standard agent folders.

The algorithm is stable-baselines3's PPO (clipped surrogate, GAE, value loss, Adam with
eps 1e-5, per-minibatch advantage normalisation, gradient-norm clipping, the
truncation bootstrap gamma V(final obs)) with VecNormalize's observation and reward
normalisation, written for whole batches on one device: the rollout, the
normalisation and the updates never leave it. ``S`` seeds train side by side: every
weight has a leading seed axis (an MLP evaluated with batched matrix products), each
seed with its own envs, statistics, minibatch order and gradient clipping, so that
the seeds are as independent as separate runs while one process drives them.

The policy is stable-baselines3's ``ActorCriticPolicy`` with ``net_arch`` [h1, h2] (separate
tanh policy and value MLPs, a state-independent log std), initialised as SB3 does
(orthogonal, gains sqrt 2 / 0.01 / 1). :meth:`MultiSeedPolicy.sb3_state_dict` gives one
seed's weights under SB3's names, so the agent folder it writes
(:func:`tether_gym_agents.files.safe_format.save_agent`) is read, and scored, as
every other PPO agent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

__all__ = ["PPOSettings", "MultiSeedPolicy", "RunningStats", "learning_rate_at",
           "clip_scales"]


@dataclass(frozen=True)
class PPOSettings:
    """Hyperparameters of one GPU PPO run (the keys of configs/gpu_ppo.yml).

    Attributes
    ----------
    n_envs : int
        Envs per seed.
    n_steps : int
        Steps per env and rollout.
    batch_size : int
        Minibatch size per seed [samples].
    n_epochs : int
        Passes over a rollout.
    learning_rate : float
        Adam step size at the start; ``lr_schedule`` "linear" lets it fall to 0,
        "adaptive" (rsl_rl's rule, per seed) multiplies it by 1.5 after a minibatch whose
        KL divergence from the rollout's policy was below ``desired_kl`` / 2 and divides
        it by 1.5 above 2 ``desired_kl``, within [1e-5, 1e-2].
    """

    n_envs: int = 1024
    n_steps: int = 64
    batch_size: int = 8192
    n_epochs: int = 10
    gamma: float = 0.995
    gae_lambda: float = 0.95
    learning_rate: float = 1.0e-3
    lr_schedule: str = "linear"
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    net_arch: tuple = (64, 64)
    log_std_init: float = -3.5
    clip_obs: float = 10.0
    clip_reward: float = 10.0
    norm_epsilon: float = 1.0e-8
    desired_kl: float = 0.01


def learning_rate_at(settings: PPOSettings, progress_remaining: float) -> float:
    """The learning rate at ``progress_remaining`` in [0, 1] (SB3's convention)."""
    if settings.lr_schedule == "linear":
        return settings.learning_rate * progress_remaining
    return settings.learning_rate


class RunningStats:
    """Running mean and variance per seed (SB3's ``RunningMeanStd``, parallel update).

    ``mean``, ``var`` of shape (S, d); ``count`` (S,), started at 1e-4 as SB3's; updated
    in place.
    """

    def __init__(self, seeds: int, dim: int, device, dtype=torch.float64):
        self.mean = torch.zeros((seeds, dim), dtype=dtype, device=device)
        self.var = torch.ones((seeds, dim), dtype=dtype, device=device)
        self.count = torch.full((seeds,), 1e-4, dtype=dtype, device=device)

    def update(self, x: torch.Tensor) -> None:
        """Fold a batch x (S, B, d) into the statistics (Chan et al.'s parallel formula)."""
        x = x.to(self.mean.dtype)
        batch_mean = x.mean(dim=1)
        batch_var = x.var(dim=1, unbiased=False)
        batch_count = x.shape[1]
        delta = batch_mean - self.mean
        tot = self.count + batch_count
        new_mean = self.mean + delta * (batch_count / tot)[:, None]
        m_a = self.var * self.count[:, None]
        m_b = batch_var * batch_count
        m2 = m_a + m_b + delta.square() * (self.count * batch_count / tot)[:, None]
        new_var = m2 / tot[:, None]
        # in place: a captured CUDA graph reads the statistics where it found them
        self.mean.copy_(new_mean)
        self.var.copy_(new_var)
        self.count.copy_(tot)


def clip_scales(grads: list[torch.Tensor], max_norm: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Each seed's gradient norm and the factor that clips it to ``max_norm``.

    ``grads`` carry the seed axis first; the norm (S,) is over all of a seed's tensors,
    the factor min(1, max_norm / (norm + 1e-6)) (SB3's clip_grad_norm_, per seed).
    """
    sq = torch.zeros(grads[0].shape[0], device=grads[0].device)
    for g in grads:
        sq = sq + g.reshape(g.shape[0], -1).square().sum(dim=1)
    norm = torch.sqrt(sq)
    return norm, torch.clamp(max_norm / (norm + 1e-6), max=1.0)


def _orthogonal(shape, gain: float, generator: torch.Generator, device) -> torch.Tensor:
    """An orthogonal (out, in) matrix times ``gain`` (torch.nn.init.orthogonal_'s recipe)."""
    rows, cols = shape
    flat = torch.randn((rows, cols) if rows >= cols else (cols, rows), generator=generator,
                       device="cpu")
    q, r = torch.linalg.qr(flat)
    q = q * torch.sign(torch.diagonal(r))
    if rows < cols:
        q = q.T
    return (gain * q).to(device)


class MultiSeedPolicy(torch.nn.Module):
    """S independent ``ActorCriticPolicy`` MLPs ([h1, h2], tanh), one per seed, batched.

    Parameters are (S, ...) tensors: ``pi_w[i]`` (S, in, out) and ``pi_b[i]`` (S, 1, out)
    for the policy net and its head, ``vf_w``/``vf_b`` for the value net and head,
    ``log_std`` (S, act).
    """

    def __init__(self, seeds: list[int], obs_dim: int, act_dim: int, settings: PPOSettings,
                 device):
        super().__init__()
        sizes = [obs_dim, *settings.net_arch]
        self.seeds = list(seeds)
        self.obs_dim, self.act_dim = obs_dim, act_dim
        self.net_arch = tuple(settings.net_arch)
        gain = math.sqrt(2.0)
        pi_w, pi_b, vf_w, vf_b = [], [], [], []
        per_seed = []
        for seed in seeds:
            g = torch.Generator().manual_seed(int(seed))
            layers: dict[str, list[torch.Tensor]] = {"pi": [], "vf": []}
            for net in ("pi", "vf"):
                for a, b in zip(sizes[:-1], sizes[1:], strict=True):
                    layers[net].append(_orthogonal((b, a), gain, g, "cpu"))
            layers["pi"].append(_orthogonal((act_dim, sizes[-1]), 0.01, g, "cpu"))
            layers["vf"].append(_orthogonal((1, sizes[-1]), 1.0, g, "cpu"))
            per_seed.append(layers)
        for i in range(len(sizes)):
            pi_w.append(torch.stack([s["pi"][i].T for s in per_seed]))
            vf_w.append(torch.stack([s["vf"][i].T for s in per_seed]))
            pi_b.append(torch.zeros((len(seeds), 1, pi_w[-1].shape[2])))
            vf_b.append(torch.zeros((len(seeds), 1, vf_w[-1].shape[2])))
        def as_params(ts):
            return (torch.nn.ParameterList(
                    [torch.nn.Parameter(t.to(device=device, dtype=torch.float32)) for t in ts]))
        self.pi_w, self.pi_b = as_params(pi_w), as_params(pi_b)
        self.vf_w, self.vf_b = as_params(vf_w), as_params(vf_b)
        self.log_std = torch.nn.Parameter(torch.full((len(seeds), act_dim),
                                                     float(settings.log_std_init),
                                                     device=device))

    @staticmethod
    def _mlp(x: torch.Tensor, ws, bs) -> torch.Tensor:
        """tanh MLP with a linear head on x (S, B, in)."""
        h = x
        last = len(ws) - 1
        for i, (w, b) in enumerate(zip(ws, bs, strict=True)):
            h = torch.baddbmm(b, h, w)
            if i < last:
                h = torch.tanh(h)
        return h

    def mean_action(self, obs: torch.Tensor) -> torch.Tensor:
        """The Gaussian's mean (S, B, act) for normalised observations (S, B, obs)."""
        return self._mlp(obs, self.pi_w, self.pi_b)

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        """V(obs) (S, B)."""
        return self._mlp(obs, self.vf_w, self.vf_b)[..., 0]

    def distribution(self, obs: torch.Tensor) -> torch.distributions.Normal:
        """The action distribution (diagonal Gaussian, state-independent std).

        Built without argument checks (``validate_args=False``): each check reads a
        tensor back to the host, a device sync per rollout and minibatch step that
        would also rule out CUDA-graph capture. The figures are the same; a NaN
        still shows in the losses and the final check.
        """
        mean = self.mean_action(obs)
        return torch.distributions.Normal(mean, self.log_std.exp()[:, None, :].expand_as(mean),
                                          validate_args=False)

    def per_seed_grad_clip(self, max_norm: float) -> torch.Tensor:
        """Scale each seed's gradient to a norm of at most ``max_norm``; the norms (S,)."""
        grads = [p.grad for p in self.parameters() if p.grad is not None]
        norm, scale = clip_scales(grads, max_norm)
        for g in grads:
            g.mul_(scale.view(-1, *([1] * (g.dim() - 1))))
        return norm

    def sb3_state_dict(self, s: int) -> dict[str, torch.Tensor]:
        """Seed ``s``'s weights under stable-baselines3 ``ActorCriticPolicy``'s names."""
        out = {"log_std": self.log_std[s]}
        hidden = len(self.net_arch)
        for net, ws, bs in (("policy_net", self.pi_w, self.pi_b),
                            ("value_net", self.vf_w, self.vf_b)):
            for i in range(hidden):
                out[f"mlp_extractor.{net}.{2 * i}.weight"] = ws[i][s].T
                out[f"mlp_extractor.{net}.{2 * i}.bias"] = bs[i][s, 0]
        out["action_net.weight"] = self.pi_w[hidden][s].T
        out["action_net.bias"] = self.pi_b[hidden][s, 0]
        out["value_net.weight"] = self.vf_w[hidden][s].T
        out["value_net.bias"] = self.vf_b[hidden][s, 0]
        return {k: v.detach().float().cpu().contiguous() for k, v in out.items()}
