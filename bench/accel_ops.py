"""Torch operations per PPO iteration of ``train.py gpu``: a count of kernel launches.

    python bench/accel_ops.py                        # configs/gpu_ppo.yml, both CPU backends
    python bench/accel_ops.py --config experiments/issue34/cfg/L.yml --backend numba
    python bench/accel_ops.py --backend numba --cuda-graphs   # what the host launches
    python bench/accel_ops.py --backend numba --cuda-graphs --sync-free

On a GPU a small batch costs its kernel launches, not its arithmetic (the eager torch
step ran in the same 21 ms from 4k to 262k envs on the H200 of 2026-12-04, docs/gpu.md).
This script counts, on the CPU, the torch operations that would each be one or more
kernel launches on a GPU, with the learner's own code: it trains a few iterations of the
config (``train_seeds``, ``--iterations``, 4 by default; the envs and minibatch sizes
of the config, which change no count) under a ``TorchDispatchMode`` that counts every
aten operation below autograd (the backward pass's included), leaving out the views,
which launch nothing (view, reshape, expand, transpose, slicing, detach and their kin).
It splits them into the rollout (policy, env step, normalisation, GAE, per iteration)
and the updates (``_update``, per minibatch step, with the optimizer's share apart:
the CPU's Adam steps each parameter tensor in turn, where ``train.py gpu`` asks CUDA for
torch's fused Adam, a kernel or two for all of them), and prints one JSON line per
backend. It also counts the host syncs (reads of a tensor's value back to the host) per
rollout step and per minibatch step, the optimizer's left out (the CPU's Adam reads its
step counter; CUDA's fused one does not): a CUDA graph can hold none. With
``--cuda-graphs`` it counts what the host launches under ``train.py gpu --cuda-graphs``:
the graphs are kept by ``RecordingCapture`` on the CPU, a replay counts as one launch
and Adam is the CPU's fused one (``_run``).

The numba backend's env step is one numba call on the CPU and one kernel launch with
numba-cuda: each call counts as one operation (``numba_kernel``), as do the torch
operations around it (copies into its rows, resets, autoreset). A count is a property
of the code, not of the machine: the same on any CPU, and a lower bound of the GPU's
launches (a fused or library kernel may launch more than one). What a launch costs on
a GPU is not measured here.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections import Counter
from pathlib import Path

import torch
from torch.utils._python_dispatch import TorchDispatchMode

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tether_gym_agents.accel.graphs import WARMUP_STEPS  # noqa: E402

VIEWS = {"view", "_unsafe_view", "reshape", "expand", "t", "transpose", "permute", "slice",
         "select", "unsqueeze", "squeeze", "detach", "alias", "as_strided", "lift_fresh",
         "_reshape_alias", "unbind", "split", "split_with_sizes", "numpy_T", "diagonal",
         "view_as", "unfold", "_record_function_enter_new", "_record_function_exit"}
"""aten operations that launch nothing: views, and the profiler's markers."""
SYNC = "_local_scalar_dense"
"""The aten operation that reads a tensor's value back to the host (``.item()``, ``if t``,
``.tolist()``): on a GPU, a wait for every kernel queued before it, and no CUDA graph
can hold it."""


class Count(TorchDispatchMode):
    """Counts the aten operations dispatched, by (phase, name), views left out."""

    def __init__(self):
        super().__init__()
        self.phase = "rollout"
        self.on = True
        self.ops: Counter = Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        name = func.overloadpacket.__name__
        if self.on and name not in VIEWS:
            self.ops[self.phase, name] += 1
        return func(*args, **(kwargs or {}))

    def by_phase(self) -> Counter:
        """Operations per phase."""
        out: Counter = Counter()
        for (phase, _), n in self.ops.items():
            out[phase] += n
        return out


def _in_phase(counter: Count, phase: str, fn):
    """``fn`` with its operations counted under ``phase``."""
    def wrapped(*args, **kwargs):
        before, counter.phase = counter.phase, phase
        try:
            return fn(*args, **kwargs)
        finally:
            counter.phase = before
    return wrapped


