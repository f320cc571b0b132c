"""The folders ``train.py`` writes: every file name, and the readers and writers of each.

This module is the one owner of the layout; training, the fan-out, the sweep, the
export and the evaluation use its names and functions. A run folder
(``train.py --out RUN``) holds:

=============================  =======================================================
``config.yml``                 resolved hyperparameters, algorithm, env id, env kwargs
``args.yml``                   the parsed command line
``command.txt``                every command line that trained the run, one a line
``train_info.json``            steps, wall time [s], seed, status (rewritten while
                               training)
``agent.json``,                the best agent in the safe format
``policy.safetensors``         (:mod:`tether_gym_agents.files.safe_format`)
``final_agent/``               the agent at the last step, in the same format
``eval/evaluations.npz``       the evaluations (stable-baselines3's ``EvalCallback``)
``learning_curve.png``         their plot
``tb/``                        TensorBoard
``train.log``                  what a seed of the fan-out printed
``final_model.zip``,           stable-baselines3's pickled files, read back only by
``best_model.zip``,            ``train.py --resume`` (and, on opt-in, by
``vecnormalize.pkl``,          :mod:`tether_gym_agents.files.pickled`)
``final_replay_buffer.pkl``,
``checkpoints/model_<N>_steps.zip`` (+ ``model_vecnormalize_<N>_steps.pkl``,
``model_replay_buffer_<N>_steps.pkl``)
=============================  =======================================================

A folder of seed runs (``train.py --seeds N --out FOLDER``) holds ``seed_K/`` run
folders, ``fanout.log`` and ``learning_curves.png``. The JSON, YAML and text files are
written atomically (a temporary name, then ``os.replace``): a kill leaves the old
file or the new one, never a piece.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..common.jsonio import to_jsonable

__all__ = ["CONFIG_FILE", "ARGS_FILE", "COMMAND_FILE", "TRAIN_INFO_FILE", "EVAL_DIR",
           "EVALUATIONS_FILE", "LEARNING_CURVE_FILE", "TB_DIR", "FINAL_AGENT_DIR",
           "BEST_MODEL_FILE", "FINAL_MODEL_FILE", "VECNORMALIZE_FILE", "REPLAY_BUFFER_FILE",
           "CHECKPOINT_DIR", "CHECKPOINT_PREFIX", "TRAIN_LOG_FILE", "SEED_CURVES_FILE",
           "FANOUT_LOG_FILE", "SavedModel", "write_text_atomic", "yaml_text", "write_train_info",
           "read_train_info", "trained_steps", "write_config", "read_config", "write_args",
           "append_command", "evaluations_path", "read_evaluations", "write_evaluations",
           "saved_models", "checkpoint_steps", "seed_dir", "seed_runs"]

CONFIG_FILE = "config.yml"
ARGS_FILE = "args.yml"
COMMAND_FILE = "command.txt"
TRAIN_INFO_FILE = "train_info.json"
EVAL_DIR = "eval"
EVALUATIONS_FILE = f"{EVAL_DIR}/evaluations.npz"
"""Where ``EvalCallback(log_path=RUN/EVAL_DIR)`` writes its evaluations."""
LEARNING_CURVE_FILE = "learning_curve.png"
TB_DIR = "tb"
FINAL_AGENT_DIR = "final_agent"
BEST_MODEL_FILE = "best_model.zip"
FINAL_MODEL_FILE = "final_model.zip"
VECNORMALIZE_FILE = "vecnormalize.pkl"
REPLAY_BUFFER_FILE = "final_replay_buffer.pkl"
CHECKPOINT_DIR = "checkpoints"
CHECKPOINT_PREFIX = "model"
"""``CheckpointCallback(name_prefix=...)``: its files are ``model_<N>_steps.zip``,
``model_vecnormalize_<N>_steps.pkl`` and ``model_replay_buffer_<N>_steps.pkl``."""
TRAIN_LOG_FILE = "train.log"
SEED_CURVES_FILE = "learning_curves.png"
FANOUT_LOG_FILE = "fanout.log"

_SEED_DIR = re.compile(r"seed_(\d+)\Z")
_STEPS_IN_NAME = re.compile(r"_(\d+)_steps")


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and ``os.replace``."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def yaml_text(data) -> str:
    """YAML without anchors/aliases (``&id001``), tuples as lists, keys in their order."""
    import yaml

    class _NoAliases(yaml.SafeDumper):
        def ignore_aliases(self, data):
            return True

    return yaml.dump(to_jsonable(data), Dumper=_NoAliases, sort_keys=False)


# ---------------------------------------------------------------------- run records
def write_train_info(run: Path, info: dict) -> None:
    """Write ``train_info.json`` (indented JSON, atomically)."""
    write_text_atomic(Path(run) / TRAIN_INFO_FILE, json.dumps(info, indent=2))


def read_train_info(run: Path) -> dict:
    """``train_info.json`` of a run; ``{}`` when there is none.

    Raises
    ------
    ValueError
        When the file is not valid JSON.
    """
    path = Path(run) / TRAIN_INFO_FILE
    return json.loads(path.read_text()) if path.is_file() else {}


def trained_steps(run: Path) -> int:
    """``num_timesteps`` recorded in ``train_info.json``; -1 when absent or unreadable."""
    try:
        return int(read_train_info(run)["num_timesteps"])
    except (ValueError, KeyError, TypeError):
        return -1


def write_config(run: Path, config: dict) -> None:
    """Write ``config.yml`` (the resolved configuration of the run)."""
    write_text_atomic(Path(run) / CONFIG_FILE, yaml_text(config))


def read_config(run: Path) -> dict:
    """``config.yml`` of a run as plain data (``{}`` for an empty file).

    Raises
    ------
    FileNotFoundError
        When the run has no ``config.yml``.
    yaml.YAMLError
        When it is not valid YAML.
    """
    import yaml

    return yaml.safe_load((Path(run) / CONFIG_FILE).read_text()) or {}


def write_args(run: Path, args: dict) -> None:
    """Write ``args.yml`` (the parsed command line)."""
    write_text_atomic(Path(run) / ARGS_FILE, yaml_text(args))


def append_command(run: Path, command: str) -> None:
    """Add a line to ``command.txt`` (the file is rewritten atomically)."""
    path = Path(run) / COMMAND_FILE
    before = path.read_text() if path.is_file() else ""
    write_text_atomic(path, before + command + "\n")


# ---------------------------------------------------------------------- evaluations
def evaluations_path(run: Path) -> Path:
    """``eval/evaluations.npz`` of a run."""
    return Path(run) / EVALUATIONS_FILE


def read_evaluations(run: Path) -> dict[str, np.ndarray] | None:
    """The arrays of ``eval/evaluations.npz``; None when the run has none.

    ``timesteps``, ``results``, ``ep_lengths`` and, when recorded, ``successes``.
    """
    path = evaluations_path(run)
    if not path.is_file():
        return None
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def write_evaluations(run: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``eval/evaluations.npz`` (atomically)."""
    path = evaluations_path(run)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    named: dict[str, Any] = dict(arrays)  # (numpy's stubs confuse a key with allow_pickle)
    with open(tmp, "wb") as fh:
        np.savez(fh, **named)
    os.replace(tmp, path)


