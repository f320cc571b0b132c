"""Agent files that hold only tensors and plain data: loading one never runs code.

An agent is one folder (a *unit*) with two files:

``agent.json``
    Plain JSON: the format version, the algorithm (``"ppo"`` or ``"sac"``), the
    stable-baselines3 policy class and its constructor settings (``net_arch``,
    activation, ``log_std_init``, ...), the observation and action spaces (shape,
    dtype, bounds), the observation normalisation statistics (``mean``, ``var``,
    ``clip_obs``, ``epsilon``; ``null`` when observations are not normalised), the env
    id and env kwargs the agent was trained on, the training seed and steps, the
    name and SHA-256 of the weights file, and ``hybrid``: ``null`` for a plain agent,
    ``{"base": "smc", "scale": ..., "filter": ...}`` for the residual of a hybrid
    (:mod:`tether_gym_agents.hybrids.residual_spec`; absent in older files, read as ``null``),
    and ``features``: ``null``, or ``{"name": ..., "scale": ...}`` for a policy whose
    network also sees features computed from the observation
    (:mod:`tether_gym_agents.common.features`; absent in older files, read as ``null``).
``policy.safetensors``
    The policy's ``state_dict`` in the safetensors format: a JSON header (names,
    dtypes, shapes, offsets) followed by raw tensor bytes. Reading it builds tensors
    and nothing else; there is no pickle in it, unlike ``torch.save`` files, whose
    ``weights_only`` unpickler has had code-execution holes (CVE-2025-32434 in torch
    <= 2.5.1, CVE-2026-24747 in torch < 2.10).

Loading rebuilds the policy from ``agent.json`` (``policy_class(observation_space,
action_space, lr_schedule, **policy_kwargs)``; classes are looked up by name in a fixed
allow-list, never imported from the file) and loads the weights into it. A missing or
modified piece is an error that names it.

stable-baselines3's own ``.zip`` (cloudpickled entries in ``data``) and
``vecnormalize.pkl`` (a pickle) can run arbitrary code when loaded; they are read only
by :func:`load_pickled_run`, behind an explicit ``allow_pickle=True``, and
:func:`convert_run` turns such a run folder into a safe unit once.
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..common.features import FeatureSpec
from ..common.jsonio import sha256_file, to_jsonable
from ..hybrids.residual_spec import ResidualSpec

__all__ = ["AgentLoadError", "AGENT_FILE", "WEIGHTS_FILE", "FORMAT", "FORMAT_VERSION",
           "save_agent", "load_agent", "load_pickled_run", "convert_run", "is_unit",
           "PICKLED_MODEL_FILES", "run_hybrid", "run_features"]

AGENT_FILE = "agent.json"
WEIGHTS_FILE = "policy.safetensors"
FORMAT = "tether_gym-agent"
FORMAT_VERSION = 1
PICKLED_MODEL_FILES = ("best_model.zip", "final_model.zip", "model.zip")
"""stable-baselines3 model files that a run folder may hold (pickled: opt-in only)."""

# Class-valued policy settings are stored by name and looked up here, never imported.
_POLICY_CLASSES = {
    ("ppo", "ActorCriticPolicy"): ("stable_baselines3.common.policies", "ActorCriticPolicy"),
    ("sac", "SACPolicy"): ("stable_baselines3.sac.policies", "SACPolicy"),
}
_ACTIVATIONS = ("Tanh", "ReLU", "ELU", "LeakyReLU", "GELU", "SiLU", "Sigmoid", "Softplus",
                "Mish")
_EXTRACTORS = ("FlattenExtractor",)
# constructor settings that only matter for training (the optimiser) or are rebuilt
_SKIP_SETTINGS = ("observation_space", "action_space", "lr_schedule", "optimizer_class",
                  "optimizer_kwargs")
# the part of the policy that ``predict`` uses (SAC's critics are not needed to act)
_WEIGHTS_MODULE = {"ppo": "policy", "sac": "actor"}


class AgentLoadError(ValueError):
    """An agent folder or file is missing, incomplete, corrupt or in a refused format."""


# ---------------------------------------------------------------------- plain data
def _float_list(arr) -> list:
    """Floats as JSON numbers; inf/nan as the strings "inf", "-inf", "nan" (strict JSON)."""
    out = []
    for x in np.asarray(arr, dtype=np.float64).ravel().tolist():
        out.append(x if math.isfinite(x) else repr(x))
    return out


def _float_array(values, shape, dtype, what: str) -> np.ndarray:
    try:
        arr = np.array([float(v) for v in values], dtype=np.float64)
        return arr.reshape(shape).astype(dtype)
    except (TypeError, ValueError) as exc:
        raise AgentLoadError(f"{what}: {exc}") from None


def _space_to_json(space) -> dict:
    from gymnasium import spaces

    if not isinstance(space, spaces.Box):
        raise TypeError(f"only Box spaces can be saved, got {type(space).__name__}")
    return {"type": "Box", "shape": list(space.shape), "dtype": str(space.dtype),
            "low": _float_list(space.low), "high": _float_list(space.high)}


def _space_from_json(data: dict, what: str):
    from gymnasium import spaces

    try:
        if data["type"] != "Box":
            raise AgentLoadError(f"{what}: only Box spaces are supported, got {data['type']!r}")
        shape = tuple(int(s) for s in data["shape"])
        dtype = np.dtype(data["dtype"])
        if dtype.kind != "f":
            raise AgentLoadError(f"{what}: dtype {dtype} is not a float type")
        low = _float_array(data["low"], shape, dtype, f"{what}.low")
        high = _float_array(data["high"], shape, dtype, f"{what}.high")
    except (KeyError, TypeError) as exc:
        raise AgentLoadError(f"{what} is malformed ({exc!r})") from None
    return spaces.Box(low=low, high=high, shape=shape, dtype=dtype)


def _settings_to_json(params: dict) -> dict:
    out = {}
    for key, value in params.items():
        if key in _SKIP_SETTINGS:
            continue
        if key == "activation_fn":
            name = value.__name__
            if name not in _ACTIVATIONS or value.__module__.split(".")[0] != "torch":
                raise TypeError(f"activation_fn {value!r} cannot be saved; supported: "
                                f"{_ACTIVATIONS}")
            out[key] = name
        elif key == "features_extractor_class":
            if value.__name__ not in _EXTRACTORS:
                raise TypeError(f"features_extractor_class {value!r} cannot be saved; "
                                f"supported: {_EXTRACTORS}")
            out[key] = value.__name__
        else:
            json.dumps(value)  # TypeError for anything that is not plain data
            out[key] = value
    return out


def _settings_from_json(data: dict) -> dict:
    import torch.nn as nn
    from stable_baselines3.common import torch_layers

    if not isinstance(data, dict):
        raise AgentLoadError(f"policy_kwargs must be a mapping, got {data!r}")
    out = dict(data)
    if "activation_fn" in out:
        if out["activation_fn"] not in _ACTIVATIONS:
            raise AgentLoadError(f"activation_fn {out['activation_fn']!r} is not one of "
                                 f"{_ACTIVATIONS}")
        out["activation_fn"] = getattr(nn, out["activation_fn"])
    if "features_extractor_class" in out:
        if out["features_extractor_class"] not in _EXTRACTORS:
            raise AgentLoadError(f"features_extractor_class {out['features_extractor_class']!r}"
                                 f" is not one of {_EXTRACTORS}")
        out["features_extractor_class"] = getattr(torch_layers, out["features_extractor_class"])
    return out


def _safetensors():
    try:
        import safetensors.torch
    except ImportError:
        raise ImportError("agent files need safetensors: pip install safetensors (or "
                          "pip install -e \".[train]\")") from None
    return safetensors.torch


# ---------------------------------------------------------------------- save
def save_agent(path, policy, algo: str, obs_rms=None, clip_obs: float = 10.0,
               epsilon: float = 1e-8, env_id: str | None = None,
               env_kwargs: dict | None = None, training: dict | None = None,
               hybrid: dict | None = None, features: dict | None = None) -> Path:
    """Write a policy and its observation normalisation as a safe agent folder.

    Parameters
    ----------
    path : path-like
        The agent folder (created; ``agent.json`` and ``policy.safetensors`` are replaced).
    policy : stable_baselines3 policy
        ``model.policy`` of a PPO or SAC model.
    algo : {"ppo", "sac"}
        The algorithm that trained it (recorded, so loading never guesses).
    obs_rms : RunningMeanStd or None
        Observation statistics of ``VecNormalize`` (None: observations are not
        normalised).
    clip_obs, epsilon : float
        ``VecNormalize``'s clip [-] and epsilon [-].
    env_id, env_kwargs : str, dict
        The environment the agent was trained on.
    training : dict or None
        Plain-data facts about the training (seed, steps, ...).
    hybrid : dict or None
        The residual hybrid the policy is the residual of (``ResidualSpec.to_dict()``:
        base, scale, filter); None for a policy that acts alone.
    features : dict or None
        The input features the policy appends to the observation
        (``FeatureSpec.to_dict()``); None for the observation alone.

    Returns
    -------
    Path
        The agent folder.
    """
    algo = algo.lower()
    if hybrid is not None:
        hybrid = ResidualSpec.from_dict(hybrid, "hybrid").to_dict()
    if features is not None:
        features = FeatureSpec.from_dict(features, "features").to_dict()
    if algo not in _WEIGHTS_MODULE:
        raise ValueError(f"algo={algo!r} must be one of {sorted(_WEIGHTS_MODULE)}")
    cls_name = type(policy).__name__
    if (algo, cls_name) not in _POLICY_CLASSES:
        raise TypeError(f"{algo.upper()} policy class {cls_name} cannot be saved; supported: "
                        f"{sorted(c for a, c in _POLICY_CLASSES if a == algo)}")
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    module = policy if _WEIGHTS_MODULE[algo] == "policy" else policy.actor
    state = {k: v.detach().cpu().clone() for k, v in module.state_dict().items()}
    weights = path / WEIGHTS_FILE
    tmp = path / (WEIGHTS_FILE + ".tmp")
    _safetensors().save_file(state, str(tmp), metadata={"format": FORMAT, "algo": algo})
    tmp.replace(weights)
    norm = None
    if obs_rms is not None:
        norm = {"mean": _float_list(obs_rms.mean), "var": _float_list(obs_rms.var),
                "count": float(obs_rms.count), "clip_obs": float(clip_obs),
                "epsilon": float(epsilon)}
    meta = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "algo": algo,
        "policy_class": cls_name,
        "policy_kwargs": _settings_to_json(policy._get_constructor_parameters()),
        "observation_space": _space_to_json(policy.observation_space),
        "action_space": _space_to_json(policy.action_space),
        "obs_normalization": norm,
        "weights": {"file": WEIGHTS_FILE, "module": _WEIGHTS_MODULE[algo],
                    "sha256": sha256_file(weights)},
        "env": {"id": env_id, "kwargs": to_jsonable(env_kwargs or {})},
        "training": to_jsonable(training or {}),
        "hybrid": hybrid,
        "features": features,
        "versions": _versions(),
    }
    text = json.dumps(meta, indent=1, allow_nan=False)
    tmp = path / (AGENT_FILE + ".tmp")
    tmp.write_text(text)
    tmp.replace(path / AGENT_FILE)
    # safetensors writes its file owner-only; give it the permissions of agent.json
    weights.chmod((path / AGENT_FILE).stat().st_mode & 0o777)
    return path


def _versions() -> dict:
    import stable_baselines3
    import torch

    import tether_gym

    return {"tether_gym": tether_gym.__version__,
            "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__.split("+")[0], "numpy": np.__version__}


# ---------------------------------------------------------------------- load
def is_unit(path) -> bool:
    """Whether ``path`` is a folder holding a safe agent (``agent.json``)."""
    return (Path(path) / AGENT_FILE).is_file()


_REQUIRED = ("format", "format_version", "algo", "policy_class", "policy_kwargs",
             "observation_space", "action_space", "obs_normalization", "weights", "env")


def load_agent(path):
    """Rebuild the policy of a safe agent folder; no code from the files is run.

    Returns
    -------
    policy : stable_baselines3 BasePolicy
        In evaluation mode, on the CPU.
    meta : dict
        The contents of ``agent.json``.

    Raises
    ------
    AgentLoadError
        If ``agent.json`` or the weights file is missing, malformed, modified
        (SHA-256 mismatch) or does not fit the recorded policy; the message names
        the file and the missing piece.
    """
    import importlib

    path = Path(path)
    meta_path = path / AGENT_FILE
    if not meta_path.is_file():
        raise AgentLoadError(f"{path} is not an agent folder: {AGENT_FILE} is missing")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise AgentLoadError(f"{meta_path} is not valid JSON: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise AgentLoadError(f"{meta_path} is not a {FORMAT} file (format "
                             f"{meta.get('format') if isinstance(meta, dict) else None!r})")
    missing = [k for k in _REQUIRED if k not in meta]
    if missing:
        raise AgentLoadError(f"{meta_path} is incomplete: missing {missing} "
                             "(obs_normalization must be present, null when not normalised)")
    if meta["format_version"] != FORMAT_VERSION:
        raise AgentLoadError(f"{meta_path} has format_version {meta['format_version']!r}; this "
                             f"tether_gym reads version {FORMAT_VERSION}")
    algo = meta["algo"]
    key = (algo, meta["policy_class"])
    if key not in _POLICY_CLASSES:
        raise AgentLoadError(f"{meta_path}: unsupported algo/policy_class {key}; supported: "
                             f"{sorted(_POLICY_CLASSES)}")
    weights_info = meta["weights"]
    if not isinstance(weights_info, dict) or set(weights_info) < {"file", "module", "sha256"}:
        raise AgentLoadError(f"{meta_path}: 'weights' must give file, module and sha256")
    if weights_info["module"] != _WEIGHTS_MODULE[algo]:
        raise AgentLoadError(f"{meta_path}: weights module {weights_info['module']!r} does not "
                             f"fit {algo.upper()} (expected {_WEIGHTS_MODULE[algo]!r})")
    weights = path / Path(str(weights_info["file"])).name
    if not weights.is_file():
        raise AgentLoadError(f"agent {path} is incomplete: weights file {weights.name} is missing")
    if sha256_file(weights) != weights_info["sha256"]:
        raise AgentLoadError(f"{weights} does not match the SHA-256 recorded in {meta_path} "
                             "(truncated or modified)")
    obs_space = _space_from_json(meta["observation_space"], f"{meta_path}: observation_space")
    act_space = _space_from_json(meta["action_space"], f"{meta_path}: action_space")
    kwargs = _settings_from_json(meta["policy_kwargs"])
    module_name, cls_name = _POLICY_CLASSES[key]
    policy_cls = getattr(importlib.import_module(module_name), cls_name)
    try:
        policy = policy_cls(obs_space, act_space, lambda _: 0.0, **kwargs)
    except TypeError as exc:
        raise AgentLoadError(f"{meta_path}: policy_kwargs do not fit {cls_name}: {exc}") from None
    try:
        state = _safetensors().load_file(str(weights), device="cpu")
    except Exception as exc:  # noqa: BLE001 - SafetensorError, OSError, ...
        raise AgentLoadError(f"cannot read weights {weights}: {exc}") from None
    target = policy if weights_info["module"] == "policy" else policy.actor
    try:
        target.load_state_dict(state, strict=True)
    except (RuntimeError, TypeError, AttributeError) as exc:
        raise AgentLoadError(f"weights {weights} do not fit the policy in {meta_path}: "
                             f"{exc}") from None
    policy.set_training_mode(False)
    meta["hybrid"] = _recorded_spec(ResidualSpec, meta.get("hybrid"), f"{meta_path}: hybrid")
    meta["features"] = _recorded_spec(FeatureSpec, meta.get("features"),
                                      f"{meta_path}: features")
    norm = meta["obs_normalization"]
    if norm is not None:
        need = ("mean", "var", "clip_obs", "epsilon")
        if not isinstance(norm, dict) or any(k not in norm for k in need):
            raise AgentLoadError(f"{meta_path}: obs_normalization must give {list(need)} or be "
                                 "null")
        shape = obs_space.shape
        meta["obs_normalization"] = {
            **norm,
            "mean": _float_array(norm["mean"], shape, np.float64, f"{meta_path}: mean"),
            "var": _float_array(norm["var"], shape, np.float64, f"{meta_path}: var"),
        }
    return policy, meta


# ---------------------------------------------------------------------- pickled (opt-in)
PICKLE_WARNING = ("loading pickled agent files ({files}): a pickle can run any code when "
                  "it is loaded; do this only for files you made yourself or trust")


def _refuse(files) -> AgentLoadError:
    return AgentLoadError(
        f"refusing pickled agent files {[str(f) for f in files]}: loading them can run code "
        "from the file. Convert a run folder you trust once with `python -m "
        "tether_gym_agents.files.agent_files convert RUN_DIR --allow-pickle`, or load it with "
        "allow_pickle=True (evaluate.py --allow-pickle)")


def load_pickled_run(path, allow_pickle: bool = False, algo: str | None = None):
    """Load a stable-baselines3 run folder (``*.zip`` + ``vecnormalize.pkl``): opt-in only.

    The folder must be a complete unit: a model file, ``config.yml`` recording the
    algorithm and whether observations were normalised, and ``vecnormalize.pkl`` when
    they were. A lone ``.zip`` needs its run folder around it.

    Returns
    -------
    model, obs_rms, clip_obs, epsilon, meta

    Raises
    ------
    AgentLoadError
        Without ``allow_pickle=True`` (the message says how to convert), or when a
        piece is missing (named).
    """
    import zipfile

    import yaml

    path = Path(path)
    if path.is_dir():
        run_dir = path
        found = [run_dir / f for f in PICKLED_MODEL_FILES if (run_dir / f).is_file()]
        if not found:
            raise AgentLoadError(f"no agent in {path}: neither {AGENT_FILE} nor a model file "
                                 f"({', '.join(PICKLED_MODEL_FILES)})")
        model_path = found[0]
    elif path.is_file():
        run_dir, model_path = path.parent, path
    else:
        raise AgentLoadError(f"agent path {str(path)!r} does not exist")
    stats = run_dir / "vecnormalize.pkl"
    if not allow_pickle:
        raise _refuse([model_path] + ([stats] if stats.is_file() else []))
    cfg_path = run_dir / "config.yml"
    if not cfg_path.is_file():
        raise AgentLoadError(f"agent {model_path} is incomplete: {cfg_path.name} (algorithm, "
                             "normalisation) is missing beside it")
    try:
        cfg = yaml.safe_load(cfg_path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise AgentLoadError(f"{cfg_path} is not valid YAML: {exc}") from None
    algo = (algo or cfg.get("algo") or "").lower()
    if algo not in _WEIGHTS_MODULE:
        raise AgentLoadError(f"{cfg_path} does not record the algorithm ('algo: ppo|sac'), "
                             f"got {cfg.get('algo')!r}")
    normalize = (cfg.get("hyperparams") or {}).get("normalize", None)
    if normalize is None:
        raise AgentLoadError(f"{cfg_path} does not record hyperparams.normalize: cannot tell "
                             "whether observations must be normalised")
    warnings.warn(PICKLE_WARNING.format(files=[str(model_path)]), stacklevel=2)
    from stable_baselines3 import PPO, SAC

    cls: Any = {"ppo": PPO, "sac": SAC}[algo]
    try:
        model = cls.load(model_path, device="cpu")
    except (zipfile.BadZipFile, KeyError, ValueError, EOFError, RuntimeError) as exc:
        raise AgentLoadError(f"cannot load {algo.upper()} model {model_path}: {exc}") from exc
    obs_rms, clip_obs, epsilon = None, 10.0, 1e-8
    norm_obs = normalize is not False and (not isinstance(normalize, dict)
                                           or normalize.get("norm_obs", True))
    if norm_obs:
        if not stats.is_file():
            raise AgentLoadError(f"agent {model_path} is incomplete: its observation "
                                 f"statistics {stats.name} are missing ({cfg_path.name} says "
                                 "observations were normalised)")
        import pickle

        try:
            with open(stats, "rb") as fh:
                vecnorm = pickle.load(fh)
        except Exception as exc:  # noqa: BLE001 - any unpickling failure is a corrupt file
            raise AgentLoadError(f"corrupt normalisation statistics {stats}: {exc}") from exc
        if not hasattr(vecnorm, "obs_rms"):
            raise AgentLoadError(f"{stats} does not hold VecNormalize statistics")
        obs_rms, clip_obs, epsilon = vecnorm.obs_rms, vecnorm.clip_obs, vecnorm.epsilon
    return model, obs_rms, clip_obs, epsilon, {"algo": algo, "run_dir": run_dir,
                                               "model_path": model_path, "config": cfg}


def run_hybrid(config: dict) -> dict | None:
    """The hybrid of a run from its ``config.yml`` (its ``residual`` hyperparameter).

    Raises
    ------
    AgentLoadError
        If the recorded ``residual`` is not a valid ResidualSpec.
    """
    return _recorded_spec(ResidualSpec, (config.get("hyperparams") or {}).get("residual"),
                          "config.yml: hyperparams.residual")


def run_features(config: dict) -> dict | None:
    """The input features of a run from its ``config.yml`` (its ``features`` hyperparameter).

    Raises
    ------
    AgentLoadError
        If the recorded ``features`` is not a valid FeatureSpec.
    """
    return _recorded_spec(FeatureSpec, (config.get("hyperparams") or {}).get("features"),
                          "config.yml: hyperparams.features")


def _recorded_spec(cls, value, what: str) -> dict | None:
    """``cls.from_dict(value).to_dict()``, None for None; a bad value is an AgentLoadError."""
    if value is None:
        return None
    try:
        return cls.from_dict(value, what).to_dict()
    except ValueError as exc:
        raise AgentLoadError(str(exc)) from None


def convert_run(path, out=None, allow_pickle: bool = False) -> Path:
    """Convert a stable-baselines3 run folder (pickles) to a safe agent folder.

    Parameters
    ----------
    path : path-like
        Run folder or model ``.zip`` inside one.
    out : path-like or None
        Agent folder to write (default: the run folder itself for ``best_model.zip``,
        as ``train.py`` writes it, else ``<run folder>/final_agent``).
    allow_pickle : bool
        Must be True: the conversion unpickles the files once.
    """
    import json as _json

    model, obs_rms, clip_obs, epsilon, info = load_pickled_run(path, allow_pickle=allow_pickle)
    cfg = info["config"]
    run_dir = info["run_dir"]
    if out is None:
        out = run_dir if info["model_path"].name == "best_model.zip" else run_dir / "final_agent"
    out = Path(out)
    train_info = {}
    if (run_dir / "train_info.json").is_file():
        train_info = _json.loads((run_dir / "train_info.json").read_text())
    training = {"seed": cfg.get("seed", train_info.get("seed")),
                "num_timesteps": int(model.num_timesteps),
                "source": info["model_path"].name,
                "command": train_info.get("command")}
    return save_agent(out, model.policy, info["algo"], obs_rms, clip_obs, epsilon,
                      env_id=cfg.get("env_id"), env_kwargs=cfg.get("env_kwargs"),
                      training=training, hybrid=run_hybrid(cfg), features=run_features(cfg))


_SEED_DIR = re.compile(r"seed_(\d+)\Z")


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


EXPORTED_FILES = (AGENT_FILE, WEIGHTS_FILE, "config.yml", "args.yml", "command.txt",
                  "train_info.json", "learning_curve.png", "eval/evaluations.npz")
"""What :func:`export_runs` copies of a run folder: the safe agent, how it was trained
and its learning curve (no pickles, checkpoints, TensorBoard files or logs)."""
EXPORTED_FOLDER_FILES = ("learning_curves.png", "fanout.log")
"""What it copies of a folder of seed runs besides the runs."""


def export_runs(src, dest) -> list[Path]:
    """Copy the shareable files of a run folder, or of every ``seed_K`` run in a folder.

    Only :data:`EXPORTED_FILES` (and the folder's :data:`EXPORTED_FOLDER_FILES`) are
    copied; every run must hold a safe agent (``agent.json`` + ``policy.safetensors``).
    Returns the run folders written. Raises AgentLoadError naming a run without one.
    """
    import shutil

    src, dest = Path(src), Path(dest)
    runs = seed_runs(src)
    pairs = [(run, dest / run.name) for run in runs] if runs else [(src, dest)]
    for run, _ in pairs:
        if not is_unit(run):
            raise AgentLoadError(f"{run} holds no safe agent ({AGENT_FILE} + {WEIGHTS_FILE}); "
                                 "convert it first")
    for run, out in pairs:
        for name in EXPORTED_FILES:
            if (run / name).is_file():
                (out / name).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(run / name, out / name)
    if runs:
        for name in EXPORTED_FOLDER_FILES:
            if (src / name).is_file():
                shutil.copy2(src / name, dest / name)
    return [out for _, out in pairs]


def main(argv=None) -> int:
    """``python -m tether_gym_agents.files.agent_files {convert,export} ...`` (see ``--help``)."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m tether_gym_agents.files.agent_files",
                                     description="Convert a stable-baselines3 run folder "
                                                 "(pickles) to a safe agent folder.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    conv = sub.add_parser("convert", help="write agent.json + policy.safetensors from a run folder")
    conv.add_argument("run", type=Path, help="run folder or model .zip")
    conv.add_argument("--out", type=Path, default=None,
                      help="agent folder (default: RUN itself for best_model.zip, else "
                           "RUN/final_agent)")
    conv.add_argument("--allow-pickle", action="store_true",
                      help="required: the conversion unpickles the run's files once")
    exp = sub.add_parser("export", help="copy the safe files of a run, or of every seed_K "
                                        "run of a folder, to share or ship them")
    exp.add_argument("src", type=Path, help="run folder or folder of seed_K run folders")
    exp.add_argument("dest", type=Path, help="destination folder")
    args = parser.parse_args(argv)
    try:
        if args.cmd == "export":
            written = export_runs(args.src, args.dest)
            print(f"exported {len(written)} run(s) to {args.dest}")
            return 0
        out = convert_run(args.run, args.out, allow_pickle=args.allow_pickle)
    except AgentLoadError as exc:
        print(f"agent_files: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out / AGENT_FILE} and {out / WEIGHTS_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
