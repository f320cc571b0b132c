"""The minibatch step's arithmetic, and the same step fused by ``torch.compile``.

A minibatch step of ``train.py gpu`` (:func:`~.trainer._minibatch_step`) is the
clipped-surrogate loss of every seed on its samples (:func:`minibatch_loss`), its
backward pass, each seed's gradient clipped to its own norm, Adam, and each seed's step
scaled by its own learning rate. Eager, that is about 365 torch operations per step
on the CPU (about 250 with CUDA's fused Adam), each a kernel launch on a GPU
(bench/accel_ops.py).

With ``train.py gpu --compile-update`` the trainer runs :class:`CompiledSteps` with
:class:`PerSeedAdam` instead: the samples' gather and the loss go through
``torch.compile`` (its forward and backward graphs, fused by Inductor into a few
kernels and the matrix products), and the clipping, Adam and the per-seed rates are
one compiled function of all parameter tensors. The arithmetic is the same as the
eager step's (tests/agents/accel/test_accel_minibatch.py checks the weights after
several steps against it), not bitwise: Inductor fuses and reorders float32 operations,
and :class:`PerSeedAdam` scales each seed's Adam step by its rate directly where the
eager step applies Adam with rate 1 and then scales the change. The first call of each
compiled function compiles it (tens of seconds on a cold cache, a few seconds once
Inductor's cache holds it); a minibatch of another size (the last one of an epoch,
when ``batch_size`` does not divide the rollout) compiles once more.

Not yet run on a GPU (no device was lent to the session that wrote this, 2026-12-07).
"""

from __future__ import annotations

import torch

from .ppo import MultiSeedPolicy, PPOSettings, clip_scales

__all__ = ["take", "minibatches", "minibatch_loss", "adapt_rates", "PerSeedAdam",
           "CompiledSteps"]

ADAM_BETAS = (0.9, 0.999)
"""Adam's moment decay rates (torch's and stable-baselines3's defaults)."""
ADAM_EPS = 1.0e-5
"""Adam's epsilon, as stable-baselines3's PPO sets it."""


