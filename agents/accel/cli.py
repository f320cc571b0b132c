"""``python train.py gpu``: PPO with the env and the learner on one torch device.

    python train.py gpu --config configs/gpu_ppo.yml --seeds 10 --out runs/ppo_gpu

trains seeds --seed .. --seed+N-1 in one process (all at once, each with its own envs,
statistics and weights) and writes ``OUT/seed_K/`` run folders that ``python
evaluate.py OUT`` scores on the standard numba env, and ``python evaluate.py curves
OUT`` along its checkpoints. ``--device auto`` (default) takes the GPU when torch sees
one, else the CPU (slow, but the same code: what the tests run).
"""

from __future__ import annotations

import argparse
import math
import shlex
import shutil
import sys
import time
from dataclasses import fields
from pathlib import Path

from tether_gym.envs.vector import MAX_NUM_ENVS

from ..common.ranges import interval
from ..common.yamlio import MAX_YAML_BYTES

__all__ = ["main", "read_config", "DEFAULT_CONFIG"]

DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "gpu_ppo.yml"
MAX_CONFIG_BYTES = MAX_YAML_BYTES
"""A config file larger than this [bytes] is refused before it is parsed."""
MAX_SEEDS = 64
MAX_ROLLOUT_BYTES = 1 << 35
"""What one iteration's samples may keep at their peak [bytes], 32 GiB
(:func:`rollout_bytes`). Checked before any work, so that a config asking for more than
a machine holds is refused in one line rather than after start-up, or by the kernel's
out-of-memory killer."""


def rollout_bytes(settings, seeds: int, obs_dim: int, act_dim: int) -> int:
    """The peak memory of one iteration's samples [bytes], for :data:`MAX_ROLLOUT_BYTES`.

    Per rollout sample and seed, the rollout's buffers and batch keep 2 (obs + act) + 9
    float32 and the minibatch orders 16 bytes per epoch (drawn int64, then stacked); per
    minibatch sample and seed, the two networks' forward and backward keep about
    2 (obs + act + 3 x the hidden widths) float32. ``ppo_accel``'s ten seeds in one
    process: about 30 MB (82k samples, 20 observations, 2 reels, 10 epochs).

    Measured on the CPU (``python train.py gpu --device cpu --backend numba``, one
    iteration of 256 envs, 1 epoch, peak resident memory): 4,096 steps against 16 added
    229.8 MB at minibatches of 1024 (this formula: 238.1 MB), and minibatches of 65,536
    against 1024 added 241.9 MB more (this formula: 209.5 MB).
    """
    samples = seeds * settings.n_envs * settings.n_steps
    minibatch = seeds * min(settings.batch_size, settings.n_envs * settings.n_steps)
    hidden = sum(settings.net_arch)
    return (samples * (4 * (2 * (obs_dim + act_dim) + 9) + 16 * settings.n_epochs)
            + minibatch * 8 * (obs_dim + act_dim + 3 * hidden))


CPU_COMPILERS = ("g++", "c++", "clang++")
"""The C++ compilers one of which torch.compile's CPU code (Inductor) needs."""
COMPILE_FLAGS = {
    "--compile": "fuse the env's torch arithmetic with torch.compile (the torch backend's "
                 "whole step; a numba backend's copies, masks and resets around its "
                 "kernel); compiles at the first steps",
    "--compile-update": "fuse each minibatch step's arithmetic with torch.compile (the "
                        "loss's forward and backward; clipping, Adam and the per-seed "
                        "rates in one function); compiles at the first update; docs/gpu.md",
    "--compile-rollout": "fuse the rollout's arithmetic with torch.compile (the policy's "
                         "half of each step after its draws, the learner's half, the "
                         "advantages); compiles at the first steps; docs/gpu.md",
}
"""The flags that run part of a run through torch.compile, each a
:class:`~.trainer.GpuRun` field of the same name (``--compile-update``:
``compile_update``), and their help."""


class GpuConfigError(ValueError):
    """A bad ``train.py gpu`` argument or config value (printed as one line, exit 2)."""


