"""The rollout's own arithmetic in ``train.py gpu``, eager and fused (``--compile-rollout``).

    python bench/accel_rollout.py                      # configs/gpu_ppo.yml (J), 1 seed
    python bench/accel_rollout.py --seeds 10 --device cuda

A rollout step of the learner is the policy's half (:meth:`~tether_gym_agents.accel.
rollout.Rollout.act`: the action draws, the actions, their records), the env's step and
the learner's half (``take`` and :meth:`~tether_gym_agents.accel.rollout.Rollout.observe`:
the normalisation, the truncation bootstrap, the counts); after ``n_steps`` of them come
the advantages (:meth:`~tether_gym_agents.accel.rollout.Rollout.finish`). This script
runs the rollout's own pieces, without the env, on made-up env steps of the config's
size (random observations, rewards and ended rows: the arithmetic does not depend on the
values), once eagerly and once with ``compiled=True`` (each piece but the draws through
``torch.compile``), and for each reports, per rollout step (an iteration's count or time
divided by ``n_steps``, the advantages included):

* the kernels, from ``torch.profiler`` over one iteration after a warm-up iteration
  (which compiles), counted as ``bench/accel_update.py`` counts them (on the CPU
  Inductor's kernels and the outermost aten operations; on a CUDA device every kernel);
* the milliseconds (median of ``--repeats`` iterations, synced).

The env's step is not in these figures (``bench/accel_ops.py`` counts it,
``bench/accel_iteration.py --compile-rollout`` times the whole iteration). It prints one
JSON line.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from accel_update import _cpu_kernels, _cuda_kernels  # noqa: E402


def measure(config: Path, device: torch.device, seeds: int, repeats: int) -> dict:
    """The module docstring's figures for the config's rollout, eager and fused."""
    import torch._inductor.config as inductor_config
    from torch.profiler import ProfilerActivity, profile

    from tether_gym_agents.accel.cli import read_config
    from tether_gym_agents.accel.ppo import MultiSeedPolicy
    from tether_gym_agents.accel.rollout import Rollout
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    settings, _, env_kwargs = read_config(config)[:3]
    env = TorchTetherVecEnv(1, **env_kwargs)
    d, a = env.observation_dim, env.n
    S, N, T = seeds, settings.n_envs, settings.n_steps
    g = torch.Generator().manual_seed(0)
    f64 = torch.float64
    # T made-up env steps: raw observations, rewards, terminated, truncated, final obs
    made_up = [tuple(x.to(device) for x in (
        torch.randn((S * N, d), generator=g, dtype=f64), torch.randn(S * N, generator=g,
                                                                     dtype=f64),
        torch.rand(S * N, generator=g) < 0.01, torch.rand(S * N, generator=g) < 0.01,
        torch.randn((S * N, d), generator=g, dtype=f64))) for _ in range(T)]
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda"
                                           else [])

    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    out: dict = {}
    for fused in (False, True):
        torch.manual_seed(0)
        policy = MultiSeedPolicy(list(range(seeds)), d, a, settings, device)
        rollout = Rollout(policy, settings, d, a, device, compiled=fused)
        rollout.start(made_up[0][0])

        @torch.no_grad()
        def iteration(rollout=rollout) -> None:
            for step in made_up:
                rollout.act()
                rollout.take(*step)
                rollout.observe()
            rollout.finish()

        with inductor_config.patch({"cpp.enable_kernel_profile": True}):
            start = time.perf_counter()
            iteration()  # the warm-up: compiles when fused
            sync()
            first_s = time.perf_counter() - start
            with profile(activities=activities) as prof:
                iteration()
                sync()
        events = prof.events()
        kernels = _cuda_kernels(events) if device.type == "cuda" else _cpu_kernels(events)
        times = []
        for _ in range(repeats):
            sync()
            start = time.perf_counter()
            iteration()
            sync()
            times.append(time.perf_counter() - start)
        out["fused" if fused else "eager"] = {
            "kernels_per_rollout_step": round(sum(kernels.values()) / T, 1),
            "most_frequent": [[k, round(n / T, 1)] for k, n in kernels.most_common(6)],
            "ms_per_rollout_step": round(1e3 * statistics.median(times) / T, 4),
            "first_iteration_s": round(first_s, 2)}
    return {"device": str(device),
            "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None,
            "torch": torch.__version__, "config": str(config), "seeds": seeds,
            "envs_per_seed": N, "rollout_steps_per_iteration": T, "repeats": repeats, **out,
            "kernels_ratio": round(out["eager"]["kernels_per_rollout_step"]
                                   / out["fused"]["kernels_per_rollout_step"], 1),
            "time_ratio": round(out["eager"]["ms_per_rollout_step"]
                                / out["fused"]["ms_per_rollout_step"], 2)}


def main(argv=None) -> int:
    from tether_gym_agents.accel.vec_env import resolve_device

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--config", type=Path, default=ROOT / "agents/configs/gpu_ppo.yml")
    p.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:K or auto")
    p.add_argument("--seeds", type=int, default=1, help="seeds in the rollout (default 1)")
    p.add_argument("--repeats", type=int, default=5, help="timed iterations (default 5)")
    args = p.parse_args(argv)
    for name, value, high in (("--seeds", args.seeds, 64), ("--repeats", args.repeats, 1000)):
        if not 1 <= value <= high:
            p.error(f"{name} must be in [1, {high}], got {value}")
    if not args.config.is_file():
        p.error(f"--config {str(args.config)!r} is not a file")
    try:
        device = resolve_device(args.device)
    except (ValueError, ImportError) as exc:
        p.error(str(exc))
    torch.set_num_threads(1)
    print(json.dumps(measure(args.config, device, args.seeds, args.repeats)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