def take(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """Rows ``idx`` (S, b) of each seed's samples x (S, M, ...)."""
    S = x.shape[0]
    return torch.gather(x, 1, idx.view(S, -1, *([1] * (x.dim() - 2))).expand(-1, -1, *x.shape[2:]))


def minibatches(orders: torch.Tensor, batch_size: int):
    """Each minibatch's sample indices (S, b) in turn: a pass per epoch over ``orders``.

    ``orders`` (epochs, S, M) holds each epoch's order per seed; minibatches of
    ``batch_size`` rows, the last of an epoch shorter when M is not a multiple of it.
    """
    M = orders.shape[2]
    bs = min(batch_size, M)
    for epoch in range(orders.shape[0]):
        for start in range(0, M, bs):
            yield orders[epoch, :, start:start + bs]


def minibatch_loss(policy: MultiSeedPolicy, settings: PPOSettings, o, ac, lp0, ad, rt):
    """PPO's loss summed over the seeds, and the log-probabilities of the actions.

    ``o`` (S, b, obs) normalised observations, ``ac`` (S, b, act) actions, ``lp0`` (S, b)
    their log-probabilities under the rollout's policy, ``ad`` (S, b) advantages
    (normalised here, per seed and minibatch, as stable-baselines3's PPO), ``rt`` (S, b)
    returns. Per seed: the clipped surrogate, ``vf_coef`` times the value error and
    ``ent_coef`` times the negative entropy (stable-baselines3's PPO loss). Returns the
    loss (a scalar: the seeds' losses are independent, so the gradient of their sum is
    each seed's own) and the new log-probabilities ``lp`` (S, b).
    """
    ad = (ad - ad.mean(dim=1, keepdim=True)) / (ad.std(dim=1, keepdim=True) + 1e-8)
    dist = policy.distribution(o)
    lp = dist.log_prob(ac).sum(-1)
    ratio = torch.exp(lp - lp0)
    pg = -torch.minimum(ad * ratio, ad * torch.clamp(ratio, 1.0 - settings.clip_range,
                                                    1.0 + settings.clip_range)).mean(1)
    vf = (rt - policy.value(o)).square().mean(1)
    ent = -dist.entropy().sum(-1).mean(1)
    return (pg + settings.ent_coef * ent + settings.vf_coef * vf).sum(), lp


def adapt_rates(lr: torch.Tensor, lp0: torch.Tensor, lp: torch.Tensor,
                settings: PPOSettings) -> None:
    """rsl_rl's adaptive rule on each seed's rate ``lr`` (S,), in place.

    The KL divergence estimate mean(lp0 - lp) of the minibatch: above 2 ``desired_kl``
    the rate is divided by 1.5, below ``desired_kl`` / 2 multiplied by 1.5, and kept
    within [1e-5, 1e-2].
    """
    with torch.no_grad():
        kl = (lp0 - lp).mean(1)
        lr.copy_(torch.where(kl > 2.0 * settings.desired_kl, lr / 1.5,
                             torch.where(kl < 0.5 * settings.desired_kl, lr * 1.5,
                                         lr)).clamp(1e-5, 1e-2))


def _clip_adam(params: list, grads: list, exp_avg: list, exp_avg_sq: list,
               step: torch.Tensor, lr: torch.Tensor, max_norm: float) -> None:
    """Each seed's gradient clipped to ``max_norm``, then Adam with each seed's rate.

    Every tensor has the seed axis first. The clipping is
    :meth:`~.ppo.MultiSeedPolicy.per_seed_grad_clip`'s (:func:`~.ppo.clip_scales`); Adam
    is torch's (moments m = b1 m + (1 - b1) g, v = b2 v + (1 - b2) g^2, bias
    corrections c1 = 1 - b1^t, c2 = 1 - b2^t, step (m / c1) / (sqrt(v) / sqrt(c2) + eps)),
    the step times the seed's rate. The step counter ``step`` is a float64 tensor (1,),
    so that the bias corrections are those of the eager step's float64 arithmetic.
    """
    b1, b2 = ADAM_BETAS
    scale = clip_scales(grads, max_norm)[1]
    step.add_(1.0)
    c1 = (1.0 - b1 ** step).to(lr.dtype)
    c2_sqrt = torch.sqrt(1.0 - b2 ** step).to(lr.dtype)
    for p, g, m, v in zip(params, grads, exp_avg, exp_avg_sq, strict=True):
        shape = (-1, *([1] * (g.dim() - 1)))
        g = g * scale.view(shape)
        m.lerp_(g, 1.0 - b1)
        v.mul_(b2).addcmul_(g, g, value=1.0 - b2)
        p.sub_(lr.view(shape) / c1 * m / (v.sqrt() / c2_sqrt + ADAM_EPS))


class PerSeedAdam:
    """Per-seed gradient clipping, Adam and per-seed rates as one function, compiled or not.

    The optimizer of ``train.py gpu --compile-update``: what the eager step does with
    :meth:`~.ppo.MultiSeedPolicy.per_seed_grad_clip`, ``torch.optim.Adam`` (rate 1, eps
    1e-5) and the scaling of each seed's change by its rate, in one function of all the
    parameter tensors (:func:`_clip_adam`), which ``torch.compile`` fuses. Its state
    (the moments and the step counter) stays in the storage it was made in, as a CUDA
    graph's replays need.

    Parameters
    ----------
    params : iterable of torch.nn.Parameter
        The policy's parameters, seed axis first.
    max_norm : float
        Each seed's gradient norm bound (``max_grad_norm``).
    compiled : bool
        Run the step through ``torch.compile`` (default True).
    """

    def __init__(self, params, max_norm: float, compiled: bool = True):
        self.params = list(params)
        self.param_groups = [{"params": self.params}]  # where a graph reads the weights
        self.max_norm = float(max_norm)
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        # shape (1,), not 0-d: torch 2.13's compiled step did not write an in-place
        # update of a 0-d CPU tensor back (the counter stayed 0, c1 = 0, NaN weights)
        self.step_count = torch.zeros((1,), dtype=torch.float64, device=self.params[0].device)
        self._step = (torch.compile(_clip_adam, fullgraph=True, dynamic=False) if compiled
                      else _clip_adam)

    def zero_grad(self, set_to_none: bool = True) -> None:
        """Drop the gradients (the next backward pass writes new ones)."""
        for p in self.params:
            p.grad = None

    def step(self, lr: torch.Tensor) -> None:
        """Clip each seed's gradients and take its Adam step at its rate ``lr`` (S,)."""
        with torch.no_grad():
            self._step(self.params, [p.grad for p in self.params], self.exp_avg,
                       self.exp_avg_sq, self.step_count, lr, self.max_norm)


def _take_loss(policy, settings, batch: tuple, idx: torch.Tensor):
    """The minibatch ``idx`` of ``batch``, its loss and log-probabilities, and its ``lp0``."""
    o, ac, lp0, ad, rt = (take(x, idx) for x in batch)
    loss, lp = minibatch_loss(policy, settings, o, ac, lp0, ad, rt)
    return loss, lp.detach(), lp0


class CompiledSteps:
    """``steps(policy, opt, lr, settings, batch, orders)`` with the arithmetic fused.

    A drop-in for :func:`~.trainer._minibatch_steps` (every minibatch step of an update,
    ``n_epochs`` passes over ``batch`` in ``orders``) whose ``opt`` is a
    :class:`PerSeedAdam`: per minibatch step, one compiled gather-and-loss (forward and
    backward graphs), the backward pass and ``opt``'s compiled step; with
    ``lr_schedule: adaptive`` the rates' rule (:func:`adapt_rates`). No host sync and
    no random draw: :class:`~.graphs.GraphedUpdate` can capture it whole.

    Parameters
    ----------
    compiled : bool
        Run the gather and the loss through ``torch.compile`` (default True; False runs
        the same Python eagerly, for the tests).
    """

    def __init__(self, compiled: bool = True):
        self._loss = (torch.compile(_take_loss, fullgraph=True, dynamic=False) if compiled
                      else _take_loss)

    def __call__(self, policy, opt: PerSeedAdam, lr: torch.Tensor, settings: PPOSettings,
                 batch: tuple, orders: torch.Tensor) -> None:
        """Every minibatch step of one update (see :func:`~.trainer._minibatch_steps`)."""
        if not isinstance(opt, PerSeedAdam):
            raise TypeError(f"CompiledSteps needs a PerSeedAdam optimizer, got "
                            f"{type(opt).__name__}")
        for idx in minibatches(orders, settings.batch_size):
            loss, lp, lp0 = self._loss(policy, settings, batch, idx)
            opt.zero_grad()
            loss.backward()
            opt.step(lr)
            if settings.lr_schedule == "adaptive":
                adapt_rates(lr, lp0, lp, settings)