# ---------------------------------------------------------------------- saved models
@dataclass(frozen=True)
class SavedModel:
    """A stable-baselines3 model a run saved, with the files that belong to it.

    Attributes
    ----------
    model : Path
        The model ``.zip``.
    stats : Path
        Its ``VecNormalize`` statistics (may be absent).
    buffer : Path
        Its replay buffer (off-policy algorithms; may be absent).
    steps : int or None
        The step count in a checkpoint's name; None for the final model.
    """

    model: Path
    stats: Path
    buffer: Path
    steps: int | None


def saved_models(run: Path) -> list[SavedModel]:
    """The final model (if any), then every checkpoint ``model_<N>_steps.zip``."""
    run = Path(run)
    found = []
    final = run / FINAL_MODEL_FILE
    if final.is_file():
        found.append(SavedModel(final, run / VECNORMALIZE_FILE, run / REPLAY_BUFFER_FILE, None))
    prefix = CHECKPOINT_PREFIX
    for ckpt in (run / CHECKPOINT_DIR).glob(f"{prefix}_*_steps.zip"):
        tag = ckpt.stem.split("_")[-2]
        if not tag.isdigit():
            continue
        found.append(SavedModel(ckpt, ckpt.parent / f"{prefix}_vecnormalize_{tag}_steps.pkl",
                                ckpt.parent / f"{prefix}_replay_buffer_{tag}_steps.pkl",
                                int(tag)))
    return found


def checkpoint_steps(run: Path) -> int:
    """The largest N of any checkpoint file ``model*_<N>_steps*`` of a run; -1 if none."""
    folder = Path(run) / CHECKPOINT_DIR
    steps = -1
    if folder.is_dir():
        for path in folder.iterdir():
            match = _STEPS_IN_NAME.search(path.name)
            if match and path.name.startswith(CHECKPOINT_PREFIX):
                steps = max(steps, int(match.group(1)))
    return steps


# ---------------------------------------------------------------------- seed runs
def seed_dir(folder: Path, seed: int) -> Path:
    """The run folder of seed ``seed`` in a folder of seed runs: ``folder/seed_<seed>``."""
    return Path(folder) / f"seed_{seed}"


def seed_runs(folder) -> list[Path]:
    """The ``seed_K`` run folders of a folder of seed runs, by K (empty if none).

    The layout that ``train.py --seeds N`` writes and that the evaluation reads as one
    policy with one run per seed.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in folder.iterdir()
             if p.is_dir() and (m := _SEED_DIR.match(p.name))]
    return [p for _, p in sorted(found)]
