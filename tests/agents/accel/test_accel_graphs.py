"""The minibatch step as a CUDA graph (``train.py gpu --cuda-graphs``), checked on the CPU.

A capture needs a step free of host syncs, random draws and sorts, and fed through
fixed inputs. The first is counted here with a dispatch mode. The second is checked
by capturing and replaying the step through :class:`RecordingCapture`, which replays
the recorded aten operations on the recorded tensors without running the Python again,
as a CUDA graph does: the result must be the eager step's, bitwise. CUDA's
capture itself is run by ``test_a_cuda_graph_trains_what_the_eager_step_trains`` where
torch sees a GPU, and skipped elsewhere (CI has none).
"""

from __future__ import annotations

from collections import Counter

import pytest

torch = pytest.importorskip("torch")

from torch.utils._python_dispatch import TorchDispatchMode  # noqa: E402

from tether_gym_agents.accel.graphs import (  # noqa: E402
    WARMUP_STEPS,
    GraphedMinibatchStep,
    RecordingCapture,
)
from tether_gym_agents.accel.ppo import MultiSeedPolicy, PPOSettings  # noqa: E402
from tether_gym_agents.accel.trainer import (  # noqa: E402
    RolloutBatch,
    _minibatch_step,
    _permutations,
    _update,
)

SYNCS = {"_local_scalar_dense", "item", "is_nonzero", "equal", "nonzero", "unique",
         "masked_select"}
"""aten operations that read a device tensor back to the host."""
DRAWS = {"rand", "randn", "normal", "uniform", "bernoulli", "random", "multinomial",
         "randint", "randperm", "sort", "argsort"}
"""Random draws and sorts (a capture keeps neither out of trouble: the orders come first)."""


class _Ops(TorchDispatchMode):
    """Counts aten operations by name while ``on``."""

    def __init__(self):
        super().__init__()
        self.on, self.ops = True, Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if self.on:
            self.ops[func.overloadpacket.__name__.rstrip("_")] += 1
        return func(*args, **(kwargs or {}))


def _learner(schedule="linear", seeds=(3, 4), obs_dim=6, act_dim=2, fused=False):
    """Settings, policy, Adam and rates; ``fused``: the CPU's fused Adam, which keeps its
    step count on the device as CUDA's capturable Adam does (the default one reads it
    back to the host)."""
    settings = PPOSettings(n_envs=8, n_steps=4, batch_size=8, n_epochs=2, lr_schedule=schedule,
                           net_arch=(16, 16), log_std_init=-1.0)
    policy = MultiSeedPolicy(list(seeds), obs_dim, act_dim, settings, "cpu")
    opt = torch.optim.Adam(policy.parameters(), lr=1.0, eps=1e-5, fused=fused)
    lr = torch.full((len(seeds),), 3e-3)
    return settings, policy, opt, lr


def _rollout(g, T, S, N, d, a):
    """Random rollout buffers (T, S, N, ...) as the trainer fills them."""
    return (torch.randn((T, S, N, d), generator=g), torch.randn((T, S, N, a), generator=g),
            torch.randn((T, S, N), generator=g) - 2.0, torch.randn((T, S, N), generator=g),
            torch.randn((T, S, N), generator=g))


@pytest.mark.parametrize("schedule", ["linear", "adaptive"])
def test_the_minibatch_step_needs_no_host_sync_and_draws_nothing(schedule):
    """The step's own operations (the CPU's Adam aside: CUDA's capturable Adam is
    another) include no read-back to the host, no random draw and no sort."""
    settings, policy, opt, lr = _learner(schedule)
    batch = RolloutBatch(4, 2, 8, 6, 2, "cpu")
    batch.fill(*_rollout(torch.Generator().manual_seed(0), 4, 2, 8, 6, 2))
    idx = _permutations(1, 2, 32, "cpu")[0, :, :8]
    counter = _Ops()
    real_step = opt.step

    def uncounted_step(*args, **kwargs):
        counter.on = False
        try:
            return real_step(*args, **kwargs)
        finally:
            counter.on = True

    opt.step = uncounted_step
    with counter:
        _minibatch_step(policy, opt, lr, settings, batch.tensors(), idx)
    assert counter.ops["bmm"] > 0 and counter.ops["tanh_backward"] > 0  # it saw the step
    assert not {k: n for k, n in counter.ops.items() if k in SYNCS | DRAWS}


def test_rollout_batch_is_the_flattened_rollout():
    """fill() writes (T, S, N, ...) seed-major in (time, env) order, in the same storage."""
    T, S, N, d, a = 3, 2, 5, 4, 2
    batch = RolloutBatch(T, S, N, d, a, "cpu")
    where = [t.data_ptr() for t in batch.tensors()]
    for k in range(2):
        rollout = _rollout(torch.Generator().manual_seed(k), T, S, N, d, a)
        batch.fill(*rollout)
        for got, src in zip(batch.tensors(), rollout, strict=True):
            assert torch.equal(got, src.transpose(0, 1).reshape(S, T * N, *src.shape[3:]))
        assert [t.data_ptr() for t in batch.tensors()] == where
    assert torch.equal(batch.obs[1, 2 * N + 3], rollout[0][2, 1, 3])


def test_permutations_are_one_argsort_of_rand_per_epoch():
    """The orders drawn up front are the draws of one ``argsort(rand)`` per epoch."""
    torch.manual_seed(5)
    perms = _permutations(3, 2, 7, "cpu")
    torch.manual_seed(5)
    for e in range(3):
        assert torch.equal(perms[e], torch.argsort(torch.rand((2, 7)), dim=1))
        assert torch.equal(perms[e].sort(dim=1).values, torch.arange(7).expand(2, 7))


