"""Train many seeds of one configuration as Ray tasks: the code behind ``train.py --seeds N``.

``python train.py --algo ppo --seeds 10 --out runs/ppo`` trains seeds ``--seed`` ...
``--seed + 9``, each into its own normal run folder ``runs/ppo/seed_K/``. The settings
are resolved once (:func:`~tether_gym_agents.training.settings.resolve_settings`: a
bad config or env kwarg fails before any task starts); each seed's record is derived
from them with :meth:`~tether_gym_agents.training.settings.TrainSettings.for_seed` and
trained by one call of :func:`tether_gym_agents.training.run.train`, in-process inside
a Ray task (the record is passed to the task as it is). ``command.txt`` records the
single run ``train.py --seed K --out runs/ppo/seed_K ...`` that reproduces the seed, so
a seed folder is exactly a single-seed run folder.

Where the tasks run
    By default a new local Ray instance sized to the machine
    (``num_cpus=os.cpu_count()``, no dashboard, no token authentication: it is this
    user's, on this machine), stopped at the end; its processes also end when the
    driver is killed (``kill -9`` included: :mod:`.ray_reaper`).
    ``--ray-address auto|local|HOST:PORT|ray://HOST:PORT`` (or the ``RAY_ADDRESS``
    environment variable; another form is an error before Ray is imported) connects to
    an existing cluster instead (``local``: the local instance above); an address
    nothing answers on is an error within :data:`CONNECT_TIMEOUT_S` seconds, one that
    answers but is no Ray cluster within :data:`GCS_PROBE_S` (``HOST:PORT``; a
    ``ray://`` address is left to Ray's client, about 30 s), in one line without Ray's
    log lines. Each task asks for ``--torch-threads``
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
    checkpoint or a final model but fewer steps is continued as ``train.py --resume``
    would for the missing steps (the resume logic of the single run picks the
    checkpoint and continues its step counter); one that never reached a checkpoint
    starts again from scratch. A seed that fails (an exception) is reported with its
    message; the other seeds go on.

Progress
    Everything a seed prints (SB3's training tables and evaluation lines,
    ``--verbose`` is raised to 1) goes to ``<out>/seed_K/train.log``; the command
    prints one summary line per seed as it finishes (steps, wall time of this call
    and of the whole run) and appends it to ``<out>/fanout.log``.

Ray is an optional dependency (``pip install -e ".[ray]"``); a single-seed
``train.py`` never imports it, and neither does ``--seeds 1`` without
``--ray-address`` or ``RAY_ADDRESS`` (it trains in this process). Ctrl-C stops every
task; the same command then resumes them.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from dataclasses import dataclass, replace
from enum import Enum
from pathlib import Path

from ..files.run_folder import (
    CONFIG_FILE,
    FANOUT_LOG_FILE,
    TRAIN_LOG_FILE,
    checkpoint_steps,
    earlier_run,
    read_train_info,
    seed_dir,
    trained_steps,
)
from .config import ConfigError
from .run import train
from .settings import TrainOptions, TrainSettings, check_ray_address, resolve_settings

__all__ = ["RAY_PIP", "RunState", "SeedStatus", "SeedJob", "SeedResult", "run_fanout", "run_jobs",
           "init_ray", "shutdown_ray", "require_ray", "run_state", "train_seed"]

RAY_PIP = 'pip install -e ".[ray]" (in a clone of tether_gym)'
#: Environment of every Ray task: one numba, OpenMP and MKL thread per run.
TASK_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: Training calls per seed and invocation: the first continues from the latest
#: checkpoint; the next ones top up if the resume had to fall back further.
MAX_CALLS = 3
INTERRUPTED = ("interrupted: run the same command again to resume the unfinished runs from "
               "their last checkpoints (finished runs are skipped)")


class RunState(Enum):
    """What a run folder holds relative to its step target."""

    NEW = "new"  # nothing to continue from: train from scratch
    PARTIAL = "partial"  # a checkpoint or final model below the target: resume
    DONE = "done"  # train_info.json reaches the target: skip


class SeedStatus(Enum):
    """What a seed job ended as."""

    TRAINED = "trained"
    SKIPPED = "skipped"  # the run folder had reached its target already
    FAILED = "failed"


@dataclass(frozen=True)
class SeedJob:
    """One seed's training: a label and the settings of its run.

    Attributes
    ----------
    label : str
        Name in progress lines, e.g. ``"seed 3"`` or ``"trial 2 seed 3"``.
    settings : TrainSettings
        A fresh single run of the seed into its folder (``settings.out``, absolute),
        for ``settings.timesteps`` env steps.
    """

    label: str
    settings: TrainSettings

    @property
    def run_dir(self) -> Path:
        """The seed's run folder."""
        return self.settings.out

    @property
    def target(self) -> int:
        """Env steps the finished run has [-]."""
        return self.settings.timesteps


