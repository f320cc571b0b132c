"""Resume a run: pick its newest good saved model, continue its records without doubles.

``train.py --resume`` (and the fan-out, for an interrupted seed) continues from the
newest saved model that loads (a truncated one, as a kill mid-save leaves, is skipped)
without unpickling anything (:mod:`.checkpoint`; pickled statistics and buffers of
older runs only with ``--allow-pickle``, with a warning),
keeps the evaluations and TensorBoard events up to that step and drops the later ones,
which the resumed run repeats.

**Files of the run folder.** Before anything is loaded, every file the resume reads
(each saved model, its statistics and replay buffer, ``config.yml``, ``args.yml``,
``train_info.json``, ``eval/evaluations.npz``, the TensorBoard events) must be a regular
file inside the run folder under its size cap
(:func:`~tether_gym_agents.files.folder_paths.file_inside`): a symlink leading out, a FIFO
named like a checkpoint or a link to ``/dev/zero`` is a :class:`ConfigError` naming it
(the command exits 2; nothing is opened, nothing is skipped silently). ``command.txt``,
which the resumed run rewrites, must be a file of its own (no symlink, no hard link).

**Replay buffers (off-policy algorithms: SAC, TQC, TD3).** A checkpoint
``checkpoints/model_<N>_steps`` is written from stable-baselines3's callback, which runs
after the env step that reaches step N and before that step's transitions are added to
the buffer. Its buffer therefore holds
``N - n_envs`` transitions (the last step's are missing), while ``final_model.zip``'s
buffer (``final_replay_buffer``) holds all N. A run resumed from a checkpoint (a killed
run) continues at step N with ``N - n_envs`` transitions: each such resume leaves out one
vector step of experience (``n_envs`` of ``buffer_size`` transitions; the step count and
the training budget are exact). ``train.py --resume`` prints the count it loaded.
"""

from __future__ import annotations

import sys
import zipfile
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..common.algorithms import algorithm
from ..common.atomic_write import atomic_target
from ..common.jsonio import loads_json
from ..files.folder_paths import FolderFileError, file_inside
from ..files.run_folder import (
    ARGS_FILE,
    CONFIG_FILE,
    FINAL_MODEL_FILE,
    TB_DIR,
    TRAIN_INFO_FILE,
    SavedModel,
    check_command_file,
    evaluation_arrays,
    evaluation_rows,
    evaluations_path,
    read_evaluations,
    saved_models,
    write_evaluations,
)
from .checkpoint import (
    check_unpacked_size,
    load_buffer_npz,
    load_stats_npz,
    load_zip_weights,
    safe_companion,
)
from .config import ConfigError

__all__ = ["PICKLE_RESUME_WARNING", "ResumeBuild", "resume_candidates", "load_resume_point",
           "continue_eval_history", "truncate_tensorboard", "check_run_files"]


def _present(path: Path) -> bool:
    """Whether something (a file, a folder, a FIFO, a dangling link) is at ``path``."""
    return path.exists() or path.is_symlink()


def check_run_files(run_dir: Path) -> None:
    """Check every file a resume reads (module docstring) before any is opened.

    Raises
    ------
    ConfigError
        Naming the first file that is not a regular file inside ``run_dir`` under its
        size cap, or a ``command.txt`` that is a symlink or a hard link.
    """
    run_dir = Path(run_dir)
    paths = [run_dir / name for name in (CONFIG_FILE, ARGS_FILE, TRAIN_INFO_FILE)]
    paths.append(evaluations_path(run_dir))
    for saved in saved_models(run_dir):
        paths += [saved.model, saved.stats, safe_companion(saved.stats), saved.buffer,
                  safe_companion(saved.buffer)]
    tb_dir = run_dir / TB_DIR
    if _present(tb_dir):
        paths.append(tb_dir)
        paths += sorted(tb_dir.rglob("events.out.tfevents.*"))
    try:
        for path in paths:
            if path == tb_dir:
                if not path.resolve().is_relative_to(run_dir.resolve()):
                    raise FolderFileError(f"{path} leads outside {run_dir} (to "
                                          f"{path.resolve()})")
            elif _present(path):
                file_inside(run_dir, path)
        check_command_file(run_dir)
    except FolderFileError as exc:
        raise ConfigError(f"--resume: {exc}") from None


def _zip_timesteps(path: Path) -> int | None:
    """``num_timesteps`` from a model zip's plain-JSON ``data`` (nothing is unpickled)."""
    try:
        with zipfile.ZipFile(path) as zf:
            check_unpacked_size(zf, path)
            return int(loads_json(zf.read("data"), path)["num_timesteps"])
    except (zipfile.BadZipFile, KeyError, ValueError, TypeError, OSError, EOFError):
        return None


