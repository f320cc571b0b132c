"""Resume a run: pick its newest good saved model, continue its records without doubles.

``train.py --resume`` (and the fan-out, for an interrupted seed) continues from the
newest saved model that loads (a truncated one, as a kill mid-save leaves, is skipped),
keeps the evaluations and TensorBoard events up to that step and drops the later ones,
which the resumed run repeats.
"""

from __future__ import annotations

import json
import sys
import zipfile
from pathlib import Path

import numpy as np

from ..files.run_folder import (
    FINAL_MODEL_FILE,
    SavedModel,
    evaluation_arrays,
    evaluation_rows,
    read_evaluations,
    saved_models,
    write_evaluations,
)
from .config import ConfigError

__all__ = ["resume_candidates", "load_resume_point", "continue_eval_history",
           "truncate_tensorboard"]


def _zip_timesteps(path: Path) -> int | None:
    """``num_timesteps`` from a model zip's plain-JSON ``data`` (nothing is unpickled)."""
    try:
        with zipfile.ZipFile(path) as zf:
            return int(json.loads(zf.read("data"))["num_timesteps"])
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


def load_resume_point(run_dir, algo_cls, venv, eval_env, normalize: bool, tb_log: str):
    """Load the newest good saved model; a truncated or incomplete one is skipped.

    Returns (model, venv, eval_env, model_path, buffer_loaded).
    """
    from stable_baselines3.common.vec_env import VecNormalize

    candidates = resume_candidates(run_dir)
    if not candidates:
        raise ConfigError(f"--resume: no checkpoint or {FINAL_MODEL_FILE} in {run_dir}")
    for steps, saved in candidates:
        model_path, stats, buffer = saved.model, saved.stats, saved.buffer
        try:
            if normalize:
                if not stats.is_file():
                    raise FileNotFoundError(f"its normalisation statistics {stats.name} are "
                                            "missing")
                train_env = VecNormalize.load(str(stats), venv)
                test_env = VecNormalize.load(str(stats), eval_env)
                test_env.training = False
                test_env.norm_reward = False
            else:
                train_env, test_env = venv, eval_env
            model = algo_cls.load(model_path, env=train_env, device="cpu", tensorboard_log=tb_log)
            loaded = False
            if hasattr(model, "replay_buffer"):
                if buffer.is_file():
                    model.load_replay_buffer(buffer)
                    loaded = True
                else:
                    print(f"warning: {model_path.name} has no replay buffer beside it "
                          f"({buffer.name}); SAC continues with an empty buffer")
        except Exception as exc:  # noqa: BLE001 - truncated files fail in many ways
            print(f"warning: skipping {model_path} (step {steps}): {type(exc).__name__}: "
                  f"{exc}", file=sys.stderr)
            continue
        return model, train_env, test_env, model_path, loaded
    raise ConfigError(f"--resume: no loadable model in {run_dir} (all "
                      f"{len(candidates)} saved models are truncated or incomplete)")


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
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as fh:
            writer = RecordWriter(fh)
            for event in keep:
                writer.write(event.SerializeToString())
            writer.flush()
        tmp.replace(path)
    return removed