def _check_number(path, key, value, low, high, integer=False):
    """``value`` as an int/float in [low, high], or GpuConfigError naming file and key."""
    kind = int if integer else float
    ok = (not isinstance(value, bool) and isinstance(value, (int, float))
          and (not integer or float(value).is_integer()) and low <= value <= high)
    if not ok:
        what = "an integer" if integer else "a number"
        raise GpuConfigError(f"{path}: {key}={value!r} must be {what} in {interval(low, high)}")
    return kind(value)


_BOUNDS = {  # key: (low, high, integer)
    "n_envs": (1, MAX_NUM_ENVS, True), "n_steps": (1, 4096, True),
    "batch_size": (1, 1 << 24, True), "n_epochs": (1, 100, True),
    "gamma": (0.0, 1.0, False), "gae_lambda": (0.0, 1.0, False),
    "learning_rate": (1e-8, 1.0, False), "clip_range": (1e-4, 10.0, False),
    "ent_coef": (0.0, 1.0, False), "vf_coef": (0.0, 10.0, False),
    "max_grad_norm": (1e-6, 1e3, False), "log_std_init": (-20.0, 2.0, False),
    "clip_obs": (1e-3, 1e6, False), "clip_reward": (1e-3, 1e6, False),
    "norm_epsilon": (1e-12, 1.0, False), "desired_kl": (1e-6, 1.0, False),
}


def read_config(path: Path) -> tuple:
    """(PPOSettings, n_timesteps, env_kwargs, checkpoints) from a ``gpu_ppo`` YAML file.

    One block keyed by the env id holds the keys: those of :class:`~.ppo.PPOSettings`,
    ``n_timesteps`` (env steps per seed), ``checkpoints`` (agent snapshots per run) and
    ``env_kwargs``; unknown keys, values out of range and files that are not small plain
    YAML (aliases included) raise GpuConfigError.
    """
    from ..common.yamlio import YamlFileError, load_yaml_file
    from .ppo import PPOSettings

    path = Path(path)
    try:  # a regular file of at most MAX_CONFIG_BYTES, no aliases, bounded depth
        doc = load_yaml_file(path, what="config", max_bytes=MAX_CONFIG_BYTES)
    except YamlFileError as exc:
        why = str(exc).removeprefix(f"config {path}").lstrip(": ").removeprefix(
            "not valid YAML: ")
        raise GpuConfigError(f"config {path} is not readable YAML: {why}") from None
    import tether_gym

    if not isinstance(doc, dict) or set(doc) != {tether_gym.ENV_ID} \
            or not isinstance(doc[tether_gym.ENV_ID], dict):
        raise GpuConfigError(f"config {path} must hold one mapping keyed by the env id "
                             f"{tether_gym.ENV_ID!r} (as every file of configs/), got "
                             f"{sorted(doc) if isinstance(doc, dict) else type(doc).__name__}")
    doc = doc[tether_gym.ENV_ID]
    names = {f.name for f in fields(PPOSettings)}
    extra = {"n_timesteps", "env_kwargs", "checkpoints"}
    unknown = sorted(set(doc) - names - extra)
    if unknown:
        raise GpuConfigError(f"{path}: unknown key(s) {unknown}; valid: "
                             f"{sorted(names | extra)}")
    values = {}
    for key, value in doc.items():
        if key in _BOUNDS:
            low, high, integer = _BOUNDS[key]
            values[key] = _check_number(path, key, value, low, high, integer)
    if "net_arch" in doc:
        arch = doc["net_arch"]
        if (not isinstance(arch, list) or not 1 <= len(arch) <= 4
                or not all(isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= 1024
                           for w in arch)):
            raise GpuConfigError(f"{path}: net_arch={arch!r} must be a list of 1 to 4 "
                                 "layer widths in [1, 1024]")
        values["net_arch"] = tuple(arch)
    if "lr_schedule" in doc:
        if doc["lr_schedule"] not in ("linear", "constant", "adaptive"):
            raise GpuConfigError(f"{path}: lr_schedule={doc['lr_schedule']!r} must be "
                                 "'linear', 'constant' or 'adaptive'")
        values["lr_schedule"] = doc["lr_schedule"]
    steps = _check_number(path, "n_timesteps", doc.get("n_timesteps", 5_000_000), 1, 1e10,
                          integer=True)
    checkpoints = _check_number(path, "checkpoints", doc.get("checkpoints", 10), 1, 100,
                                integer=True)
    env_kwargs = doc.get("env_kwargs") or {}
    if not isinstance(env_kwargs, dict) or not all(isinstance(k, str) for k in env_kwargs):
        raise GpuConfigError(f"{path}: env_kwargs must be a mapping of argument names, got "
                             f"{env_kwargs!r}")
    return PPOSettings(**values), steps, env_kwargs, checkpoints