def resume_candidates(run_dir: Path) -> list[tuple[int, SavedModel]]:
    """(steps, saved model) of every model a run saved, newest first.

    The steps are read from each zip's plain-JSON ``data`` (a checkpoint's name
    otherwise); the final model comes before a checkpoint of the same step.
    """
    found = []
    for saved in saved_models(run_dir):
        steps = _zip_timesteps(saved.model)
        if steps is None:
            steps = saved.steps if saved.steps is not None else -1
        found.append((steps, saved.steps is None, saved))
    found.sort(key=lambda c: (c[0], c[1]), reverse=True)
    return [(int(s or 0), saved) for s, _, saved in found]


PICKLE_RESUME_WARNING = ("warning: --allow-pickle: unpickling {files}; a pickle can run any "
                         "code when it is loaded: do this only for run folders you made "
                         "yourself or trust")


class ResumeBuild(NamedTuple):
    """How a resumed run builds its model and normalisation (for the safe load).

    Attributes
    ----------
    new_model : callable
        ``new_model(env)``: a fresh model of the run's algorithm and hyperparameters.
    normalized : callable or None
        ``normalized(venv, eval_env)``: both envs wrapped in new ``VecNormalize``; None
        when the run does not normalise observations.
    algo_cls : type
        The algorithm (``algo_cls.load`` for a pickled resume, on opt-in).
    tb_log : str
        TensorBoard folder.
    algo : str
        The run's algorithm, a name of :data:`~..common.algorithms.ALGORITHMS` (its row
        says whether a replay buffer is resumed).
    allow_pickle : bool
        Whether pickled statistics and buffers may be loaded (``--allow-pickle``).
    """

    new_model: Any
    normalized: Any
    algo_cls: Any
    tb_log: str
    algo: str
    allow_pickle: bool = False


def load_resume_point(run_dir: Path, build: ResumeBuild, venv, eval_env):
    """Load the newest good saved model; a truncated or incomplete one is skipped.

    The model zip's tensors and counters, the statistics and the replay buffer are read
    from arrays (:mod:`.checkpoint`); nothing is unpickled. A saved model whose
    statistics are only pickled (``.pkl``, from an older run) is skipped unless
    ``build.allow_pickle``, which loads it with stable-baselines3 and a warning.

    Returns (model, venv, eval_env, model_path, buffer_loaded).

    Raises
    ------
    ConfigError
        When no saved model loads (naming ``--allow-pickle`` when pickled ones were
        refused), or a file of the run folder is refused (:func:`check_run_files`).
    """
    check_run_files(run_dir)
    candidates = resume_candidates(run_dir)
    if not candidates:
        raise ConfigError(f"--resume: no checkpoint or {FINAL_MODEL_FILE} in {run_dir}")
    refused = []
    for steps, saved in candidates:
        pickled = build.normalized is not None and not safe_companion(saved.stats).is_file() \
            and saved.stats.is_file()
        if pickled and not build.allow_pickle:
            refused.append(saved.stats)
            print(f"warning: skipping {saved.model} (step {steps}): its normalisation "
                  f"statistics are pickled only ({saved.stats.name}, no "
                  f"{safe_companion(saved.stats).name}); pass --allow-pickle to load them",
                  file=sys.stderr)
            continue
        try:
            if pickled:
                print(PICKLE_RESUME_WARNING.format(files=[str(saved.stats), str(saved.model)]),
                      file=sys.stderr)
                return _load_pickled(saved, build, venv, eval_env)
            return _load_safe(saved, build, venv, eval_env)
        except Exception as exc:  # noqa: BLE001 - truncated files fail in many ways
            print(f"warning: skipping {saved.model} (step {steps}): {type(exc).__name__}: "
                  f"{exc}", file=sys.stderr)
    if refused:
        raise ConfigError(f"--resume: no saved model of {run_dir} loads without unpickling: "
                          f"{[str(p) for p in refused]} are pickled (loading them can run "
                          "code from the file); pass --allow-pickle if you made them or "
                          "trust them")
    raise ConfigError(f"--resume: no loadable model in {run_dir} (all "
                      f"{len(candidates)} saved models are truncated or incomplete)")


