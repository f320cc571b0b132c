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
``eval/evaluations.npz``       the evaluations (stable-baselines3's layout, plus
                               ``episodes``: see :func:`evaluation_arrays`)
``learning_curve.png``         their plot
``tb/``                        TensorBoard
``train.log``                  what a seed of the fan-out printed
``final_model.zip``,           stable-baselines3's model zips; ``train.py --resume``
``checkpoints/model_<N>_steps.zip``  reads only their tensors (``torch.load(weights_only=True)``)
                               and plain JSON counters, never their pickled entries
``vecnormalize.npz``,          the normalisation statistics and the replay buffer
``final_replay_buffer.npz``    (SAC) as arrays, which ``--resume`` reads; likewise
                               ``checkpoints/model_vecnormalize_<N>_steps.npz``,
                               ``model_replay_buffer_<N>_steps.npz`` (the newest
                               checkpoint's only: 360 MB each for SAC's 1M buffer)
``best_model.zip``,            stable-baselines3's pickled files, read only on
``vecnormalize.pkl``,          opt-in (``--allow-pickle``; and
``final_replay_buffer.pkl``,   :mod:`tether_gym_agents.files.pickled`)
``checkpoints/*.pkl``
=============================  =======================================================

A folder of seed runs (``train.py --seeds N --out FOLDER``) holds ``seed_K/`` run
folders, ``fanout.log`` and ``learning_curves.png``.

Every file of a run is written atomically (a temporary name beside it, then
``os.replace``; :func:`write_text_atomic` for JSON, YAML and text, :func:`atomic_target`
for the rest: npz, the saved models, statistics, buffers, safe agents, plots): a kill
leaves the old file or the new one, never a piece. A file damaged otherwise is
reported with its path (:class:`DamagedFileError`), and a resumed run falls back to
what is intact (an older checkpoint, a new evaluation history).

Wall time. ``train_info.json`` is written when a call of ``train.py`` starts (before
its envs and model are built), then every ``PROGRESS_EVERY_S`` seconds and at the
end; each record holds ``wall_time_s`` (all calls so far) and ``updated_at`` (the
Unix time of the record [s]). A call killed between two records is not lost: when
the run is resumed and the record's ``status`` is not ``finished``, the time from
``updated_at`` to the newest file the killed call wrote (TensorBoard events,
evaluations, checkpoints: :func:`last_write_time`) is added to ``wall_time_s``, up to
ten minutes (``training.run.UNRECORDED_MAX_S``: a folder copied without its
modification times adds no more).
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..common.atomic_write import atomic_target, new_temporary_file, write_text_atomic
from ..common.jsonio import loads_json, to_jsonable
from ..common.yamlio import MAX_YAML_BYTES, load_yaml_file
from .folder_paths import FolderFileError, file_inside, folder_inside, size_cap
from .safe_format import AGENT_FILE
from .safe_npz import NpzFileError, after_path, read_npz

__all__ = ["CONFIG_FILE", "ARGS_FILE", "COMMAND_FILE", "TRAIN_INFO_FILE", "EVAL_DIR",
           "EVALUATIONS_FILE", "LEARNING_CURVE_FILE", "TB_DIR", "FINAL_AGENT_DIR",
           "BEST_MODEL_FILE", "FINAL_MODEL_FILE", "VECNORMALIZE_FILE", "REPLAY_BUFFER_FILE",
           "CHECKPOINT_DIR", "CHECKPOINT_PREFIX", "CHECKPOINT_AGENT_PREFIX", "TRAIN_LOG_FILE",
           "ITERATION_LOG_FILE",
           "SEED_CURVES_FILE",
           "FANOUT_LOG_FILE", "SavedModel", "DamagedFileError", "atomic_target",
           "last_write_time", "evaluation_arrays", "evaluation_rows", "write_text_atomic",
           "yaml_text", "write_train_info",
           "read_train_info", "trained_steps", "write_config", "read_config", "write_args",
           "append_command", "check_command_file", "evaluations_path", "read_evaluations",
           "write_evaluations",
           "saved_models", "checkpoint_steps", "checkpoint_agents", "seed_dir", "seed_runs",
           "prune_checkpoint_buffers", "check_writable_folder", "earlier_run",
           "check_fresh_run_folder"]

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
CHECKPOINT_AGENT_PREFIX = "agent"
"""Each checkpoint's policy as a safe agent folder, ``checkpoints/agent_<N>_steps/``,
whose ``agent.json`` records the steps and the run's wall time then (learning curves
against wall-clock time, evaluated afterwards on any suite)."""
TRAIN_LOG_FILE = "train.log"
"""The fan-out's text log of one run's console output (``train.py fanout``)."""
ITERATION_LOG_FILE = "train_log.json"
"""The in-process learners' per-iteration records (``train.py gpu``: its training
episodes per checkpoint; ``train.py distill``: one record per DAgger iteration)."""
SEED_CURVES_FILE = "learning_curves.png"
FANOUT_LOG_FILE = "fanout.log"

_SEED_DIR = re.compile(r"seed_(\d+)\Z")
_STEPS_IN_NAME = re.compile(r"_(\d+)_steps")


class DamagedFileError(ValueError):
    """A run file that exists but cannot be read (cut short, or not what it should hold)."""


def last_write_time(run: Path) -> float:
    """The newest modification time of any file in a run folder (Unix time [s]); 0 if none.

    Estimates when a killed call stopped writing (see the module's "Wall time").
    """
    newest = 0.0
    for path in Path(run).rglob("*"):
        try:
            if path.is_file():
                newest = max(newest, path.stat().st_mtime)
        except OSError:
            continue
    return newest


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
        When the file is not valid JSON, or not a regular file inside the run folder of
        at most 1 MiB (:class:`~.folder_paths.FolderFileError`).
    """
    path = Path(run) / TRAIN_INFO_FILE
    if not (path.exists() or path.is_symlink()):
        return {}
    return loads_json(file_inside(run, path).read_bytes(), path)


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

    Read with :func:`~tether_gym_agents.common.yamlio.load_yaml_file` (no code run, no
    anchors or aliases, bounded depth and size) after checking that it is a regular file
    inside the run folder (:func:`~.folder_paths.file_inside`).

    Raises
    ------
    FileNotFoundError
        When the run has no ``config.yml``.
    FolderFileError
        When it is not a regular file inside the run folder (a link leading out, a
        FIFO) or larger than :data:`~tether_gym_agents.common.yamlio.MAX_YAML_BYTES`.
    YamlFileError
        When it is not UTF-8 or not valid YAML (a ``ValueError`` naming it).
    """
    path = Path(run) / CONFIG_FILE
    if not (path.exists() or path.is_symlink()):
        raise FileNotFoundError(f"{path} does not exist")
    file_inside(run, path, max_bytes=MAX_YAML_BYTES)
    return load_yaml_file(path, what="run config") or {}


def write_args(run: Path, args: dict) -> None:
    """Write ``args.yml`` (the parsed command line)."""
    write_text_atomic(Path(run) / ARGS_FILE, yaml_text(args))


def append_command(run: Path, command: str) -> None:
    """Add a line to ``command.txt`` (the file is rewritten atomically).

    Raises
    ------
    FolderFileError
        When ``command.txt`` is a symlink (wherever it leads), a hard link (another name
        for the same file exists), not a regular file or over 1 MiB: rewriting it would
        copy what it points to into the run folder, which an export then ships.
    """
    check_command_file(run)
    path = Path(run) / COMMAND_FILE
    before = path.read_text() if path.exists() else ""
    write_text_atomic(path, before + command + "\n")


def check_command_file(run: Path) -> None:
    """Refuse a ``command.txt`` that :func:`append_command` must not rewrite (its Raises)."""
    path = Path(run) / COMMAND_FILE
    if path.is_symlink():
        raise FolderFileError(f"{path} is a symlink (to {path.resolve()}); a run's "
                              f"{COMMAND_FILE} must be a regular file, it is rewritten "
                              "and exported")
    if path.exists():
        file_inside(run, path)
        if path.stat().st_nlink > 1:
            raise FolderFileError(f"{path} is a hard link ({path.stat().st_nlink} names for "
                                  f"one file); a run's {COMMAND_FILE} must be a file of its "
                                  "own, it is rewritten and exported")


# ---------------------------------------------------------------------- evaluations
def evaluations_path(run: Path) -> Path:
    """``eval/evaluations.npz`` of a run."""
    return Path(run) / EVALUATIONS_FILE


_EVAL_KEYS = ("timesteps", "results", "ep_lengths")


def read_evaluations(run: Path) -> dict[str, np.ndarray] | None:
    """The arrays of ``eval/evaluations.npz``; None when the run has none.

    ``timesteps``, ``results``, ``ep_lengths`` and, when recorded, ``successes`` and
    ``episodes`` (see :func:`evaluation_arrays`).

    Raises
    ------
    DamagedFileError
        When the file is not a readable npz (cut short), not a regular file inside the run
        folder (a link leading out, a FIFO) or over its size cap, or lacks one of the arrays
        ``timesteps``, ``results``, ``ep_lengths``, or their lengths differ; the
        message names the file.
    """
    path = evaluations_path(run)
    if not (path.exists() or path.is_symlink()):
        return None
    try:
        file_inside(run, path)
    except FolderFileError as exc:
        raise DamagedFileError(str(exc)) from None
    try:
        arrays = read_npz(path, max_bytes=size_cap(path))
    except NpzFileError as exc:  # its message starts with the path
        raise DamagedFileError(f"{path}: damaged ({after_path(exc, path)})") from None
    except OSError as exc:
        raise DamagedFileError(f"{path}: damaged ({type(exc).__name__}: {exc})") from None
    missing = [k for k in _EVAL_KEYS if k not in arrays]
    if missing:
        raise DamagedFileError(f"{path}: damaged (no {', '.join(missing)}; it holds "
                               f"{sorted(arrays)})")
    if len({len(arrays[k]) for k in _EVAL_KEYS}) != 1:
        raise DamagedFileError(f"{path}: damaged (timesteps, results and ep_lengths hold "
                               f"{[len(arrays[k]) for k in _EVAL_KEYS]} evaluations)")
    return arrays


def write_evaluations(run: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``eval/evaluations.npz`` (atomically)."""
    path = evaluations_path(run)
    path.parent.mkdir(parents=True, exist_ok=True)
    named: dict[str, Any] = dict(arrays)  # (numpy's stubs confuse a key with allow_pickle)
    with atomic_target(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **named)


def _padded(rows: Sequence[Sequence[float]]) -> np.ndarray:
    """Rows of any lengths as one array; shorter rows padded with NaN (float then)."""
    width = max((len(r) for r in rows), default=0)
    if all(len(r) == width for r in rows):
        return np.array(rows).reshape(len(rows), width)
    table = np.full((len(rows), width), np.nan)
    for i, row in enumerate(rows):
        table[i, :len(row)] = row
    return table


def evaluation_arrays(timesteps: list[int], results: list[list[float]],
                      lengths: list[list[int]], successes: list[list[bool]] | None = None
                      ) -> dict[str, np.ndarray]:
    """The arrays of ``eval/evaluations.npz`` for evaluations of any episode counts.

    ``results[i]`` and ``lengths[i]`` are the returns [-] and lengths [steps] of the
    episodes of the evaluation at ``timesteps[i]``. As stable-baselines3 stores them,
    one row per evaluation; when the counts differ (a run resumed with another
    ``--eval-episodes``) the shorter rows are padded with NaN, and ``episodes`` (always
    written) holds each row's count. :func:`evaluation_rows` reads them back.
    """
    arrays = {"timesteps": np.asarray(timesteps, dtype=np.int64).reshape(-1),
              "results": _padded(results), "ep_lengths": _padded(lengths),
              "episodes": np.array([len(r) for r in results], dtype=np.int64)}
    if successes:
        arrays["successes"] = _padded(successes)
    return arrays


def evaluation_rows(arrays: dict[str, np.ndarray]) -> dict[str, list[list]]:
    """Each evaluation's own episodes from :func:`evaluation_arrays` (padding removed).

    Returns ``{"results": [...], "ep_lengths": [...]}`` (and ``"successes"`` when
    recorded), one list per evaluation; a file without ``episodes`` (written by
    stable-baselines3 itself) has full rows.
    """
    n = len(arrays["timesteps"])
    counts = arrays.get("episodes", np.full(n, arrays["results"].shape[1] if n else 0))
    rows: dict[str, list[list]] = {}
    for key in ("results", "ep_lengths", "successes"):
        if key in arrays:
            cast = bool if key == "successes" else (int if key == "ep_lengths" else float)
            rows[key] = [[cast(v) for v in arrays[key][i, :int(counts[i])]] for i in range(n)]
    return rows


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
    """The final model (if any), then every checkpoint ``model_<N>_steps.zip``.

    Whatever is at those names is listed (a folder, a FIFO, a link): the readers check
    each with :func:`~.folder_paths.file_inside` before opening it.
    """
    run = Path(run)
    found = []
    final = run / FINAL_MODEL_FILE
    if final.exists() or final.is_symlink():  # a FIFO too: the reader refuses it, by name
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


def prune_checkpoint_buffers(run: Path, keep_steps: int) -> list[Path]:
    """Delete the replay buffers of every checkpoint but ``model_<keep_steps>_steps``.

    Each checkpoint of an off-policy run otherwise keeps its own copy of the whole
    buffer (SAC with ``buffer_size`` 1M and 16 envs: 360 MB per checkpoint, ``.pkl`` and
    ``.npz``; a 300k-step run with a checkpoint every 50k steps kept 2.2 GB of them).
    ``--resume`` reads only the newest whole checkpoint's buffer; a run resumed from an
    older checkpoint (the newest one damaged) continues with an empty buffer, which
    ``--resume`` says. Returns the deleted files.
    """
    folder = Path(run) / CHECKPOINT_DIR
    deleted = []
    for path in sorted(folder.glob(f"{CHECKPOINT_PREFIX}_replay_buffer_*_steps.*")):
        match = _STEPS_IN_NAME.search(path.name)
        if match and int(match.group(1)) != keep_steps and path.suffix in (".pkl", ".npz"):
            path.unlink(missing_ok=True)
            deleted.append(path)
    return deleted


def checkpoint_agents(run: Path) -> list[tuple[int, Path]]:
    """``(N, folder)`` of every ``checkpoints/agent_<N>_steps/`` of a run, by N.

    A folder without its ``agent.json`` (a call killed while writing it) is left out.

    Raises
    ------
    FolderFileError
        When such a folder (or ``checkpoints/``) is a symlink leading outside the run
        folder.
    """
    folder = Path(run) / CHECKPOINT_DIR
    if not folder.is_dir():
        return []
    folder_inside(run, folder)
    found = []
    for path in folder.iterdir():
        match = _STEPS_IN_NAME.search(path.name)
        if not (match and path.name.startswith(CHECKPOINT_AGENT_PREFIX + "_")):
            continue
        if path.is_symlink():
            folder_inside(run, path)
        if (path / AGENT_FILE).exists() or (path / AGENT_FILE).is_symlink():
            found.append((int(match.group(1)), path))
    return sorted(found)


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


def check_writable_folder(out: Path, written: Sequence[str]) -> None:
    """Refuse an output folder that a training call could not write.

    ``out`` must exist or be creatable, take a file, and hold no folder at a ``written``
    name (the files the call writes at its top).

    Raises
    ------
    FolderFileError
        Naming what is wrong; the caller puts its flag (``--out PATH:``) in front.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise FolderFileError("is a file; give a folder (new or a run folder)")
    for name in written:
        if (out / name).is_dir():
            raise FolderFileError(f"{out / name} is a folder; the run writes a file there "
                                  "(remove or rename it)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        new_temporary_file(out / "write_test").unlink()  # a new file, nothing written to
    except OSError as exc:
        raise FolderFileError(f"cannot write there ({exc.strerror or exc})") from None


def earlier_run(run: Path) -> str:
    """What an earlier training call left in ``run`` that a new run would mix with its own.

    Its checkpoints (``checkpoints/*_<N>_steps*``: ``--resume`` continues the largest N,
    and the learning curves read them all) and the final model and agent of a finished
    stable-baselines3 run. A fresh run into such a folder is refused, since its own
    checkpoints would land beside the old ones. Empty when there are none: a new
    folder, or a call killed before its first checkpoint (whose best ``agent.json``, if
    an evaluation wrote one, the new run's first evaluation replaces).

    Returns
    -------
    str
        The names found, relative to ``run`` (sorted; the first three, then how many
        more), or "" when there are none.
    """
    run = Path(run)
    found = [name for name in (FINAL_MODEL_FILE, FINAL_AGENT_DIR)
             if (run / name).exists() or (run / name).is_symlink()]
    folder = run / CHECKPOINT_DIR
    if folder.is_dir():
        found += [f"{CHECKPOINT_DIR}/{path.name}" for path in folder.iterdir()
                  if _STEPS_IN_NAME.search(path.name)]
    found.sort()
    more = f" and {len(found) - 3} more" if len(found) > 3 else ""
    return ", ".join(found[:3]) + more


def check_fresh_run_folder(run: Path, written: Sequence[str], instead: str) -> None:
    """Refuse ``run`` as the folder of a new training run (not a resumed one).

    It must be writable (:func:`check_writable_folder`, which makes it), hold at each
    ``written`` name nothing but a regular file inside it (a symlink leading out or a
    FIFO there is refused: before, a symlinked ``command.txt`` was a traceback after
    ``config.yml`` was written), and hold no earlier run's checkpoints or final model
    (:func:`earlier_run`). A refused folder keeps its files.

    Parameters
    ----------
    run : Path
        The run folder.
    written : sequence of str
        The files the call writes at the top of ``run``.
    instead : str
        What the user can do instead, for the message ("give a new --out, ...").

    Raises
    ------
    FolderFileError
        Naming what is wrong; the caller puts its flag in front.
    """
    check_writable_folder(run, written)
    for name in written:  # (a resumed run's files are checked by its resume)
        target = Path(run) / name
        if target.is_symlink() or target.exists():
            try:  # a link out, a FIFO: a write or append through it lands outside or blocks
                file_inside(run, target)
            except FolderFileError as exc:
                raise FolderFileError(f"{exc}; the run writes a file there (remove or "
                                      "rename it)") from None
    found = earlier_run(run)
    if found:
        raise FolderFileError(f"already holds an earlier training run ({found}), whose "
                              f"checkpoints a new run's would mix with; {instead}")


# ---------------------------------------------------------------------- seed runs
def seed_dir(folder: Path, seed: int) -> Path:
    """The run folder of seed ``seed`` in a folder of seed runs: ``folder/seed_<seed>``."""
    return Path(folder) / f"seed_{seed}"


def seed_runs(folder) -> list[Path]:
    """The ``seed_K`` run folders of a folder of seed runs, by K (empty if none).

    The layout that ``train.py --seeds N`` writes and that the evaluation reads as one
    policy with one run per seed.

    Raises
    ------
    FolderFileError
        When a ``seed_K`` is a symlink leading outside ``folder`` (to another run).
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in folder.iterdir()
             if (m := _SEED_DIR.match(p.name)) and (p.is_dir() or p.is_symlink())]
    for _, path in found:
        if path.is_symlink():
            folder_inside(folder, path)
    return [p for _, p in sorted(found) if p.is_dir()]