def _run(settings, env_kwargs, backend: str, iterations: int,
         graphs: bool = False, sync_free: bool = False) -> tuple[Count, int]:
    """The operations of one whole ``train_seeds`` call, and its minibatch steps.

    Phases: ``update`` (``_update`` less the optimizer), ``adam`` (``Adam.step``),
    ``env`` (the parts of ``TorchTetherVecEnv.step`` that the rollout step calls; with
    graphs only the eager ones, ``step_kernel`` and ``step_autoreset``: the others are
    inside the rollout step's replays, counted there) and
    ``rollout`` (all else: the start, the policy and normalisation of the rollouts,
    their GAE, the one checkpoint's files). A call of the numba row code (a numba-cuda
    kernel on a GPU) counts as one operation (``numba_kernel``).
    The final check on the training distribution is no part of an iteration and is
    not run (``train_info.json`` gets no figures of it).

    ``graphs``: ``--cuda-graphs``, its captures kept by ``RecordingCapture`` on the CPU
    with the CPU's fused Adam (whose step count stays on the device, as with CUDA's
    capturable Adam). A replay counts as one operation (``graph_replay``): what the host
    launches; the operations inside it are not counted. ``sync_free``: ``train.py gpu
    --sync-free`` (the autoreset without host syncs).
    """
    from tether_gym_agents.accel import graphs as graph_module
    from tether_gym_agents.accel import trainer
    from tether_gym_agents.accel.row_step import NumbaCpuStep
    from tether_gym_agents.accel.trainer import GpuRun, train_seeds
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    counter = Count()
    minibatches = [0]
    adam_class = torch.optim.Adam
    real = (trainer._update, trainer.evaluate_on_device, adam_class.step,
            TorchTetherVecEnv.step, graph_module.CudaCapture,
            trainer._minibatch_step, TorchTetherVecEnv.step_kernel,
            TorchTetherVecEnv.step_autoreset, NumbaCpuStep._launch,
            TorchTetherVecEnv.step_begin, TorchTetherVecEnv.step_end)
    adam = _in_phase(counter, "adam", real[2])

    def adam_step(self, *args, **kwargs):
        return adam(self, *args, **kwargs)

    def minibatch_step(*args, **kwargs):  # its Python runs eagerly or in a capture only
        minibatches[0] += 1
        return real[5](*args, **kwargs)

    def kernel(self, reset):
        counter.ops[counter.phase, "numba_kernel"] += 1
        return real[8](self, reset)

    class CountedCapture(graph_module.RecordingCapture):
        def capture(self, fn, generators=()):
            replay = super().capture(fn, generators)

            def counted():
                counter.ops[counter.phase, "graph_replay"] += 1
                counter.on = False
                try:
                    replay()
                finally:
                    counter.on = True
            return counted

    trainer._update = _in_phase(counter, "update", real[0])
    trainer.evaluate_on_device = lambda *args, **kwargs: {}
    adam_class.step = adam_step
    TorchTetherVecEnv.step = _in_phase(counter, "env", real[3])
    TorchTetherVecEnv.step_kernel = _in_phase(counter, "env", real[6])
    TorchTetherVecEnv.step_autoreset = _in_phase(counter, "env", real[7])
    NumbaCpuStep._launch = kernel
    TorchTetherVecEnv.step_begin = _in_phase(counter, "env", real[9])
    TorchTetherVecEnv.step_end = _in_phase(counter, "env", real[10])
    trainer._minibatch_step = minibatch_step
    if graphs:
        graph_module.CudaCapture = CountedCapture
        torch.optim.Adam = lambda params, **kw: adam_class(params, **{**kw, "fused": True})
    try:
        with tempfile.TemporaryDirectory() as out, counter:
            run = GpuRun([0], iterations * settings.n_steps * settings.n_envs, env_kwargs,
                         Path(out), torch.device("cpu"), checkpoints=1, eval_episodes=1,
                         backend=backend, cuda_graphs=graphs, sync_free=sync_free)
            train_seeds(settings, run, log=None)
    finally:
        (trainer._update, trainer.evaluate_on_device, adam_class.step,
         TorchTetherVecEnv.step, graph_module.CudaCapture,
         trainer._minibatch_step, TorchTetherVecEnv.step_kernel,
         TorchTetherVecEnv.step_autoreset, NumbaCpuStep._launch,
         TorchTetherVecEnv.step_begin, TorchTetherVecEnv.step_end) = real
        torch.optim.Adam = adam_class
    return counter, minibatches[0]