@pytest.mark.parametrize(("N", "schedule", "graphs"),
                         [(8, "linear", 1), (9, "adaptive", 2)])
def test_a_replayed_step_is_the_eager_step(N, schedule, graphs):
    """Three iterations of ``_update`` on fresh rollouts: the graphed step (through
    RecordingCapture) leaves the weights, Adam's moments and the rates bitwise as the
    eager step does. With 9 envs x 4 steps the last minibatch of an epoch is 4 rows, not 8:
    a second graph."""
    T, S, d, a = 4, 2, 6, 2
    results = []
    for graphed in (False, True):
        settings, policy, opt, lr = _learner(schedule, fused=True)
        step = GraphedMinibatchStep(_minibatch_step, RecordingCapture()) if graphed \
            else _minibatch_step
        batch = RolloutBatch(T, S, N, d, a, "cpu")
        g = torch.Generator().manual_seed(11)
        torch.manual_seed(7)
        for _ in range(3):
            batch.fill(*_rollout(g, T, S, N, d, a))
            _update(policy, opt, lr, settings, batch, step)
        if graphed:
            assert step.captured == graphs
        moments = [opt.state[p][k] for p in policy.parameters() for k in ("exp_avg",
                                                                             "exp_avg_sq")]
        results.append([*(p.detach() for p in policy.parameters()), *moments, lr])
    eager, replayed = results
    assert all(torch.equal(x, y) for x, y in zip(eager, replayed, strict=True))
    assert not torch.equal(eager[0], _learner(schedule)[1].pi_w[0])  # it trained


def test_a_replay_whose_inputs_moved_is_refused():
    """A rollout in new storage after the capture would be read stale by a replay."""
    settings, policy, opt, lr = _learner(fused=True)
    batch = RolloutBatch(4, 2, 8, 6, 2, "cpu")
    batch.fill(*_rollout(torch.Generator().manual_seed(0), 4, 2, 8, 6, 2))
    step = GraphedMinibatchStep(_minibatch_step, RecordingCapture())
    idx = _permutations(1, 2, 32, "cpu")[0, :, :8]
    for _ in range(WARMUP_STEPS + 1):
        step(policy, opt, lr, settings, batch.tensors(), idx)
    assert step.captured == 1
    moved = tuple(t.clone() for t in batch.tensors())
    with pytest.raises(RuntimeError, match="moved since the capture"):
        step(policy, opt, lr, settings, moved, idx)


def test_the_stand_in_keeps_a_graphs_rules():
    """RecordingCapture is a CUDA graph's rules, not a second call: its capture changes
    nothing, a replay reads the tensors the capture read (a tensor that Python rebinds
    afterwards is not seen; one refilled in place is), Python numbers stay as captured,
    and a host sync cannot be captured."""
    state = {"x": torch.ones(3), "k": 2.0}
    total = torch.zeros(3)

    def fn():
        total.add_(state["x"] * state["k"])

    replay = RecordingCapture().capture(fn)
    assert torch.equal(total, torch.zeros(3))       # capturing ran nothing
    replay()
    assert torch.equal(total, torch.full((3,), 2.0))
    state["x"].fill_(5.0)                            # refilled in place: seen
    state["k"] = 100.0                               # a Python number: fixed at capture
    replay()
    assert torch.equal(total, torch.full((3,), 12.0))
    state["x"] = torch.full((3,), 7.0)               # rebound: the replay reads the old one
    replay()
    assert torch.equal(total, torch.full((3,), 22.0))
    with pytest.raises(RuntimeError, match="host sync"):
        RecordingCapture().capture(lambda: float(total.sum()))


def test_the_cpus_default_adam_cannot_be_captured():
    """The CPU's default Adam reads its step count back to the host, as CUDA's Adam does
    without ``capturable=True``: a capture of the step fails, where the trainer's
    ``--cuda-graphs`` asks for the capturable one."""
    settings, policy, opt, lr = _learner()
    batch = RolloutBatch(4, 2, 8, 6, 2, "cpu")
    batch.fill(*_rollout(torch.Generator().manual_seed(0), 4, 2, 8, 6, 2))
    step = GraphedMinibatchStep(_minibatch_step, RecordingCapture())
    idx = _permutations(1, 2, 32, "cpu")[0, :, :8]
    for _ in range(WARMUP_STEPS):
        step(policy, opt, lr, settings, batch.tensors(), idx)
    with pytest.raises(RuntimeError, match="host sync"):
        step(policy, opt, lr, settings, batch.tensors(), idx)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_a_cuda_graph_trains_what_the_eager_step_trains(tmp_path):
    """On a GPU: ``train.py gpu --cuda-graphs`` ends near the eager run's weights (float32;
    the capturable Adam is not the eager run's kernel, so not bitwise)."""
    from tether_gym_agents.cli.train import main as train_main
    from tether_gym_agents.files.safe_format import load_agent

    weights = []
    for flag in ([], ["--cuda-graphs"]):
        out = tmp_path / ("graphs" if flag else "eager")
        assert train_main(["gpu", "--device", "cuda", "--out", str(out), "--n-envs", "16",
                           "--timesteps", str(16 * 64 * 3), *flag]) == 0
        weights.append(load_agent(out / "seed_0")[0].state_dict())
    for name, w in weights[0].items():
        assert (weights[1][name] - w).abs().max() <= 1e-4 * (1.0 + w.abs().max()), name
