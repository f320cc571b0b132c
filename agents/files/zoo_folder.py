"""rl-baselines3-zoo's run folders, read as plain data (its YAML) around pickled models.

``python -m rl_zoo3.train --algo ALGO --env ENV_ID -f LOGS`` (its ``ExperimentManager``)
writes one folder per run, ``LOGS/ALGO/<ENV_NAME>_<N>/``, where ``ENV_NAME`` is the env id
with ``/`` replaced by ``-`` (``tether_gym-TetherLibration-v1``):

==================================  ====================================================
``<ENV_NAME>.zip``                  the model at the last step (pickled)
``best_model.zip``                  the best model, when it evaluated during training
``evaluations.npz``                 those evaluations
``<ENV_NAME>/config.yml``           the hyperparameters it used (``normalize``,
                                    ``env_kwargs``, ``policy_kwargs``, ...)
``<ENV_NAME>/args.yml``             its command line (``algo``, ``env``, ``seed``, ...)
``<ENV_NAME>/command.txt``          the command
``<ENV_NAME>/vecnormalize.pkl``     ``VecNormalize`` statistics (pickled), when
                                    ``normalize`` was on
==================================  ====================================================

Both YAML files are dumps of ``OrderedDict`` objects (``!!python/object/apply:
collections.OrderedDict``); :func:`read_zoo_yaml` reads them with a safe loader that
knows this one tag (and ``!!python/tuple``) and refuses every other Python tag, so
reading them runs no code. The model is the last one (``<ENV_NAME>.zip``), as
``rl_zoo3.enjoy`` loads by default: ``vecnormalize.pkl`` holds the statistics of the last
step (the zoo rewrites it on every new best and at the end), so ``best_model.zip`` is used
only when the last model is missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..common.yamlio import MAX_YAML_BYTES, YamlFileError, load_yaml_file
from .folder_paths import FolderFileError, file_inside

__all__ = ["ZOO_CONFIG_FILE", "ZOO_ARGS_FILE", "ZOO_STATS_FILE", "ZOO_BEST_MODEL_FILE",
           "ZooRun", "ZooFolderError", "find_zoo_run", "read_zoo_yaml", "zoo_config"]

ZOO_CONFIG_FILE = "config.yml"
ZOO_ARGS_FILE = "args.yml"
ZOO_STATS_FILE = "vecnormalize.pkl"
ZOO_BEST_MODEL_FILE = "best_model.zip"
_ORDERED_DICT_TAG = "tag:yaml.org,2002:python/object/apply:collections.OrderedDict"
_TUPLE_TAG = "tag:yaml.org,2002:python/tuple"


class ZooFolderError(ValueError):
    """An rl_zoo3 run folder is incomplete or its YAML is not what the zoo writes."""


@dataclass(frozen=True)
class ZooRun:
    """The pieces of one rl_zoo3 run folder.

    Attributes
    ----------
    run_dir : Path
        ``LOGS/ALGO/<ENV_NAME>_<N>``.
    params_dir : Path
        ``run_dir/<ENV_NAME>`` (``config.yml``, ``args.yml``, ``vecnormalize.pkl``).
    model_path : Path
        The model file to load.
    """

    run_dir: Path
    params_dir: Path
    model_path: Path

    @property
    def stats_path(self) -> Path:
        """Where the zoo writes the ``VecNormalize`` statistics."""
        return self.params_dir / ZOO_STATS_FILE


def _params_dirs(run_dir: Path) -> list[Path]:
    return sorted(d for d in run_dir.iterdir() if d.is_dir()
                  and (d / ZOO_CONFIG_FILE).is_file() and (d / ZOO_ARGS_FILE).is_file())


def find_zoo_run(path) -> ZooRun | None:
    """The rl_zoo3 run that ``path`` designates; None when ``path`` is not one.

    ``path`` may be the run folder, its ``<ENV_NAME>/`` folder or one of its model
    ``.zip`` files.

    Raises
    ------
    ZooFolderError
        If the folder is an rl_zoo3 run but holds no model file.
    """
    path = Path(path)
    if path.is_file():
        if path.suffix != ".zip" or not _params_dirs(path.parent):
            return None
        run_dir = path.parent
    elif path.is_dir():
        run_dir = path
        if not _params_dirs(path) and (path.parent / f"{path.name}.zip").is_file() \
                and path in _params_dirs(path.parent):
            run_dir = path.parent
    else:
        return None
    dirs = _params_dirs(run_dir)
    if not dirs:
        return None
    named = [d for d in dirs if (run_dir / f"{d.name}.zip").is_file()]
    params = (named or dirs)[0]
    if path.is_file():
        return ZooRun(run_dir, params, path)
    for model in (run_dir / f"{params.name}.zip", run_dir / ZOO_BEST_MODEL_FILE):
        if model.is_file():
            return ZooRun(run_dir, params, model)
    raise ZooFolderError(f"rl_zoo3 run {run_dir} holds no model: neither {params.name}.zip "
                         f"nor {ZOO_BEST_MODEL_FILE}")


def read_zoo_yaml(path: Path) -> dict:
    """A YAML file the zoo wrote (an ``OrderedDict`` dump) as a dict; no code is run.

    Read with :func:`~tether_gym_agents.common.yamlio.load_yaml_file` (its size, alias and
    depth limits) and the zoo's two tags (``OrderedDict``, ``tuple``) as plain data.

    Raises
    ------
    ZooFolderError
        If the file is not valid YAML, uses another Python tag, an anchor or alias, or
        nests too deeply, is not a mapping, or is not a regular file in its folder of at
        most :data:`~tether_gym_agents.common.yamlio.MAX_YAML_BYTES` (checked before it
        is opened).
    """
    import yaml

    def ordered_dict(loader, node):
        args = loader.construct_sequence(node, deep=True)
        pairs = args[0] if len(args) == 1 and isinstance(args[0], list) else None
        if pairs is None or not all(isinstance(p, list) and len(p) == 2 for p in pairs):
            raise yaml.constructor.ConstructorError(None, None, "an OrderedDict that is not "
                                                    "a list of key-value pairs", node.start_mark)
        return {k: v for k, v in pairs}

    def as_tuple(loader, node):
        return tuple(loader.construct_sequence(node))

    try:
        file_inside(Path(path).parent, path, max_bytes=MAX_YAML_BYTES)
    except FolderFileError as exc:
        raise ZooFolderError(str(exc)) from None
    try:
        data = load_yaml_file(path, what="rl_zoo3 file", constructors={
            _ORDERED_DICT_TAG: ordered_dict, _TUPLE_TAG: as_tuple})
    except YamlFileError as exc:
        raise ZooFolderError(f"{path} cannot be read as rl_zoo3's YAML (plain data and "
                             f"OrderedDict only): {exc}") from None
    if not isinstance(data, dict):
        raise ZooFolderError(f"{path} is not a mapping (got {type(data).__name__})")
    return data


def zoo_config(run: ZooRun) -> dict:
    """The run's settings in the form of ``train.py``'s ``config.yml``.

    ``algo``, ``env_id``, ``env_kwargs`` (``config.yml``'s, else the command line's),
    ``seed`` and ``hyperparams`` (``config.yml``, with ``normalize`` as recorded, or, when
    the zoo recorded it as a string of Python code (never evaluated here), True when
    ``vecnormalize.pkl`` is there).
    """
    hyper = read_zoo_yaml(run.params_dir / ZOO_CONFIG_FILE)
    args = read_zoo_yaml(run.params_dir / ZOO_ARGS_FILE)
    normalize = hyper.get("normalize", False)
    if not isinstance(normalize, (bool, dict)):
        normalize = run.stats_path.is_file()
    env_kwargs = hyper.get("env_kwargs") or args.get("env_kwargs") or {}
    return {"algo": args.get("algo"), "env_id": args.get("env"), "env_kwargs": dict(env_kwargs),
            "seed": args.get("seed"), "hyperparams": {**hyper, "normalize": normalize},
            "source": "rl_zoo3"}
