"""stable-baselines3's pickled run folders (``*.zip`` + ``vecnormalize.pkl``): opt-in only.

Both files can run arbitrary code when they are loaded (cloudpickled entries in the
zip's ``data``, a plain pickle); they are read only by :func:`load_pickled_run`, behind
an explicit ``allow_pickle=True``, and :func:`~tether_gym_agents.files.export.convert_run`
turns such a run folder into a safe agent folder once.

Two layouts are read: ``train.py``'s run folders (:mod:`.run_folder`) and rl-baselines3-zoo's
(:mod:`.zoo_folder`: ``LOGS/ALGO/<ENV_NAME>_<N>/`` with ``<ENV_NAME>.zip`` and
``<ENV_NAME>/{config.yml,args.yml,vecnormalize.pkl}``). Every file is read only if it is a
regular file inside the run folder (:mod:`.folder_paths`).
"""

from __future__ import annotations

import importlib
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..common.algorithms import ALGORITHMS, ALGOS, split_name
from ..common.features import FeatureSpec
from ..hybrids.residual_spec import ResidualSpec
from .run_folder import (
    BEST_MODEL_FILE,
    CONFIG_FILE,
    FINAL_MODEL_FILE,
    VECNORMALIZE_FILE,
    read_config,
)
from .safe_format import (
    AGENT_FILE,
    AgentLoadError,
    ObsNormalization,
    checked_file,
    recorded_spec,
)
from .zoo_folder import ZooFolderError, ZooRun, find_zoo_run, zoo_config

__all__ = ["PICKLED_MODEL_FILES", "PICKLE_WARNING", "PickledRun", "load_pickled_run",
           "run_hybrid", "run_features", "is_pickled_run"]

PICKLED_MODEL_FILES = (BEST_MODEL_FILE, FINAL_MODEL_FILE, "model.zip")
"""stable-baselines3 model files that a run folder may hold (pickled: opt-in only)."""
PICKLE_WARNING = ("loading pickled agent files ({files}): a pickle can run any code when "
                  "it is loaded; do this only for files you made yourself or trust")


@dataclass(frozen=True)
class PickledRun:
    """A model loaded from a run folder's pickled files.

    Attributes
    ----------
    model : stable_baselines3 (or sb3-contrib) model
        Of the library class of its algorithm's row
        (:data:`~tether_gym_agents.common.algorithms.ALGORITHMS`).
    norm : ObsNormalization or None
        Its observation statistics (None: observations were not normalised).
    algo : str
    run_dir, model_path : Path
    config : dict
        The run's ``config.yml``.
    """

    model: Any
    norm: ObsNormalization | None
    algo: str
    run_dir: Path
    model_path: Path
    config: dict


def _refuse(files) -> AgentLoadError:
    return AgentLoadError(
        f"refusing pickled agent files {[str(f) for f in files]}: loading them can run code "
        "from the file. Convert a run folder you trust once with `python -m "
        "tether_gym_agents.files convert RUN_DIR --allow-pickle`, or load it with "
        "allow_pickle=True (evaluate.py --allow-pickle)")


def is_pickled_run(path) -> bool:
    """Whether ``path`` is a run folder of pickled files (``train.py``'s or rl_zoo3's)."""
    path = Path(path)
    if any((path / f).is_file() for f in PICKLED_MODEL_FILES):
        return True
    try:
        return find_zoo_run(path) is not None
    except ZooFolderError:
        return True  # a zoo run without a model: load_pickled_run says what is missing


def _zoo_run(path: Path) -> ZooRun | None:
    try:
        return find_zoo_run(path)
    except ZooFolderError as exc:
        raise AgentLoadError(str(exc)) from None


def _model_file(path: Path) -> tuple[Path, Path]:
    """(run folder, model file) that ``path`` designates."""
    if path.is_dir():
        found = [path / f for f in PICKLED_MODEL_FILES if (path / f).is_file()]
        if not found:
            raise AgentLoadError(f"no agent in {path}: neither {AGENT_FILE} nor a model file "
                                 f"({', '.join(PICKLED_MODEL_FILES)})")
        return path, found[0]
    if path.is_file():
        return path.parent, path
    raise AgentLoadError(f"agent path {str(path)!r} does not exist")


