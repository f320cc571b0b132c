"""Train many seeds of one configuration as Ray tasks: the code behind ``train.py --seeds N``.

``python train.py --algo ppo --seeds 10 --out runs/ppo`` trains seeds ``--seed`` ...
``--seed + 9``, each into its own normal run folder ``runs/ppo/seed_K/``. Every seed
is one call of the single-run :func:`tether_gym_agents.training.train.main`, in-process
inside a Ray task, with the command line that ``train.py --seed K --out
runs/ppo/seed_K`` would get (``command.txt`` in the folder records it), so a seed
folder is exactly a single-seed run folder.

Where the tasks run
    By default a new local Ray instance sized to the machine
    (``num_cpus=os.cpu_count()``, no dashboard), stopped at the end;
    ``--ray-address auto|HOST:PORT`` (or the ``RAY_ADDRESS`` environment variable)
    connects to an existing cluster instead. Each task asks for ``--torch-threads``
    CPUs (default 1) and runs with that many torch threads and one numba thread
    (``NUMBA_NUM_THREADS=1``, ``OMP_NUM_THREADS=1`` and ``MKL_NUM_THREADS=1``: the
    local workers inherit them, a cluster's get them as the job's runtime
    environment); each seed's log states the counts it ran with. On a cluster ``--out``
    must be a path every node sees (a shared NFS mount): the tasks write the run
    folders there directly, and relative paths given on the command line are made
    absolute on the machine that runs ``train.py``.

Re-running the same command
    A seed whose ``train_info.json`` records ``num_timesteps`` >= the target
    (``--timesteps``, else the config's ``n_timesteps``) is skipped. A seed with a
    checkpoint or a final model but fewer steps is continued with ``train.py
    --resume`` for the missing steps (the resume logic of the single run picks the
    checkpoint and continues its step counter); one that never reached a checkpoint
    starts again from scratch.

Progress
    Everything a seed prints (SB3's training tables and evaluation lines,
    ``--verbose`` is raised to 1) goes to ``<out>/seed_K/train.log``; the command
    prints one summary line per seed as it finishes (steps, wall time of this call
    and of the whole run) and appends it to ``<out>/fanout.log``.

Ray is an optional dependency (``pip install "tether_gym[ray]"``); a single-seed
``train.py`` never imports it, and neither does ``--seeds 1`` without
``--ray-address`` or ``RAY_ADDRESS`` (it trains in this process). Ctrl-C stops every
task; the same command then resumes them.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import os
import re
import sys
import time
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

from .train import ConfigError, load_hyperparams, parse_env_kwargs

__all__ = ["RAY_PIP", "RunState", "SeedJob", "run_from_args", "run_jobs", "init_ray",
           "require_ray", "run_state", "train_seed", "seed_argv", "target_timesteps",
           "config_path"]

RAY_PIP = 'pip install "tether_gym[ray]"'
#: Environment of every Ray task: one numba, OpenMP and MKL thread per run.
TASK_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: Calls of the single-run main per seed and invocation: the first continues from the
#: latest checkpoint; the next ones top up if the resume had to fall back further.
MAX_CALLS = 3
_STEPS_IN_NAME = re.compile(r"_(\d+)_steps")
INTERRUPTED = ("interrupted: run the same command again to resume the unfinished runs from "
               "their last checkpoints (finished runs are skipped)")


class RunState(Enum):
    """What a run folder holds relative to its step target."""

    NEW = "new"  # nothing to continue from: train from scratch
    PARTIAL = "partial"  # a checkpoint or final model below the target: resume
    DONE = "done"  # train_info.json reaches the target: skip


@dataclass(frozen=True)
class SeedJob:
    """One seed's training: its single-run command line and where it goes.

    Attributes
    ----------
    label : str
        Name in progress lines, e.g. ``"seed 3"`` or ``"trial 2 seed 3"``.
    run_dir : Path
        The seed's run folder (absolute).
    argv : tuple of str
        ``train.py`` arguments of a fresh single run into ``run_dir``.
    target : int
        Env steps the finished run has [-].
    """

    label: str
    run_dir: Path
    argv: tuple[str, ...]
    target: int


def require_ray():
    """``import ray``, or a ConfigError with the pip command when it is missing."""
    try:
        import ray
    except ImportError as exc:
        raise ConfigError(f"--seeds > 1, --sweep and --ray-address run on Ray, which is not "
                          f"installed: {RAY_PIP}") from exc
    return ray


def init_ray(address: str | None = None) -> bool:
    """Start or join Ray unless it is already initialised; True if this call started it.

    Parameters
    ----------
    address : str or None
        ``"auto"``, ``"HOST:PORT"`` or ``"ray://HOST:PORT"`` of an existing cluster;
        None uses ``RAY_ADDRESS`` when it is set, else starts a local instance with
        ``num_cpus=os.cpu_count()`` and no dashboard.
    """
    ray = require_ray()
    if ray.is_initialized():
        return False
    address = address or os.environ.get("RAY_ADDRESS") or None
    quiet = {"logging_level": logging.WARNING, "log_to_driver": False}
    if address:  # the workers of other nodes get the thread settings as a runtime env
        try:
            ray.init(address=address, runtime_env={"env_vars": dict(TASK_ENV)}, **quiet)
        except (ConnectionError, RuntimeError) as exc:
            raise ConfigError(
                f"cannot connect to the Ray cluster at --ray-address/RAY_ADDRESS {address!r} "
                f"({type(exc).__name__}: {str(exc).splitlines()[0]}). Start it with `ray start "
                f"--head` and give its address; a cluster with token authentication needs its "
                f"token here too (RAY_AUTH_MODE=token and RAY_AUTH_TOKEN, as on its nodes)"
            ) from exc
        return True
    # A local instance's workers inherit the environment of the processes ray.init
    # starts: the same settings without a runtime env, whose set-up was measured to
    # add about 4 s to the first tasks on a busy 2-core machine.
    saved = {k: os.environ.get(k) for k in TASK_ENV}
    os.environ.update(TASK_ENV)
    try:
        # "local": a new instance even when a `ray start` cluster runs on this machine
        ray.init(address="local", num_cpus=os.cpu_count(), include_dashboard=False, **quiet)
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return True


def target_timesteps(args: argparse.Namespace) -> int:
    """Env steps each run must reach: ``--timesteps``, else the config's ``n_timesteps``."""
    if args.timesteps is not None:
        if args.timesteps < 1:
            raise ConfigError(f"--timesteps must be >= 1, got {args.timesteps}")
        return int(args.timesteps)
    params = load_hyperparams(config_path(args), args.algo, args.env_id)
    return int(params.get("n_timesteps", 1e5))