@dataclass(frozen=True)
class SeedResult:
    """What became of a seed job.

    Attributes
    ----------
    label, run_dir : str
    status : SeedStatus
    steps : int
        Env steps the run folder holds [-].
    wall_s : float
        Wall time of this invocation [s].
    run_wall_s : float or None
        The run's ``wall_time_s`` (all calls) [s].
    calls : int
        Training calls made.
    message : str
        Why it failed (the exception's message); empty otherwise.
    """

    label: str
    run_dir: str
    status: SeedStatus
    steps: int
    wall_s: float = 0.0
    run_wall_s: float | None = None
    calls: int = 0
    message: str = ""


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
        ``num_cpus=os.cpu_count()`` and no dashboard (:func:`_start_local`).

    Raises
    ------
    ConfigError
        When the cluster at ``address`` cannot be reached (within
        :data:`CONNECT_TIMEOUT_S` for a host and port nothing answers on).
    """
    if address is None and os.environ.get("RAY_ADDRESS", "").strip():
        address = check_ray_address(os.environ["RAY_ADDRESS"], "RAY_ADDRESS")
    elif address is not None:
        address = check_ray_address(address)
    ray = require_ray()
    if ray.is_initialized():
        return False
    if address in (None, "local"):
        _start_local(ray)
        return True
    quiet = {"logging_level": logging.WARNING, "log_to_driver": False}
    with _ray_stderr() as said:
        try:  # the workers of other nodes get the thread settings as a runtime env
            _probe(address)
            ray.init(address=address, runtime_env={"env_vars": dict(TASK_ENV)}, **quiet)
            failure = None
        except (ConnectionError, RuntimeError, OSError, ValueError) as exc:
            failure = exc
    if failure is None:
        sys.stderr.write(said.text)  # a connected cluster's warnings are shown
        return True
    # Ray's own log lines ("[2026-01-01 12:00:00,000 W 123 123] file.cc:85: ..."), the last
    last = [line for line in said.text.splitlines() if line.startswith("[20")][-1:]
    raise ConfigError(
        f"cannot connect to the Ray cluster at --ray-address/RAY_ADDRESS {address!r} "
        f"({type(failure).__name__}: {(str(failure) or 'no answer').splitlines()[0]}"
        + (f"; Ray's last line: {last[0].split('] ', 1)[-1][:200]}" if last else "")
        + "). Start it with `ray start --head` and give its address; a cluster with token "
        "authentication needs its token here too (RAY_AUTH_MODE=token and RAY_AUTH_TOKEN, "
        "as on its nodes)") from failure


class _Captured:
    text = ""


@contextlib.contextmanager
def _ray_stderr():
    """Hold what is written to file descriptor 2 (Ray's C++ log lines) while connecting.

    Ray retries an address that answers but is no Ray cluster about once a second and
    logs each try on stderr; the retries are capped at :data:`CONNECT_RETRIES` (Ray's
    ``RAY_gcs_server_port_wait_time_s`` unless the user set it) and the lines are given
    back in the returned object's ``text``, for the caller to show or summarise.
    """
    import tempfile

    said = _Captured()
    saved_env = os.environ.get("RAY_gcs_server_port_wait_time_s")
    if saved_env is None:
        os.environ["RAY_gcs_server_port_wait_time_s"] = str(CONNECT_RETRIES)
    sys.stderr.flush()
    saved_fd = os.dup(2)
    with tempfile.TemporaryFile("w+b") as held:
        os.dup2(held.fileno(), 2)
        try:
            yield said
        finally:
            sys.stderr.flush()
            os.dup2(saved_fd, 2)
            os.close(saved_fd)
            if saved_env is None:
                os.environ.pop("RAY_gcs_server_port_wait_time_s", None)
            held.seek(0)
            said.text = held.read(1 << 16).decode("utf-8", "replace")


CONNECT_TIMEOUT_S = 10.0
"""Seconds to wait for a cluster's host and port to accept a connection [s] (Ray itself
retries an address nothing listens on for minutes, silently)."""
GCS_PROBE_S = 8.0
"""Seconds a cluster's GCS has to answer a first request [s], Python's start included."""
CONNECT_RETRIES = 3
"""Tries (about a second each) Ray makes to reach the cluster's GCS at an address that
accepts connections (Ray's default: 20, each logged on stderr)."""


def _probe(address: str) -> None:
    """Raise OSError unless ``HOST:PORT`` (or ``ray://HOST:PORT``) accepts a TCP connection.

    ``auto`` is left to Ray (it reads the address of a cluster on this machine and
    fails at once when there is none).
    """
    import socket

    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if address == "auto" or not sep or not port.isdigit():
        return
    try:
        with socket.create_connection((host.strip("[]"), int(port)), CONNECT_TIMEOUT_S):
            pass
    except TimeoutError:
        raise OSError(f"no answer within {CONNECT_TIMEOUT_S:g} s") from None
    except OSError as exc:
        raise OSError(exc.strerror or str(exc)) from None
    if not address.startswith("ray://"):
        _probe_gcs(address)


#: Run in a child process: connect a GCS client to argv[1] (exit 3: this Ray has no such
#: client, skip the check).
_GCS_PROBE = """
import sys
try:
    from ray._raylet import GcsClient
except ImportError:
    sys.exit(3)
GcsClient(address=sys.argv[1], cluster_id=None)
"""


def _probe_gcs(address: str) -> None:
    """Raise OSError unless a Ray cluster's GCS answers at ``HOST:PORT`` within GCS_PROBE_S.

    Something that accepts connections but is no Ray cluster (a proxy, another server)
    keeps ``ray.init`` waiting about 40 s per try, 20 tries; the check runs in a child
    process that is killed after :data:`GCS_PROBE_S` seconds.
    """
    import subprocess

    try:
        done = subprocess.run([sys.executable, "-c", _GCS_PROBE, address],
                              capture_output=True, text=True, timeout=GCS_PROBE_S,
                              stdin=subprocess.DEVNULL, check=False)
    except subprocess.TimeoutExpired:
        raise OSError(f"it accepts connections, but no Ray cluster answered within "
                      f"{GCS_PROBE_S:g} s") from None
    if done.returncode in (0, 3):
        return
    lines = [line.split("] ", 1)[-1] for line in done.stderr.splitlines() if line.strip()]
    raise OSError(f"no Ray cluster answers there ({lines[-1][:200] if lines else 'no reply'})")


#: Environment of the processes of a local instance: the task threads, no
#: token-authentication banner (no one else connects to it: it listens on this machine).
LOCAL_ENV = {**TASK_ENV, "RAY_AUTH_MODE": "disabled"}


def reaper_folder() -> Path:
    """Where the local instances' process records are kept (one file per driver).

    The folder also holds the start-up module every Python process of a local instance
    imports (:func:`.ray_reaper.fate_env`), and the reaper kills what its records name,
    so it must be this user's alone: made with mode 0700, and refused (ConfigError) when
    it exists as anything else, such as a folder another user made in the shared
    temporary directory, where a planted ``sitecustomize.py`` would run in our processes.
    """
    import stat
    import tempfile

    uid = getattr(os, "getuid", lambda: None)()
    folder = Path(tempfile.gettempdir()) / f"tether_gym_ray_{uid if uid is not None else 0}"
    with contextlib.suppress(FileExistsError):
        folder.mkdir(mode=0o700)
    if uid is None:  # no owners to check (Windows)
        return folder
    info = os.lstat(folder)
    if (not stat.S_ISDIR(info.st_mode) or info.st_uid != uid
            or stat.S_IMODE(info.st_mode) & 0o022):
        raise ConfigError(f"{folder} is not a private folder of this user (a "
                          f"{'folder' if stat.S_ISDIR(info.st_mode) else 'non-folder'} of "
                          f"owner uid {info.st_uid}, mode {stat.S_IMODE(info.st_mode):o}): a "
                          "local Ray instance keeps its process records and start-up module "
                          "there; remove it, or set TMPDIR to a folder of your own")
    return folder


_WATCHERS: dict[int, object] = {}


def _start_local(ray) -> None:
    """Start a local Ray instance whose processes end with this driver, even on ``kill -9``.

    The processes of a previous local instance whose driver was killed are stopped
    first (:func:`.ray_reaper.reap_stale`); the new instance's processes are recorded
    and a watcher process stops them if this driver dies without ``ray.shutdown()``
    (:mod:`.ray_reaper`).
    """
    import subprocess

    from . import ray_reaper

    folder = reaper_folder()
    stale = ray_reaper.reap_stale(folder)
    if stale:
        print(f"stopped {stale} process(es) left by a killed local Ray instance", flush=True)
    # A local instance's workers inherit the environment of the processes ray.init
    # starts: the thread settings without a runtime env, whose set-up was measured to
    # add about 4 s to the first tasks on a busy 2-core machine.
    local_env = {**LOCAL_ENV, **ray_reaper.fate_env(folder, os.getpid())}
    saved = {k: os.environ.get(k) for k in local_env}
    os.environ.update(local_env)
    try:
        # "local": a new instance even when a `ray start` cluster runs on this machine
        ray.init(address="local", num_cpus=os.cpu_count(), include_dashboard=False,
                 logging_level=logging.WARNING, log_to_driver=False)
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    record = folder / f"driver_{os.getpid()}.json"
    ray_reaper.record(record, os.getpid())
    _WATCHERS[os.getpid()] = subprocess.Popen(
        [sys.executable, ray_reaper.__file__, str(os.getpid()), str(record)],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True)


def shutdown_ray(ray) -> None:
    """``ray.shutdown()``; the watcher of a local instance started here ends too."""
    ray.shutdown()
    watcher = _WATCHERS.pop(os.getpid(), None)
    (reaper_folder() / f"driver_{os.getpid()}.json").unlink(missing_ok=True)
    if watcher is not None:
        try:
            watcher.wait(timeout=10)  # type: ignore[attr-defined]
        except Exception:  # noqa: BLE001 - it stops by itself once the record is gone
            pass


def run_state(run_dir: Path, target: int) -> tuple[RunState, int]:
    """State of a run folder and the env steps it has saved [-].

    ``DONE`` when ``train_info.json`` records ``num_timesteps >= target``;
    ``PARTIAL`` when a checkpoint (``checkpoints/model*_<N>_steps*``: the largest N
    counts) or a finished shorter run is there; ``NEW`` otherwise (including a
    folder killed before its first checkpoint, or one without ``config.yml``, which
    the resume needs). The step count only sizes the first resumed call; the resume
    logic of the single run chooses the checkpoint, and :func:`train_seed` tops up if
    it had to fall back to an earlier one.
    """
    run_dir = Path(run_dir)
    steps = trained_steps(run_dir)
    if steps >= target:
        return RunState.DONE, steps
    steps = max(steps, checkpoint_steps(run_dir))
    if steps > 0 and (run_dir / CONFIG_FILE).is_file():
        return RunState.PARTIAL, steps
    return RunState.NEW, max(steps, 0)


def resume_command(settings: TrainSettings, steps: int) -> tuple[str, ...]:
    """The ``train.py`` arguments that continue the run of ``settings`` for ``steps``."""
    return (*replace(settings.options, timesteps=None).argv(keep=("seed",)), "--resume",
            "--timesteps", str(steps))


def _train_call(job: SeedJob, state: RunState, steps: int) -> str:
    """One training call of a seed job (fresh or resumed); the error message, or ''."""
    import numba
    import torch

    settings, missing = job.settings, max(job.target - steps, 1)
    # a checkpoint at the target without the final files still needs a call
    command = settings.command if state is RunState.NEW else resume_command(settings, missing)
    print(f"==== {time.strftime('%Y-%m-%d %H:%M:%S')} {job.label}: {state.value} at "
          f"step {steps}/{job.target} (torch threads {torch.get_num_threads()}, numba "
          f"threads {numba.get_num_threads()}, pid {os.getpid()}): train.py "
          f"{' '.join(command)}", flush=True)
    try:
        if state is not RunState.NEW:  # as `train.py --resume`: from the run's config.yml
            options = replace(settings.options, resume=True, timesteps=missing)
            settings = resolve_settings(options, command)
        train(settings)
    except ConfigError as exc:
        print(f"train.py: error: {exc}", file=sys.stderr)
        return str(exc)
    except Exception as exc:  # reported per seed; the other seeds go on
        import traceback

        traceback.print_exc()
        return f"{type(exc).__name__}: {exc}"
    return ""


def train_seed(job: SeedJob, threads: int = 1) -> SeedResult:
    """Train one seed to its target in this process; the body of each Ray task.

    Fresh runs train ``job.settings``; partial ones are resumed for the missing steps.
    Output goes to ``run_dir/train.log``.
    """
    import numba
    import torch

    torch.set_num_threads(threads)
    with contextlib.suppress(ValueError):  # NUMBA_NUM_THREADS lower than `threads`
        limit = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
        numba.set_num_threads(min(threads, limit))
    t0 = time.perf_counter()
    job.run_dir.mkdir(parents=True, exist_ok=True)
    state, steps = run_state(job.run_dir, job.target)
    status = SeedStatus.SKIPPED if state is RunState.DONE else SeedStatus.TRAINED
    calls, message = 0, ""
    with open(job.run_dir / TRAIN_LOG_FILE, "a", buffering=1) as log, \
            contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        while state is not RunState.DONE:
            if calls == MAX_CALLS:
                status = SeedStatus.FAILED
                message = f"still at step {steps} of {job.target} after {MAX_CALLS} calls"
                break
            message = _train_call(job, state, steps)
            calls += 1
            if message:
                status = SeedStatus.FAILED
                break
            state, steps = run_state(job.run_dir, job.target)
        print(f"==== {job.label}: {status.value} at step {steps}", flush=True)
    return SeedResult(job.label, str(job.run_dir), status, steps,
                      round(time.perf_counter() - t0, 1), _run_wall(job.run_dir), calls, message)


def _run_wall(run_dir: Path) -> float | None:
    """The ``wall_time_s`` of a run (None if it has none)."""
    return read_train_info(run_dir).get("wall_time_s")


def _summary_line(res: SeedResult) -> str:
    if res.status is SeedStatus.FAILED:
        return (f"{res.label}: FAILED after {res.wall_s} s: {res.message} "
                f"(log {res.run_dir}/{TRAIN_LOG_FILE})")
    verb = "already finished" if res.status is SeedStatus.SKIPPED else f"trained in {res.wall_s} s"
    return (f"{res.label}: {verb}, step {res.steps}, run wall time {res.run_wall_s} s "
            f"({res.run_dir})")


def run_jobs(jobs: list[SeedJob], *, address: str | None = None, threads: int = 1,
             use_ray: bool = True, summary_log: Path | None = None) -> list[SeedResult]:
    """Run seed jobs (as Ray tasks when ``use_ray``); print a line per finished job.

    Jobs whose folder is already complete are reported as skipped without starting
    a task. A Ray instance started here is shut down at the end; one already
    initialised (by the caller) is left running.
    """
    results, todo = [], []
    for job in jobs:
        state, steps = run_state(job.run_dir, job.target)
        if state is RunState.DONE:
            results.append(SeedResult(job.label, str(job.run_dir), SeedStatus.SKIPPED, steps,
                                      run_wall_s=_run_wall(job.run_dir)))
        else:
            todo.append(job)

    def report(res: SeedResult) -> None:
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
    for res in _run_on_ray(todo, address, threads):
        report(res)
        results.append(res)
    return results


def _run_on_ray(jobs: list[SeedJob], address: str | None, threads: int):
    """Yield the result of each job as its Ray task finishes."""
    ray = require_ray()
    started = init_ray(address)
    try:
        remote = ray.remote(num_cpus=threads, max_retries=0)(train_seed)
        print(f"{len(jobs)} run(s) on Ray ({ray.cluster_resources().get('CPU', 0):g} CPUs, "
              f"{threads} per run); progress in <run folder>/{TRAIN_LOG_FILE}", flush=True)
        pending = {remote.remote(job, threads): job for job in jobs}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            job = pending.pop(done[0])
            try:
                res = ray.get(done[0])
            except Exception as exc:  # a worker died (killed, out of memory)
                res = SeedResult(job.label, str(job.run_dir), SeedStatus.FAILED,
                                 run_state(job.run_dir, job.target)[1],
                                 message=f"{type(exc).__name__}: {str(exc).splitlines()[0]}")
            yield res
    finally:
        if started:
            shutdown_ray(ray)


def _check_seed_folder(out: Path, folder: Path) -> None:
    """A ``seed_K`` that exists is a folder of its own inside ``out`` (no symlink).

    A symlinked ``seed_K`` would train (and resume) a run elsewhere, another seed's or
    one outside ``out``, under this seed's name.
    """
    if folder.is_symlink():
        raise ConfigError(f"--out {out}: {folder} is a symlink (to {os.readlink(folder)}); "
                          "each seed trains into a folder of its own inside --out")
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"--out {out}: {folder} is not a folder; each seed trains into a "
                          "folder of its own inside --out")
    if folder.exists() and not folder.resolve().is_relative_to(out.resolve()):
        raise ConfigError(f"--out {out}: {folder} leads outside it (to {folder.resolve()})")