def load_pickled_run(path, allow_pickle: bool = False, algo: str | None = None) -> PickledRun:
    """Load a stable-baselines3 run folder (``*.zip`` + ``vecnormalize.pkl``): opt-in only.

    The folder must be a complete unit: a model file, ``config.yml`` recording the
    algorithm and whether observations were normalised, and ``vecnormalize.pkl`` when
    they were. A lone ``.zip`` needs its run folder around it.

    Raises
    ------
    AgentLoadError
        Without ``allow_pickle=True`` (the message says how to convert), or when a
        piece is missing (named).
    """
    import zipfile

    zoo = _zoo_run(Path(path))
    if zoo is not None:
        run_dir, model_path, stats = zoo.run_dir, zoo.model_path, zoo.stats_path
    else:
        run_dir, model_path = _model_file(Path(path))
        stats = run_dir / VECNORMALIZE_FILE
    if not allow_pickle:
        raise _refuse([model_path] + ([stats] if stats.is_file() else []))
    checked_file(run_dir, model_path)
    cfg = _run_config(run_dir, model_path) if zoo is None else _zoo_config(zoo)
    algo = algo or cfg.get("algo") or ""
    algo = algo.lower() if isinstance(algo, str) else ""
    if algo not in ALGORITHMS:
        where = run_dir / CONFIG_FILE if zoo is None else zoo.params_dir / "args.yml"
        raise AgentLoadError(f"{where} does not record a supported algorithm (one of "
                             f"{list(ALGOS)}), got {cfg.get('algo')!r}")
    normalize = (cfg.get("hyperparams") or {}).get("normalize", None)
    if normalize is None:
        raise AgentLoadError(f"{run_dir / CONFIG_FILE} does not record hyperparams.normalize: "
                             "cannot tell whether observations must be normalised")
    warnings.warn(PICKLE_WARNING.format(files=[str(model_path)]), stacklevel=2)
    row = ALGORITHMS[algo]
    module, name = split_name(row.library_model)
    try:
        cls: Any = getattr(importlib.import_module(module), name)
    except ImportError:
        raise AgentLoadError(f"{model_path} is a {algo.upper()} model: {row.install()}"
                             ) from None
    try:
        model = cls.load(model_path, device="cpu")
    except (zipfile.BadZipFile, KeyError, ValueError, EOFError, RuntimeError) as exc:
        raise AgentLoadError(f"cannot load {algo.upper()} model {model_path}: {exc}") from exc
    norm = None
    if normalize is not False and (not isinstance(normalize, dict)
                                   or normalize.get("norm_obs", True)):
        norm = _pickled_stats(run_dir, stats, model_path)
    return PickledRun(model, norm, algo, run_dir, model_path, cfg)


def _zoo_config(zoo: ZooRun) -> dict:
    """The settings of an rl_zoo3 run (its YAML read as plain data)."""
    for name in ("config.yml", "args.yml"):
        checked_file(zoo.run_dir, zoo.params_dir / name)
    try:
        return zoo_config(zoo)
    except ZooFolderError as exc:
        raise AgentLoadError(str(exc)) from None


def _run_config(run_dir: Path, model_path: Path) -> dict:
    """``config.yml`` beside a pickled model; a missing or malformed one is an error.

    Raises AgentLoadError naming the file when it is missing, not valid YAML (or beyond
    the limits of :mod:`~tether_gym_agents.common.yamlio`), or not a mapping whose
    ``hyperparams`` is a mapping.
    """
    from ..common.yamlio import YamlFileError

    path = run_dir / CONFIG_FILE
    if not path.is_file():
        raise AgentLoadError(f"agent {model_path} is incomplete: {CONFIG_FILE} (algorithm, "
                             "normalisation) is missing beside it")
    checked_file(run_dir, path)
    try:
        cfg = read_config(run_dir)
    except YamlFileError as exc:
        raise AgentLoadError(str(exc)) from None
    if not isinstance(cfg, dict) or not isinstance(cfg.get("hyperparams") or {}, dict):
        raise AgentLoadError(f"{path} must be a mapping with a mapping 'hyperparams' (as "
                             f"train.py writes it), got {type(cfg).__name__}")
    return cfg


def _pickled_stats(run_dir: Path, stats: Path, model_path: Path) -> ObsNormalization | None:
    """The observation statistics of a pickled ``vecnormalize.pkl`` (None: norm_obs off)."""
    import pickle

    if not stats.is_file():
        raise AgentLoadError(f"agent {model_path} is incomplete: its observation "
                             f"statistics {stats.name} are missing ({CONFIG_FILE} says "
                             "observations were normalised)")
    checked_file(run_dir, stats)
    try:
        with open(stats, "rb") as fh:
            vecnorm = pickle.load(fh)
    except Exception as exc:  # noqa: BLE001 - any unpickling failure is a corrupt file
        raise AgentLoadError(f"corrupt normalisation statistics {stats}: {exc}") from exc
    if not hasattr(vecnorm, "obs_rms"):
        raise AgentLoadError(f"{stats} does not hold VecNormalize statistics")
    if getattr(vecnorm, "norm_obs", True) is False:
        return None
    return ObsNormalization.of_stats(vecnorm.obs_rms, vecnorm.clip_obs, vecnorm.epsilon)


def run_hybrid(config: dict) -> dict | None:
    """The hybrid of a run from its ``config.yml`` (its ``residual`` hyperparameter).

    Raises
    ------
    AgentLoadError
        If the recorded ``residual`` is not a valid ResidualSpec.
    """
    return recorded_spec(ResidualSpec, (config.get("hyperparams") or {}).get("residual"),
                         "config.yml: hyperparams.residual")


def run_features(config: dict) -> dict | None:
    """The input features of a run from its ``config.yml`` (its ``features`` hyperparameter).

    Raises
    ------
    AgentLoadError
        If the recorded ``features`` is not a valid FeatureSpec.
    """
    return recorded_spec(FeatureSpec, (config.get("hyperparams") or {}).get("features"),
                         "config.yml: hyperparams.features")