def config_path(args) -> Path:
    """The hyperparameter file of a run: ``--config``, else the packaged ``<algo>.yml``."""
    from .train import CONFIG_DIR

    return Path(args.config) if args.config else CONFIG_DIR / f"{args.algo}.yml"


class _ErrorLines(io.TextIOBase):
    """Writes through to ``stream`` and keeps the last ``train.py: error:`` line."""

    def __init__(self, stream):
        self.stream = stream
        self.last = ""

    def write(self, text: str) -> int:
        for line in text.splitlines():
            if line.startswith("train.py: error:"):
                self.last = line
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()


PATH_OPTIONS = ("config", "sweep")
"""Options of train.py that name files: made absolute for the tasks (other nodes)."""


def seed_argv(parser: argparse.ArgumentParser, args: argparse.Namespace, **changes) -> list[str]:
    """The ``train.py`` arguments that reproduce ``args`` with ``changes`` applied.

    Options equal to their default are left out and paths are made absolute, so the
    line can run on another node of the cluster. Works for any option the parser
    holds (``store``, ``store_true``/``store_false``, ``nargs``).
    """
    values = {**vars(args), **changes}
    out: list[str] = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or not action.option_strings:
            continue
        value = values.get(action.dest, action.default)
        if value == action.default:
            continue
        flag = action.option_strings[-1]
        if action.nargs == 0:  # store_true / store_false / store_const
            if value == action.const:
                out.append(flag)
            continue
        items = value if isinstance(value, (list, tuple)) else [value]
        out.append(flag)
        out.extend(str(Path(v).absolute())
                   if isinstance(v, Path) or action.dest in PATH_OPTIONS else str(v)
                   for v in items)
    return out


def run_state(run_dir: Path, target: int) -> tuple[RunState, int]:
    """State of a run folder and the env steps it has saved [-].

    ``DONE`` when ``train_info.json`` records ``num_timesteps >= target``;
    ``PARTIAL`` when a checkpoint (``checkpoints/model*_<N>_steps*``: the largest N
    counts) or a finished shorter run is there; ``NEW`` otherwise (including a
    folder killed before its first checkpoint, or one without ``config.yml``, which
    ``--resume`` needs). The step count only sizes the first ``--resume`` call; the
    resume logic of the single run chooses the checkpoint, and :func:`train_seed`
    tops up if it had to fall back to an earlier one.
    """
    run_dir = Path(run_dir)
    info = run_dir / "train_info.json"
    steps = -1
    if info.is_file():
        try:
            steps = int(json.loads(info.read_text())["num_timesteps"])
        except (ValueError, KeyError, TypeError):
            steps = -1
    if steps >= target:
        return RunState.DONE, steps
    ckpt_dir = run_dir / "checkpoints"
    if ckpt_dir.is_dir():
        for path in ckpt_dir.iterdir():
            match = _STEPS_IN_NAME.search(path.name)
            if match and path.name.startswith("model"):  # any saved piece of a checkpoint
                steps = max(steps, int(match.group(1)))
    if steps > 0 and (run_dir / "config.yml").is_file():
        return RunState.PARTIAL, steps
    return RunState.NEW, max(steps, 0)