def _load_safe(saved: SavedModel, build: ResumeBuild, venv, eval_env):
    """A saved model rebuilt from arrays and JSON: (model, venv, eval_env, path, buffer)."""
    if build.normalized is not None:
        stats = safe_companion(saved.stats)
        if not stats.is_file():
            raise FileNotFoundError(f"its normalisation statistics {stats.name} are missing")
        venv, eval_env = build.normalized(venv, eval_env)
        load_stats_npz((venv, eval_env), stats)
    model = build.new_model(venv)
    load_zip_weights(model, saved.model)
    return model, venv, eval_env, saved.model, _load_buffer(model, saved, build.algo,
                                                            build.allow_pickle)


def _load_buffer(model, saved: SavedModel, algo: str, allow_pickle: bool) -> bool:
    """Fill an off-policy model's replay buffer from beside its saved model (True if so).

    ``algo``'s row of the algorithm table says whether the model has one.
    """
    if algorithm(algo).on_policy:
        return False
    arrays = safe_companion(saved.buffer)
    if arrays.is_file():
        load_buffer_npz(model, arrays)
        return True
    if saved.buffer.is_file() and allow_pickle:
        print(PICKLE_RESUME_WARNING.format(files=[str(saved.buffer)]), file=sys.stderr)
        model.load_replay_buffer(saved.buffer)
        return True
    pickled = (f"; its pickled {saved.buffer.name} is read only with --allow-pickle"
               if saved.buffer.is_file() else "")
    print(f"warning: {saved.model.name} has no replay buffer beside it ({arrays.name}"
          f"){pickled}; {algo.upper()} continues with an empty buffer")
    return False


def _load_pickled(saved: SavedModel, build: ResumeBuild, venv, eval_env):
    """stable-baselines3's own load of pickled files (``--allow-pickle`` only)."""
    from stable_baselines3.common.vec_env import VecNormalize

    train_env = VecNormalize.load(str(saved.stats), venv)
    test_env = VecNormalize.load(str(saved.stats), eval_env)
    test_env.training = False
    test_env.norm_reward = False
    model = build.algo_cls.load(saved.model, env=train_env, device="cpu",
                                tensorboard_log=build.tb_log)
    return model, train_env, test_env, saved.model, _load_buffer(model, saved, build.algo, True)


def continue_eval_history(callback, run_dir: Path, last_step: int) -> int:
    """Seed an EvalCallback with the evaluations up to ``last_step``; drop later ones.

    Evaluations after the resume point were made by the interrupted part of the run,
    which the resumed run repeats; the file is rewritten without them. Each
    evaluation keeps its own episode count (the resumed run may use another
    ``--eval-episodes``). Returns the number dropped.

    Raises
    ------
    DamagedFileError
        When ``eval/evaluations.npz`` cannot be read (its path is in the message).
    """
    arrays = read_evaluations(run_dir)
    if arrays is None:
        return 0
    rows = evaluation_rows(arrays)
    keep = [i for i, t in enumerate(arrays["timesteps"]) if t <= last_step]
    dropped = len(arrays["timesteps"]) - len(keep)
    callback.evaluations_timesteps = [int(arrays["timesteps"][i]) for i in keep]
    callback.evaluations_results = [rows["results"][i] for i in keep]
    callback.evaluations_length = [rows["ep_lengths"][i] for i in keep]
    callback.evaluations_successes = [rows["successes"][i] for i in keep
                                      if "successes" in rows]
    if dropped:
        write_evaluations(run_dir, evaluation_arrays(
            callback.evaluations_timesteps, callback.evaluations_results,
            callback.evaluations_length, callback.evaluations_successes))
    # best_model.zip may come from a dropped evaluation: keep its score as the bar
    returns = [float(np.mean(r)) for r in rows["results"] if r]
    if returns:
        callback.best_mean_reward = max(returns)
    return dropped


def truncate_tensorboard(tb_dir: Path, last_step: int) -> int:
    """Remove TensorBoard events after ``last_step`` (the part a resumed run repeats).

    Returns the number of events removed.
    """
    if not tb_dir.is_dir():
        return 0
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
    from tensorboard.summary.writer.record_writer import RecordWriter

    removed = 0
    for path in sorted(tb_dir.rglob("events.out.tfevents.*")):
        try:
            events = list(EventFileLoader(str(path)).Load())
        except Exception:  # noqa: BLE001 - a truncated last record: keep what was read
            events = []
        keep = [e for e in events if e.step <= last_step]
        if len(keep) == len(events):
            continue
        removed += len(events) - len(keep)
        with atomic_target(path) as tmp, open(tmp, "wb") as fh:
            writer = RecordWriter(fh)
            for event in keep:
                writer.write(event.SerializeToString())
            writer.flush()
    return removed
