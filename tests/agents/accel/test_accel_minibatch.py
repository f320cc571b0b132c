"""The minibatch step fused by ``torch.compile`` (``train.py gpu --compile-update``).

:class:`PerSeedAdam` and :class:`CompiledSteps` must do the eager step's arithmetic
(:func:`~tether_gym_agents.accel.trainer._minibatch_steps` with torch's Adam): run
uncompiled, their weights, moments and rates after several updates equal the eager
update's to float32 rounding; compiled, they equal the uncompiled ones to the same
tolerance, with a shorter last minibatch (a second compile) and the adaptive rates.
"""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from tether_gym_agents.accel.minibatch import (  # noqa: E402
    CompiledSteps,
    PerSeedAdam,
    _clip_adam,
)
from tether_gym_agents.accel.ppo import MultiSeedPolicy, PPOSettings  # noqa: E402
from tether_gym_agents.accel.trainer import _minibatch_steps, _permutations  # noqa: E402

S, M, D, A = 2, 40, 6, 2


def _batch(g: torch.Generator) -> tuple:
    """A made-up rollout (observations, actions, log-probabilities, advantages, returns)."""
    return (torch.randn((S, M, D), generator=g), 0.05 * torch.randn((S, M, A), generator=g),
            torch.randn((S, M), generator=g) + 2.0, torch.randn((S, M), generator=g),
            torch.randn((S, M), generator=g))


def _train(fused: str, schedule: str, batch_size: int, updates: int = 3):
    """``updates`` updates on fresh made-up rollouts; the weights, Adam's moments, the
    rates and Adam's step count. ``fused``: "no" (torch's Adam and the eager step),
    "eager" or "compiled" (:class:`CompiledSteps`)."""
    # max_grad_norm 0.05: the clipping acts; per-seed rates unequal
    settings = PPOSettings(n_envs=8, n_steps=5, batch_size=batch_size, n_epochs=2,
                           lr_schedule=schedule, max_grad_norm=0.05, log_std_init=-1.0)
    policy = MultiSeedPolicy([3, 4], D, A, settings, "cpu")
    lr = torch.tensor([1e-3, 4e-4])
    if fused == "no":
        opt = torch.optim.Adam(policy.parameters(), lr=1.0, eps=1e-5)
        steps = _minibatch_steps
    else:
        opt = PerSeedAdam(policy.parameters(), settings.max_grad_norm,
                          compiled=fused == "compiled")
        steps = CompiledSteps(compiled=fused == "compiled")
    g = torch.Generator().manual_seed(1)
    torch.manual_seed(2)
    for _ in range(updates):
        batch = _batch(g)
        steps(policy, opt, lr, settings, batch, _permutations(settings.n_epochs, S, M, "cpu"))
    if fused == "no":
        moments = [opt.state[p][k] for k in ("exp_avg", "exp_avg_sq")
                   for p in policy.parameters()]
        count = float(opt.state[policy.log_std]["step"])
    else:
        moments = [*opt.exp_avg, *opt.exp_avg_sq]
        count = float(opt.step_count)
    return [p.detach().clone() for p in policy.parameters()], moments, lr, count


def _close(got, want) -> None:
    """Equal to float32 rounding: 1e-5 relative, or 1e-5 of the tensor's largest entry
    (the gradients' sums, and so Adam's moments, round at the size of their terms)."""
    for x, y in zip(got, want, strict=True):
        torch.testing.assert_close(x, y, rtol=1e-5, atol=1e-5 * float(y.abs().max()) + 1e-12)