def train_seed(job: SeedJob, threads: int = 1) -> dict:
    """Train one seed to its target in this process; the body of each Ray task.

    Fresh runs call the single-run ``main`` with ``job.argv``; partial ones with
    ``--resume --timesteps <missing steps>``. Output goes to ``run_dir/train.log``.

    Returns
    -------
    dict
        ``label``, ``run_dir``, ``status`` (``"trained"``, ``"skipped"`` or
        ``"failed"``), ``steps``, ``wall_s`` (this call) [s], ``run_wall_s`` (the
        run's ``wall_time_s``) [s], ``calls`` and ``message``.
    """
    import numba
    import torch

    from .train import main as train_main

    torch.set_num_threads(threads)
    with contextlib.suppress(ValueError):  # NUMBA_NUM_THREADS lower than `threads`
        limit = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
        numba.set_num_threads(min(threads, limit))
    t0 = time.perf_counter()
    result: dict[str, Any] = {"label": job.label, "run_dir": str(job.run_dir),
                              "status": "trained", "calls": 0, "message": ""}
    job.run_dir.mkdir(parents=True, exist_ok=True)
    state, steps = run_state(job.run_dir, job.target)
    if state is RunState.DONE:
        result["status"] = "skipped"
    with open(job.run_dir / "train.log", "a", buffering=1) as log, \
            contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        while state is not RunState.DONE:
            if result["calls"] == MAX_CALLS:
                result.update(status="failed", message=f"still at step {steps} of {job.target} "
                                                       f"after {MAX_CALLS} calls")
                break
            if state is RunState.NEW:
                argv = list(job.argv)
            else:
                # a checkpoint at the target without the final files still needs a call
                argv = [*_without_timesteps(job.argv), "--resume", "--timesteps",
                        str(max(job.target - steps, 1))]
            print(f"==== {time.strftime('%Y-%m-%d %H:%M:%S')} {job.label}: {state.value} at "
                  f"step {steps}/{job.target} (torch threads {torch.get_num_threads()}, numba "
                  f"threads {numba.get_num_threads()}, pid {os.getpid()}): train.py "
                  f"{' '.join(argv)}", flush=True)
            errors = _ErrorLines(sys.stderr)
            try:
                with contextlib.redirect_stderr(errors):
                    rc = train_main(argv)
            except Exception as exc:  # reported per seed; the other seeds go on
                import traceback

                traceback.print_exc()
                rc, result["message"] = 1, f"{type(exc).__name__}: {exc}"
            result["calls"] += 1
            if rc != 0:
                result["status"] = "failed"
                result["message"] = (result["message"] or errors.last
                                     or f"train.py exited {rc}")
                break
            state, steps = run_state(job.run_dir, job.target)
        print(f"==== {job.label}: {result['status']} at step {steps}", flush=True)
    info = job.run_dir / "train_info.json"
    run_wall = json.loads(info.read_text()).get("wall_time_s") if info.is_file() else None
    result.update(steps=steps, wall_s=round(time.perf_counter() - t0, 1), run_wall_s=run_wall)
    return result


def _without_timesteps(argv) -> list[str]:
    out, skip = [], False
    for item in argv:
        if skip:
            skip = False
        elif item == "--timesteps":
            skip = True
        else:
            out.append(item)
    return out


def _summary_line(res: dict) -> str:
    if res["status"] == "failed":
        return (f"{res['label']}: FAILED after {res['wall_s']} s: {res['message']} "
                f"(log {res['run_dir']}/train.log)")
    verb = "already finished" if res["status"] == "skipped" else f"trained in {res['wall_s']} s"
    return (f"{res['label']}: {verb}, step {res['steps']}, run wall time {res['run_wall_s']} s "
            f"({res['run_dir']})")