def count(config: Path, backend: str, iterations: int, graphs: bool = False,
          sync_free: bool = False) -> dict:
    """Operations per rollout step and per minibatch step, from two runs' difference.

    A run of ``iterations`` iterations and one of twice as many: the difference of their
    counts is ``iterations`` iterations' operations, without the start (env, policy,
    reset) and the checkpoint's files, which both runs make once.
    """
    from tether_gym_agents.accel.cli import read_config

    settings, _, env_kwargs = read_config(config)[:3]
    one, mb_one = _run(settings, env_kwargs, backend, iterations, graphs, sync_free)
    two, mb_two = _run(settings, env_kwargs, backend, 2 * iterations, graphs, sync_free)
    per_iteration = two.ops.copy()
    per_iteration.subtract(one.ops)
    phases = two.by_phase()
    phases.subtract(one.by_phase())
    if graphs:  # a replay runs no Python: the update's minibatch steps by their number
        M = settings.n_steps * settings.n_envs
        minibatches = settings.n_epochs * -(-M // min(settings.batch_size, M))
    else:       # the minibatch steps the trainer called
        minibatches = (mb_two - mb_one) // iterations    # per iteration
    per_env = phases["env"] / (iterations * settings.n_steps)
    per_step = phases["rollout"] / (iterations * settings.n_steps) + per_env
    per_update = phases["update"] / (iterations * minibatches)
    per_adam = phases["adam"] / (iterations * minibatches)
    in_rollout = per_step * settings.n_steps
    in_updates = (per_update + per_adam) * minibatches
    top = Counter({k: v // iterations for k, v in per_iteration.items() if v > 0})
    return {"config": str(config), "backend": backend, "cuda_graphs": graphs,
            "sync_free": sync_free, "iterations": iterations,
            "n_steps": settings.n_steps, "minibatches_per_iteration": minibatches,
            "ops_per_rollout_step": round(per_step, 1),
            "of_which_env_step": round(per_env, 1),
            "ops_per_minibatch_step": round(per_update + per_adam, 1),
            "of_which_adam": round(per_adam, 1),
            "ops_per_iteration": round(in_rollout + in_updates),
            "rollout_share": round(in_rollout / (in_rollout + in_updates), 3),
            "host_syncs_per_rollout_step": round(
                (per_iteration["rollout", SYNC] + per_iteration["env", SYNC])
                / (iterations * settings.n_steps), 2),
            "host_syncs_per_minibatch_step": round(
                per_iteration["update", SYNC] / (iterations * minibatches), 2),
            "per_iteration_most_frequent": [[f"{ph}:{name}", n]
                                            for (ph, name), n in top.most_common(10)]}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--config", type=Path, default=ROOT / "agents/configs/gpu_ppo.yml")
    p.add_argument("--backend", nargs="+", default=["torch", "numba"],
                   choices=["torch", "numba"])
    p.add_argument("--iterations", type=int, default=4)
    p.add_argument("--cuda-graphs", action="store_true",
                   help="count train.py gpu --cuda-graphs: a graph's replay is one launch")
    p.add_argument("--sync-free", action="store_true",
                   help="count train.py gpu --sync-free (the autoreset without host syncs)")
    args = p.parse_args(argv)
    if args.iterations < 1:
        p.error(f"--iterations must be >= 1, got {args.iterations}")
    if args.cuda_graphs and args.iterations <= WARMUP_STEPS:
        p.error(f"--cuda-graphs counts replays only from --iterations {WARMUP_STEPS + 1} on "
                f"(the advantages are captured at their call {WARMUP_STEPS + 1}), got "
                f"{args.iterations}")
    if not args.config.is_file():
        p.error(f"--config {str(args.config)!r} is not a file")
    torch.set_num_threads(1)
    for backend in args.backend:
        print(json.dumps(count(args.config, backend, args.iterations, args.cuda_graphs,
                               args.sync_free)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