@pytest.mark.parametrize("schedule", ["linear", "adaptive"])
def test_per_seed_adam_is_the_eager_update(schedule):
    """Uncompiled, the fused step is the eager step (torch's Adam at rate 1, the change
    scaled by each seed's rate), to float32 rounding: 3 updates of 10 minibatch steps."""
    want_w, want_m, want_lr, want_n = _train("no", schedule, batch_size=8)
    got_w, got_m, got_lr, got_n = _train("eager", schedule, batch_size=8)
    _close(got_w, want_w)
    _close(got_m, want_m)
    torch.testing.assert_close(got_lr, want_lr, rtol=1e-6, atol=0)
    assert got_n == want_n == 30
    start = MultiSeedPolicy([3, 4], D, A, PPOSettings(log_std_init=-1.0), "cpu")
    moved = max(float((w - p.detach()).abs().max()) for w, p in zip(want_w, start.parameters(),
                                                           strict=True))
    assert moved > 1e-3  # it trained far beyond the tolerance
    if schedule == "adaptive":
        assert not torch.equal(want_lr, torch.tensor([1e-3, 4e-4]))  # the rule acted


def test_the_clipping_and_adam_are_torchs():
    """One :func:`_clip_adam` step against per_seed_grad_clip + torch's Adam on the same
    gradients, one seed's clipped (norm above the bound) and the other's not."""
    torch.manual_seed(0)
    params = [torch.randn(2, 3, 4), torch.randn(2, 1, 4)]
    grads = [torch.randn(2, 3, 4), torch.randn(2, 1, 4)]
    grads[0][1] *= 1e-3
    grads[1][1] *= 1e-3  # seed 1's norm is below 0.5: not clipped
    lr = torch.tensor([1e-2, 3e-3])
    mine = [p.clone() for p in params]
    m, v = [torch.zeros_like(p) for p in params], [torch.zeros_like(p) for p in params]
    count = torch.zeros(1, dtype=torch.float64)
    theirs = [torch.nn.Parameter(p.clone()) for p in params]
    opt = torch.optim.Adam(theirs, lr=1.0, eps=1e-5)
    for _ in range(2):
        _clip_adam(mine, [g.clone() for g in grads], m, v, count, lr, 0.5)
        norm = torch.sqrt(sum(g.reshape(2, -1).square().sum(1) for g in grads))
        scale = torch.clamp(0.5 / (norm + 1e-6), max=1.0)
        for p, g in zip(theirs, grads, strict=True):
            p.grad = g * scale.view(-1, *([1] * (g.dim() - 1)))
        before = [p.detach().clone() for p in theirs]
        opt.step()
        with torch.no_grad():
            for p, b in zip(theirs, before, strict=True):
                p.copy_(b + (p - b) * lr.view(-1, *([1] * (p.dim() - 1))))
    assert float(scale[0]) < 1.0 and float(scale[1]) == 1.0
    _close(mine, [p.detach() for p in theirs])
    assert float(count) == 2.0


def test_the_compiled_steps_are_the_uncompiled_ones():
    """Compiled (Inductor on the CPU), 3 updates with minibatches of 16 (the last of an
    epoch 8 rows: two compiled shapes) and the adaptive rates equal the uncompiled run
    to float32 rounding, and they ran compiled."""
    from torch._dynamo.utils import counters

    torch._dynamo.reset()
    before = counters["stats"]["unique_graphs"]
    want = _train("eager", "adaptive", batch_size=16)
    got = _train("compiled", "adaptive", batch_size=16)
    assert counters["stats"]["unique_graphs"] - before >= 3  # the loss twice, the step
    _close(got[0], want[0])
    _close(got[1], want[1])
    torch.testing.assert_close(got[2], want[2], rtol=1e-6, atol=0)
    assert got[3] == want[3] == 3 * 2 * 3


def test_compiled_steps_refuse_another_optimizer():
    policy = MultiSeedPolicy([0], D, A, PPOSettings(), "cpu")
    opt = torch.optim.Adam(policy.parameters())
    with pytest.raises(TypeError, match="PerSeedAdam"):
        CompiledSteps(compiled=False)(policy, opt, torch.ones(1), PPOSettings(),
                                      _batch(torch.Generator()), torch.zeros((1, 1, M),
                                                                             dtype=torch.long))