def run_jobs(jobs: list[SeedJob], *, address: str | None = None, threads: int = 1,
             use_ray: bool = True, summary_log: Path | None = None) -> list[dict]:
    """Run seed jobs (as Ray tasks when ``use_ray``); print a line per finished job.

    Jobs whose folder is already complete are reported as skipped without starting
    a task. A Ray instance started here is shut down at the end; one already
    initialised (by the caller) is left running.
    """
    results, todo = [], []
    for job in jobs:
        state, steps = run_state(job.run_dir, job.target)
        if state is RunState.DONE:
            info = json.loads((job.run_dir / "train_info.json").read_text())
            results.append({"label": job.label, "run_dir": str(job.run_dir), "status": "skipped",
                            "steps": steps, "wall_s": 0.0, "calls": 0, "message": "",
                            "run_wall_s": info.get("wall_time_s")})
        else:
            todo.append(job)

    def report(res):
        line = _summary_line(res)
        print(line, flush=True)
        if summary_log is not None:
            with open(summary_log, "a") as fh:
                fh.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {line}\n")

    for res in results:
        report(res)
    if not todo:
        return results
    if not use_ray:
        for job in todo:
            res = train_seed(job, threads)
            report(res)
            results.append(res)
        return results
    ray = require_ray()
    started = init_ray(address)
    try:
        remote = ray.remote(num_cpus=threads, max_retries=0)(train_seed)
        print(f"{len(todo)} run(s) on Ray ({ray.cluster_resources().get('CPU', 0):g} CPUs, "
              f"{threads} per run); progress in <run folder>/train.log", flush=True)
        pending = {remote.remote(job, threads): job for job in todo}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            job = pending.pop(done[0])
            try:
                res = ray.get(done[0])
            except Exception as exc:  # a worker died (killed, out of memory)
                res = {"label": job.label, "run_dir": str(job.run_dir), "status": "failed",
                       "steps": run_state(job.run_dir, job.target)[1], "wall_s": 0.0,
                       "calls": 0, "run_wall_s": None,
                       "message": f"{type(exc).__name__}: {str(exc).splitlines()[0]}"}
            report(res)
            results.append(res)
    finally:
        if started:
            ray.shutdown()
    return results


def _check_common(args) -> None:
    if args.seeds is not None and args.seeds < 1:
        raise ConfigError(f"--seeds must be >= 1, got {args.seeds}")
    if args.resume:
        raise ConfigError("--resume cannot be combined with --seeds or --sweep: re-running the "
                          "same command resumes the interrupted seeds and skips finished ones")
    if args.ray_address is not None and not str(args.ray_address).strip():
        raise ConfigError("--ray-address must be 'auto' or HOST:PORT, got an empty string")
    if args.torch_threads < 1:
        raise ConfigError(f"--torch-threads must be >= 1, got {args.torch_threads}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    parse_env_kwargs(args.env_kwargs)  # malformed entries fail here, before any task


def run_from_args(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """``train.py`` with ``--seeds``, ``--sweep`` or ``--ray-address``; returns the exit code."""
    if args.seeds is None and args.sweep is None:
        raise ConfigError(f"--ray-address {args.ray_address} needs --seeds N or --sweep FILE.yml")
    _check_common(args)
    if args.sweep is not None:
        from .sweep import run_sweep

        return run_sweep(args, parser)
    out = Path(args.out or Path("runs") / args.algo).absolute()
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out} is a file; --seeds needs a folder for seed_K/ runs")
    target = target_timesteps(args)
    load_hyperparams(config_path(args), args.algo, args.env_id)  # a bad config fails here
    use_ray = args.seeds > 1 or bool(args.ray_address or os.environ.get("RAY_ADDRESS"))
    if use_ray:
        require_ray()
    jobs = []
    for seed in range(args.seed, args.seed + args.seeds):
        run_dir = out / f"seed_{seed}"
        argv = seed_argv(parser, args, seed=seed, out=run_dir, seeds=None, sweep=None,
                         ray_address=None, no_progress=True, verbose=max(args.verbose, 1))
        jobs.append(SeedJob(f"seed {seed}", run_dir, tuple(argv), target))
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    try:
        results = run_jobs(jobs, address=args.ray_address, threads=args.torch_threads,
                           use_ray=use_ray, summary_log=out / "fanout.log")
    except KeyboardInterrupt:
        print(INTERRUPTED, file=sys.stderr)
        return 130
    failed = [r for r in results if r["status"] == "failed"]
    print(f"{len(results) - len(failed)}/{len(results)} seeds complete in {out} "
          f"({time.perf_counter() - t0:.0f} s)")
    from .train import plot_seed_learning_curves

    plot = plot_seed_learning_curves(out)
    if plot is not None:
        print(f"learning curves of every seed: {plot}")
    return 1 if failed else 0
