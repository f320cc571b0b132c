"""Where an iteration of ``train.py gpu`` spends its wall time, part by part, on this device.

    python bench/accel_iteration.py --device cuda --backend numba-cuda --cuda-graphs
    python bench/accel_iteration.py --device cpu --backend numba      # the CPU, eager
    python bench/accel_iteration.py --device cpu --backend numba --compile-update
    python bench/accel_iteration.py --device cpu --backend numba --compile-update --compile-rollout
    python bench/accel_iteration.py --backend numba --compile --compile-update --compile-rollout

``bench/accel_ops.py`` counts what an iteration launches; this script times it. It runs
the learner's own ``train_seeds`` on a config (default ``configs/gpu_ppo.yml``, J, one
seed) twice, for ``--iterations`` iterations each, and times the iterations from the
5th on (the pieces are captured as graphs at their 4th call; a median is taken over the
timed iterations, so a later capture, of the reset's graphs, does not weigh):

1. as it trains: the wall time of each iteration, with one device sync at its end.
   This is what training costs per iteration. Times the config's iterations, it is
   the training time, start-up and compilation aside.
2. part by part: each part of an iteration between two device syncs, on the host's
   clock. The parts are the rollout step's (``act``: the policy's half, the action into
   the env and the env's first part; ``kernel``: a numba backend's launch; ``end``: its
   results into the env; ``autoreset``: the host's question whether a sub-env ended and
   the resets; ``observe``: the learner's half), the advantages (``finish``) and the
   updates (``update``: the minibatch orders and every minibatch step); where the whole
   rollout is one graph (``--cuda-graphs --sync-free`` on the torch backend or on
   numba-cuda), its replay (``rollout``: the step's parts are then 0). A part's time is
   then the device's time to run it plus what the host spends launching it. The syncs
   keep the host from running ahead of the device, so the parts add up to more than
   run 1's iteration: run 1 is the cost, run 2 says where it goes.

It prints one JSON line: the device, its name, the settings, run 1's median
milliseconds per iteration, run 2's per part, and run 1's time scaled to the config's
iterations. The final check of ``train_seeds`` (an evaluation on the device) is not run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FIRST_TIMED = 5
"""The first timed iteration (the pieces are captured at their 4th call)."""
PARTS = ("act", "kernel", "end", "autoreset", "observe", "finish", "rollout", "update")


def _run(config: Path, device: torch.device, iterations: int, parts: bool,
         options: dict) -> list[dict[str, float]]:
    """``iterations`` iterations of ``train_seeds``; per iteration {part or "total": s}.

    ``options``: :class:`~tether_gym_agents.accel.trainer.GpuRun`'s ``backend``,
    ``cuda_graphs``, ``compile``, ``compile_update``, ``compile_rollout`` and ``sync_free``.
    """
    from tether_gym_agents.accel import trainer
    from tether_gym_agents.accel.cli import read_config
    from tether_gym_agents.accel.graphs import RolloutStep

    settings, _, env_kwargs = read_config(config)[:3]

    def sync() -> None:
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    spent: dict[str, float] = defaultdict(float)
    done: list[dict[str, float]] = []
    clock = [time.perf_counter()]

    def timed(name, fn):
        def call(*args, **kwargs):
            sync()
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                sync()
                spent[name] += time.perf_counter() - start
        return call

    real_update, real_graphed_call = trainer._update, trainer.GraphedCall

    def update(*args, **kwargs):
        if parts:
            timed("update", real_update)(*args, **kwargs)
        else:
            real_update(*args, **kwargs)
        sync()
        now = time.perf_counter()
        done.append({**spent, "total": now - clock[0]})
        spent.clear()
        clock[0] = now

    class TimedStep(RolloutStep):
        def __init__(self, rollout, env, graphs=False, capture=None):
            super().__init__(rollout, env, graphs, capture)
            # inside the whole rollout's graph (a sync would break its capture): untimed
            if parts and not (options["cuda_graphs"] and env.whole_step_graph):
                self._act = timed("act", self._act)
                self._observe = timed("observe", self._observe)
                if self._end is not None:
                    self._end = timed("end", self._end)
                env.step_kernel = timed("kernel", env.step_kernel)
                env.step_autoreset = timed("autoreset", env.step_autoreset)

    def graphed_call(fn, *args, **kwargs):  # the advantages, or the whole rollout
        call = real_graphed_call(fn, *args, **kwargs)
        name = "finish" if fn.__name__ == "finish" else "rollout"
        return timed(name, call) if parts else call

    real = (trainer._update, trainer.GraphedCall, trainer.RolloutStep,
            trainer.evaluate_on_device)
    trainer._update, trainer.GraphedCall, trainer.RolloutStep = update, graphed_call, TimedStep
    trainer.evaluate_on_device = lambda *args, **kwargs: {}
    graphs = options["cuda_graphs"]
    if parts and not graphs:
        real_finish = trainer.Rollout.finish
        trainer.Rollout.finish = timed("finish", real_finish)  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory() as out:
            run = trainer.GpuRun([0], iterations * settings.n_steps * settings.n_envs,
                                 env_kwargs, Path(out), device, checkpoints=1,
                                 eval_episodes=1, **options)
            clock[0] = time.perf_counter()
            trainer.train_seeds(settings, run, log=None)
    finally:
        (trainer._update, trainer.GraphedCall, trainer.RolloutStep,
         trainer.evaluate_on_device) = real
        if parts and not graphs:
            trainer.Rollout.finish = real_finish  # type: ignore[method-assign]
    return done


def measure(config: Path, device: torch.device, iterations: int, options: dict) -> dict:
    """Run 1 and run 2 (the module docstring), summarised; ``options`` as :func:`_run`'s."""
    from tether_gym_agents.accel.cli import read_config

    settings, timesteps = read_config(config)[:2]
    plain = _run(config, device, iterations, False, options)
    split = _run(config, device, iterations, True, options)
    per_rollout = settings.n_steps * settings.n_envs
    n_updates = -(-timesteps // per_rollout)

    def median_ms(runs, key):
        return round(1e3 * statistics.median(r.get(key, 0.0) for r in runs[FIRST_TIMED - 1:]), 3)

    iteration_ms = median_ms(plain, "total")
    return {"device": str(device),
            "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None,
            "torch": torch.__version__, "config": str(config), **options,
            "iterations": iterations,
            "timed_iterations": iterations - FIRST_TIMED + 1,
            "ms_per_iteration": iteration_ms,
            "parts_ms_per_iteration": {k: median_ms(split, k) for k in PARTS},
            "parts_run_ms_per_iteration": median_ms(split, "total"),
            "config_iterations": n_updates,
            "config_training_s": round(iteration_ms * n_updates / 1e3, 1)}


def main(argv=None) -> int:
    from tether_gym_agents.accel.vec_env import check_backend, resolve_device

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--config", type=Path, default=ROOT / "agents/configs/gpu_ppo.yml")
    p.add_argument("--device", default="auto", help="cpu, cuda, cuda:K or auto")
    p.add_argument("--backend", default="torch", help="torch, numba (CPU) or numba-cuda")
    p.add_argument("--cuda-graphs", action="store_true", help="as train.py gpu --cuda-graphs")
    p.add_argument("--compile", action="store_true",
                   help="as train.py gpu --compile (the env's torch arithmetic; compiled at "
                        "the first steps, which are not timed)")
    p.add_argument("--compile-update", action="store_true",
                   help="as train.py gpu --compile-update (compiled at the first update, "
                        "which is not timed)")
    p.add_argument("--compile-rollout", action="store_true",
                   help="as train.py gpu --compile-rollout (compiled at the first "
                        "iteration, which is not timed)")
    p.add_argument("--sync-free", action="store_true",
                   help="as train.py gpu --sync-free (the autoreset without host syncs)")
    p.add_argument("--iterations", type=int, default=12)
    args = p.parse_args(argv)
    if args.iterations < FIRST_TIMED:
        p.error(f"--iterations must be >= {FIRST_TIMED} (the first {FIRST_TIMED - 1} are not "
                f"timed), got {args.iterations}")
    if not args.config.is_file():
        p.error(f"--config {str(args.config)!r} is not a file")
    try:
        device = resolve_device(args.device)
        check_backend(args.backend, device)
    except (ValueError, ImportError) as exc:
        p.error(str(exc))
    if args.cuda_graphs and device.type != "cuda":
        p.error("--cuda-graphs needs a CUDA device")
    torch.set_num_threads(1)
    options = {"backend": args.backend, "cuda_graphs": args.cuda_graphs,
               "compile": args.compile, "compile_update": args.compile_update,
               "compile_rollout": args.compile_rollout, "sync_free": args.sync_free}
    print(json.dumps(measure(args.config, device, args.iterations, options)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
