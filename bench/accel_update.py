"""One minibatch step of ``train.py gpu``, eager and fused (``--compile-update``): kernels and time.

    python bench/accel_update.py                       # configs/gpu_ppo.yml (J), 1 seed
    python bench/accel_update.py --seeds 10 --device cuda

On a GPU a minibatch step of a small policy costs its kernel launches (or, inside a
CUDA graph, the kernels' own start-up), not its arithmetic. This script runs the
learner's own update on a made-up rollout of the config's size (``n_steps`` x
``n_envs`` samples per seed, its minibatch size, one epoch), once eagerly
(:func:`~tether_gym_agents.accel.trainer._minibatch_steps` with Adam, fused on CUDA as
``train.py gpu`` asks) and once fused (:class:`~tether_gym_agents.accel.minibatch.CompiledSteps`
with :class:`~tether_gym_agents.accel.minibatch.PerSeedAdam`), and for each reports:

* kernels per minibatch step, from ``torch.profiler`` over one update after a warm-up
  update (which compiles): on a CUDA device the kernels the GPU ran; on the CPU the
  operations that run a loop of their own, that is Inductor's fused kernels (profiled
  with ``torch._inductor.config.cpp.enable_kernel_profile``) and the outermost aten
  operations, views and allocations left out. The CPU's count is what Inductor makes of
  the step for the CPU; its CUDA code fuses by the same rules into other kernels, so a
  GPU's count is its own;
* milliseconds per minibatch step (median of ``--repeats`` updates, synced).

It prints one JSON line. The eager count here can differ a little from
``bench/accel_ops.py``'s (another counter: the profiler's outermost operations, with
the optimizer's inner operations, against every dispatched operation).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import Counter
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from accel_ops import VIEWS  # noqa: E402

NOT_KERNELS = VIEWS | {"resolve_conj", "resolve_neg", "empty", "empty_like", "empty_strided",
                       "result_type", "promote_types", "is_nonzero", "size", "stride",
                       "numel"}
"""aten operations that run no loop of their own: accel_ops.py's views, and allocations
and the like."""


def _cpu_kernels(events) -> Counter:
    """The CPU profile's kernels by name: Inductor's, and the outermost aten operations."""
    out: Counter = Counter()
    for e in events:
        if "cpp_fused" in e.name:
            out["inductor"] += 1
            continue
        if not e.name.startswith("aten::") or e.name[6:].rstrip("_") in NOT_KERNELS:
            continue
        parent, nested = e.cpu_parent, False
        while parent is not None:
            if parent.name.startswith("aten::"):
                nested = True
                break
            parent = parent.cpu_parent
        if not nested:
            out[e.name[6:].rstrip("_")] += 1
    return out


def _cuda_kernels(events) -> Counter:
    """The CUDA profile's kernels (every kernel the device ran), by kind."""
    out: Counter = Counter()
    for e in events:
        if e.device_type == torch.autograd.DeviceType.CUDA:
            out["triton" if "triton" in e.name else "other"] += 1
    return out


def kernels_and_time(fn, device: torch.device, repeats: int, per: int, unit: str,
                     first: str) -> dict:
    """One column of the figures: ``fn`` (a whole update or iteration) profiled and timed.

    Its first call (the warm-up, which compiles a fused ``fn``) is timed as ``first``
    [s]; one profiled call then gives the kernels per ``unit`` (the call's count divided
    by ``per``), and ``repeats`` more calls the milliseconds per ``unit`` (median).
    """
    import torch._inductor.config as inductor_config
    from torch.profiler import ProfilerActivity, profile

    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda"
                                           else [])

    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    # Inductor's CPU kernels show in the profile (this process's setting, restored after)
    with inductor_config.patch({"cpp.enable_kernel_profile": True}):
        start = time.perf_counter()
        fn()
        sync()
        first_s = time.perf_counter() - start
        with profile(activities=activities) as prof:
            fn()
            sync()
    events = prof.events()
    kernels = _cuda_kernels(events) if device.type == "cuda" else _cpu_kernels(events)
    times = []
    for _ in range(repeats):
        sync()
        start = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - start)
    return {f"kernels_per_{unit}": round(sum(kernels.values()) / per, 1),
            "most_frequent": [[k, round(n / per, 1)] for k, n in kernels.most_common(6)],
            f"ms_per_{unit}": round(1e3 * statistics.median(times) / per, 4),
            first: round(first_s, 2)}