def _field(flag: str) -> str:
    """A flag's argparse and ``GpuRun`` name: ``--compile-update`` -> ``compile_update``."""
    return flag[2:].replace("-", "_")


def build_parser() -> argparse.ArgumentParser:
    """The arguments of ``train.py gpu``."""
    p = argparse.ArgumentParser(prog="train.py gpu",
                                description="PPO with env and learner on one torch device.")
    p.add_argument("--config", type=Path, default=DEFAULT_CONFIG,
                   help="gpu_ppo YAML (default: the packaged configs/gpu_ppo.yml)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--seeds", type=int, default=1, help="seeds trained at once (default 1)")
    p.add_argument("--timesteps", type=int, default=None, help="env steps per seed")
    p.add_argument("--n-envs", type=int, default=None, help="envs per seed")
    p.add_argument("--device", default="auto", help="cuda, cuda:K, cpu or auto (default)")
    p.add_argument("--out", type=Path, default=Path("runs/ppo_gpu"), help="output folder")
    p.add_argument("--backend", default="torch",
                   help="the env's step: torch (default: torch operations), numba (the numba "
                        "env's own row step, CPU) or numba-cuda (that row step compiled for "
                        "the GPU); docs/gpu.md")
    p.add_argument("--cuda-graphs", action="store_true",
                   help="capture the learner's pieces (the rollout step's two halves, the "
                        "advantages, the minibatch step) as CUDA graphs and replay them; "
                        "with --sync-free on the torch or numba-cuda backend the whole "
                        "rollout is one graph (CUDA devices only; not yet measured on a "
                        "GPU: docs/gpu.md)")
    for flag, text in COMPILE_FLAGS.items():
        p.add_argument(flag, action="store_true", help=text)
    p.add_argument("--sync-free", action="store_true",
                   help="the env's autoreset without host syncs: one reset attempt every "
                        "step, a failed start not drawn again in its step (docs/gpu.md), "
                        "so that the host does not wait for the device at each step")
    p.add_argument("--max-seconds", type=float, default=None,
                   help="stop after the update that passes this wall time [s] (start-up "
                        "included); the runs record the steps reached, and a linear "
                        "learning rate falls to 0 at this time, counted from the end of "
                        "the first update (compiles and captures)")
    return p