def run_fanout(options: TrainOptions) -> int:
    """``train.py --seeds N``: train seeds ``--seed`` ... ``--seed + N - 1``; the exit code.

    Raises
    ------
    ConfigError
        Before any training: Ray missing when it is needed, ``--out`` a file, or a
        setting that :func:`~.settings.resolve_settings` rejects.
    """
    from .curves import plot_seed_learning_curves

    seeds = options.seeds or 1
    out = Path(options.out or Path("runs") / options.algo).absolute()
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out} is a file; --seeds needs a folder for seed_K/ runs")
    found = earlier_run(out) if out.is_dir() else ""
    if found:  # one run's folder, not a folder of runs (its --resume is not --seeds')
        raise ConfigError(f"--out {out} is itself a training run ({found}); --seeds writes "
                          "one seed_K/ run per seed into a folder of its own: give a new "
                          "folder, or the one that holds the seed_K/ runs")
    use_ray = seeds > 1 or bool(options.ray_address or os.environ.get("RAY_ADDRESS"))
    if use_ray:
        require_ray()
    dirs = {seed: seed_dir(out, seed) for seed in range(options.seed, options.seed + seeds)}
    for folder in dirs.values():
        _check_seed_folder(out, folder)
    base = resolve_settings(replace(options, out=str(out)))
    jobs = [SeedJob(f"seed {seed}", base.for_seed(seed, folder))
            for seed, folder in dirs.items()]
    t0 = time.perf_counter()
    try:
        results = run_jobs(jobs, address=options.ray_address, threads=options.torch_threads,
                           use_ray=use_ray, summary_log=out / FANOUT_LOG_FILE)
    except KeyboardInterrupt:
        print(INTERRUPTED, file=sys.stderr)
        return 130
    failed = [r for r in results if r.status is SeedStatus.FAILED]
    print(f"{len(results) - len(failed)}/{len(results)} seeds complete in {out} "
          f"({time.perf_counter() - t0:.0f} s)")
    plot = plot_seed_learning_curves(out)
    if plot is not None:
        print(f"learning curves of every seed: {plot}")
    return 1 if failed else 0