def summary(config: Path, device: torch.device, seeds: int, out: dict, unit: str,
            **sizes) -> dict:
    """The JSON line: the machine, the settings ``sizes``, both columns and their ratios."""
    eager, fused = out["eager"], out["fused"]
    return {"device": str(device),
            "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None,
            "torch": torch.__version__, "config": str(config), "seeds": seeds, **sizes,
            **out,
            "kernels_ratio": round(eager[f"kernels_per_{unit}"] / fused[f"kernels_per_{unit}"],
                                   1),
            "time_ratio": round(eager[f"ms_per_{unit}"] / fused[f"ms_per_{unit}"], 2)}


def measure(config: Path, device: torch.device, seeds: int, repeats: int) -> dict:
    """The module docstring's figures for the config's update, eager and fused."""
    from tether_gym_agents.accel.cli import read_config
    from tether_gym_agents.accel.minibatch import ADAM_EPS, CompiledSteps, PerSeedAdam
    from tether_gym_agents.accel.ppo import MultiSeedPolicy
    from tether_gym_agents.accel.trainer import _minibatch_steps, _permutations
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    settings, _, env_kwargs = read_config(config)[:3]
    env = TorchTetherVecEnv(1, **env_kwargs)
    d, a = env.observation_dim, env.n
    M = settings.n_steps * settings.n_envs
    per_update = -(-M // min(settings.batch_size, M))
    g = torch.Generator().manual_seed(0)
    batch = tuple(x.to(device) for x in (
        torch.randn((seeds, M, d), generator=g), 0.05 * torch.randn((seeds, M, a), generator=g),
        torch.randn((seeds, M), generator=g), torch.randn((seeds, M), generator=g),
        torch.randn((seeds, M), generator=g)))
    lr = torch.full((seeds,), settings.learning_rate, device=device)
    out: dict = {}
    for fused in (False, True):
        policy = MultiSeedPolicy(list(range(seeds)), d, a, settings, device)
        if fused:
            opt = PerSeedAdam(policy.parameters(), settings.max_grad_norm)
            steps = CompiledSteps()
        else:
            opt = torch.optim.Adam(policy.parameters(), lr=1.0, eps=ADAM_EPS,
                                   fused=device.type == "cuda")
            steps = _minibatch_steps

        def update(steps=steps, policy=policy, opt=opt) -> None:
            steps(policy, opt, lr, settings, batch, _permutations(1, seeds, M, device))

        out["fused" if fused else "eager"] = kernels_and_time(
            update, device, repeats, per_update, "minibatch_step", "first_update_s")
    return summary(config, device, seeds, out, "minibatch_step", samples_per_seed=M,
                   minibatch_steps_per_update=per_update, repeats=repeats)


def cli(measure_fn, description: str, what: str, argv=None, env: bool = False) -> int:
    """The command line of this script and of ``accel_rollout.py``: parse, check, measure.

    ``measure_fn(config, device, seeds, repeats)`` gives the JSON line; ``what`` names
    what ``--seeds`` and ``--repeats`` count in the help. ``env``: an ``--env BACKEND``
    option too, checked on the device and passed on as ``env=``, and ``--sync-free``
    (with ``--env``), passed on as ``sync_free=``.
    """
    from tether_gym_agents.accel.vec_env import check_backend, resolve_device

    p = argparse.ArgumentParser(description=description)
    p.add_argument("--config", type=Path, default=ROOT / "agents/configs/gpu_ppo.yml")
    p.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:K or auto")
    p.add_argument("--seeds", type=int, default=1, help=f"seeds in the {what} (default 1)")
    p.add_argument("--repeats", type=int, default=5, help=f"timed {what}s (default 5)")
    if env:
        p.add_argument("--env", default=None, metavar="BACKEND",
                       help="step a real env of this backend (numba on the CPU, numba-cuda "
                            "or torch) instead of made-up steps")
        p.add_argument("--sync-free", action="store_true",
                       help="with --env: its autoreset without host syncs (train.py gpu "
                            "--sync-free)")
    args = p.parse_args(argv)
    for name, value, high in (("--seeds", args.seeds, 64), ("--repeats", args.repeats, 1000)):
        if not 1 <= value <= high:
            p.error(f"{name} must be in [1, {high}], got {value}")
    if not args.config.is_file():
        p.error(f"--config {str(args.config)!r} is not a file")
    if env and args.sync_free and args.env is None:
        p.error("--sync-free needs --env BACKEND (a real env)")
    try:
        device = resolve_device(args.device)
        if env and args.env is not None:
            check_backend(args.env, device)
    except (ValueError, ImportError) as exc:
        p.error(str(exc))
    torch.set_num_threads(1)
    kwargs = {"env": args.env, "sync_free": args.sync_free} if env else {}
    print(json.dumps(measure_fn(args.config, device, args.seeds, args.repeats, **kwargs)),
          flush=True)
    return 0


def main(argv=None) -> int:
    return cli(measure, __doc__.split("\n")[0], "update", argv)


if __name__ == "__main__":
    sys.exit(main())