def main(argv=None, clock_start: float | None = None) -> int:
    """Parse, train and print a summary; 2 with one line on a bad argument."""
    start = time.perf_counter() if clock_start is None else clock_start
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    try:
        import torch  # noqa: F401
    except ImportError:
        print('train.py gpu: error: needs torch: pip install -e ".[gpu]" (on CPU-only '
              "machines pip install torch==2.13.0 first)", file=sys.stderr)
        return 2
    from dataclasses import replace

    from tether_gym.envs.config import EnvConfig

    from .trainer import GpuRun, check_out, train_seeds
    from .vec_env import check_backend, resolve_device

    try:
        settings, steps, env_kwargs, checkpoints = read_config(args.config)
        if not 0 <= args.seed <= 2**31 - 1:
            raise GpuConfigError(f"--seed={args.seed} must be in [0, {2**31 - 1}]")
        if not 1 <= args.seeds <= MAX_SEEDS:
            raise GpuConfigError(f"--seeds={args.seeds} must be in [1, {MAX_SEEDS}]")
        if args.timesteps is not None:
            steps = _check_number("--timesteps", "value", args.timesteps, 1, 1e10, True)
        if args.n_envs is not None:
            settings = replace(settings, n_envs=_check_number("--n-envs", "value",
                                                              args.n_envs, 1, MAX_NUM_ENVS, True))
        if settings.n_envs * args.seeds > MAX_NUM_ENVS:  # the seeds share one vector env
            raise GpuConfigError(f"n_envs x seeds = {settings.n_envs * args.seeds} must be "
                                 f"<= {MAX_NUM_ENVS}")
        try:
            config = EnvConfig.from_kwargs(**env_kwargs)
        except (TypeError, ValueError) as exc:  # TypeError: a value of the wrong type
            raise GpuConfigError(f"{args.config}: env_kwargs: {exc}") from None
        need = rollout_bytes(settings, args.seeds, config.obs_dim, config.n_tethers)
        if need > MAX_ROLLOUT_BYTES:
            raise GpuConfigError(f"n_envs x n_steps x seeds = {settings.n_envs} x "
                                 f"{settings.n_steps} x {args.seeds} samples per rollout "
                                 f"with n_epochs={settings.n_epochs} would keep "
                                 f"{need / 2**30:,.1f} GiB; at most "
                                 f"{MAX_ROLLOUT_BYTES / 2**30:g} GiB (fewer envs, steps, "
                                 "seeds or epochs)")
        if str(args.out) in ("", "."):
            raise GpuConfigError("--out must name a new or existing run folder, not ''")
        max_seconds = (math.inf if args.max_seconds is None else
                       _check_number("--max-seconds", "value", args.max_seconds, 1.0, 1e7))
        device = resolve_device(args.device)
        check_backend(args.backend, device, compile=args.compile)
        fused = {_field(flag): getattr(args, _field(flag)) for flag in COMPILE_FLAGS}
        compiles = [flag for flag in COMPILE_FLAGS if fused[_field(flag)]]
        if (compiles and device.type == "cpu"
                and not any(shutil.which(cxx) for cxx in CPU_COMPILERS)):
            flag = compiles[0]
            raise GpuConfigError(f"{flag} on the CPU needs a C++ compiler for torch.compile "
                                 f"(one of {', '.join(CPU_COMPILERS)} on the PATH; for "
                                 f"instance apt install g++), or leave out {flag}")
        if args.cuda_graphs and device.type != "cuda":
            raise GpuConfigError(f"--cuda-graphs needs a CUDA device (--device cuda or "
                                 f"auto on a GPU machine), got --device {args.device!r} "
                                 f"-> {device}")
        seeds = list(range(args.seed, args.seed + args.seeds))
        check_out(args.out, seeds)  # last: it makes the seed folders
    except (ValueError, ImportError) as exc:
        print(f"train.py gpu: error: {exc}", file=sys.stderr)
        return 2
    command = "python train.py gpu " + " ".join(shlex.quote(a) for a in argv)
    print(f"train.py gpu: {len(seeds)} seed(s) x {settings.n_envs} envs on {device}, "
          f"{steps} env steps per seed -> {args.out}")
    summary = train_seeds(settings, GpuRun(seeds, steps, env_kwargs, args.out, device,
                                           checkpoints=checkpoints, command=command,
                                           clock_start=start, max_seconds=max_seconds,
                                           backend=args.backend,
                                           cuda_graphs=args.cuda_graphs,
                                           sync_free=args.sync_free, **fused))
    print(f"train.py gpu: done, {summary['steps_per_seed']} steps per seed in "
          f"{summary['wall_time_s']:.1f} s ({summary['env_steps_per_s']:,.0f} env steps/s "
          "over all seeds, start-up included)")
    final = summary["final"]
    for i, seed in enumerate(seeds):
        print(f"  seed {seed}: training distribution, deterministic, 64 episodes: survived "
              f"{final['survived'][i]:.3f}, tracking RMS {final['tracking_rms'][i]} rad, "
              f"return {final['mean_return'][i]:.1f}")
    return 0
