"""Agent files that hold only tensors and plain data: loading one never runs code.

An agent is one folder (a *unit*) with two files:

``agent.json``
    Plain JSON: the format version, the algorithm (a name of
    :data:`tether_gym_agents.common.algorithms.ALGORITHMS`: ``"ppo"``, ``"sac"``, ``"tqc"``,
    ``"td3"``), the stable-baselines3 policy class and its constructor settings (``net_arch``,
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
modified piece is an error that names it. stable-baselines3's pickled files are read
only by :mod:`tether_gym_agents.files.pickled`, on explicit opt-in.

Files are read only if they are regular files inside the agent folder (a symlink whose
resolved target stays inside the folder is read; one that leads out, or a device or FIFO,
is an error naming the file: :mod:`.folder_paths`).

Before anything is allocated, the values of ``agent.json`` and the weights' dtypes and
values are checked; each value out of bounds is an :class:`AgentLoadError` naming the
file, the key, the value and what is allowed. The bounds are listed in one place, the
docstring of :mod:`.agent_values` (normalisation statistics, spaces and their Box
bounds, network sizes, ``log_std_init``, weights float32/float64 and finite).
"""

from __future__ import annotations

import importlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..common.algorithms import ALGORITHMS, ALGOS, Algorithm, algorithm
from ..common.atomic_write import atomic_target, write_text_atomic
from ..common.features import FeatureSpec
from ..common.jsonio import sha256_file, to_jsonable
from ..hybrids.residual_spec import ResidualSpec
from .agent_values import ValueProblem, check_values, check_weights
from .folder_paths import FolderFileError, file_inside
from .policy_json import (
    PolicyJsonError,
    float_array,
    float_list,
    settings_from_json,
    settings_to_json,
    space_from_json,
    space_to_json,
)

__all__ = ["AgentLoadError", "ObsNormalization", "AGENT_FILE", "WEIGHTS_FILE", "FORMAT",
           "FORMAT_VERSION", "ALGOS", "SB3_CONTRIB_PIP", "save_agent", "load_agent", "is_unit",
           "recorded_spec", "normalization_of", "checked_file"]

AGENT_FILE = "agent.json"
WEIGHTS_FILE = "policy.safetensors"
FORMAT = "tether_gym-agent"
FORMAT_VERSION = 1

SB3_CONTRIB_PIP = ALGORITHMS["tqc"].install()
"""How to install sb3-contrib, whose TQC is an optional extra."""
# Policy classes are looked up by the name the algorithm's row of the table gives
# (tether_gym_agents.common.algorithms), never imported from a file.
_REQUIRED = ("format", "format_version", "algo", "policy_class", "policy_kwargs",
             "observation_space", "action_space", "obs_normalization", "weights", "env")


class AgentLoadError(ValueError):
    """An agent folder or file is missing, incomplete, corrupt or in a refused format."""


def checked_file(root, path) -> Path:
    """``path`` if it is a regular file inside ``root`` (:func:`.folder_paths.file_inside`).

    Raises
    ------
    AgentLoadError
        Naming the file, when it leads outside ``root`` or is not a regular file.
    """
    try:
        return file_inside(root, path)
    except FolderFileError as exc:
        raise AgentLoadError(str(exc)) from None


@dataclass(frozen=True)
class ObsNormalization:
    """The observation statistics of ``VecNormalize``, as an agent acts with them.

    Attributes
    ----------
    mean, var : numpy.ndarray
        Running mean and variance of the raw observations (float64).
    count : float
        Number of observations the statistics were made of [-].
    clip_obs : float
        Normalised observations are clipped to [-clip_obs, clip_obs] [-].
    epsilon : float
        Added to the variance before its square root [-].
    """

    mean: np.ndarray
    var: np.ndarray
    count: float = 0.0
    clip_obs: float = 10.0
    epsilon: float = 1e-8

    @classmethod
    def of_stats(cls, rms, clip_obs: float = 10.0, epsilon: float = 1e-8) -> ObsNormalization:
        """From a ``RunningMeanStd`` (``VecNormalize.obs_rms``) and VecNormalize's settings."""
        return cls(rms.mean, rms.var, float(rms.count), clip_obs, epsilon)

    @classmethod
    def of_vec_normalize(cls, venv) -> ObsNormalization | None:
        """The statistics of a ``VecNormalize`` env; None for any other env or norm_obs off."""
        from stable_baselines3.common.vec_env import VecNormalize

        if not isinstance(venv, VecNormalize) or not venv.norm_obs:
            return None
        return cls.of_stats(venv.obs_rms, venv.clip_obs, venv.epsilon)

    def apply(self, obs: np.ndarray) -> np.ndarray:
        """Observations as the policy saw them in training (VecNormalize's formula)."""
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon),
                       -self.clip_obs, self.clip_obs).astype(np.float32)

    def to_json(self) -> dict:
        """The ``obs_normalization`` entry of ``agent.json``."""
        return {"mean": float_list(self.mean), "var": float_list(self.var),
                "count": float(self.count), "clip_obs": float(self.clip_obs),
                "epsilon": float(self.epsilon)}


def _safetensors():
    try:
        import safetensors.torch
    except ImportError:
        raise ImportError("agent files need safetensors: pip install safetensors (or "
                          "pip install -e \".[train]\")") from None
    return safetensors.torch


# ---------------------------------------------------------------------- save
def save_agent(path, policy, algo: str, norm: ObsNormalization | None = None,
               env_id: str | None = None, env_kwargs: dict | None = None,
               training: dict | None = None, hybrid: dict | None = None,
               features: dict | None = None) -> Path:
    """Write a policy and its observation normalisation as a safe agent folder.

    Parameters
    ----------
    path : path-like
        The agent folder (created; ``agent.json`` and ``policy.safetensors`` are replaced).
    policy : stable_baselines3 policy
        ``model.policy`` of a model of one of the algorithms of
        :data:`~tether_gym_agents.common.algorithms.ALGORITHMS`.
    algo : str
        The algorithm that trained it (a name of that table: ``"ppo"``, ``"sac"``,
        ``"tqc"``, ``"td3"``; recorded, so loading never guesses).
    norm : ObsNormalization or None
        Observation statistics of ``VecNormalize`` (None: observations are not
        normalised).
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
    row = algorithm(algo)
    algo = row.name
    if hybrid is not None:
        hybrid = ResidualSpec.from_dict(hybrid, "hybrid").to_dict()
    if features is not None:
        features = FeatureSpec.from_dict(features, "features").to_dict()
    cls_name = type(policy).__name__
    if cls_name != row.policy:
        raise TypeError(f"{algo.upper()} policy class {cls_name} cannot be saved; supported: "
                        f"{[row.policy]}")
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    weights = _write_weights(path, policy, row)
    meta = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "algo": algo,
        "policy_class": cls_name,
        "policy_kwargs": settings_to_json(policy._get_constructor_parameters()),
        "observation_space": space_to_json(policy.observation_space),
        "action_space": space_to_json(policy.action_space),
        "obs_normalization": norm.to_json() if norm is not None else None,
        "weights": {"file": WEIGHTS_FILE, "module": row.weights,
                    "sha256": sha256_file(weights)},
        "env": {"id": env_id, "kwargs": to_jsonable(env_kwargs or {})},
        "training": to_jsonable(training or {}),
        "hybrid": hybrid,
        "features": features,
        "versions": _versions(),
    }
    text = json.dumps(meta, indent=1, allow_nan=False)
    write_text_atomic(path / AGENT_FILE, text)
    # safetensors writes its file owner-only; give it the permissions of agent.json
    weights.chmod((path / AGENT_FILE).stat().st_mode & 0o777)
    return path


def _write_weights(path: Path, policy, row: Algorithm) -> Path:
    """Write the acting module's ``state_dict`` as safetensors (atomically); its path."""
    module = policy if row.weights == "policy" else getattr(policy, row.weights)
    state = {k: v.detach().cpu().clone() for k, v in module.state_dict().items()}
    weights = path / WEIGHTS_FILE
    with atomic_target(weights) as tmp:
        _safetensors().save_file(state, str(tmp), metadata={"format": FORMAT,
                                                            "algo": row.name})
    return weights


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


def recorded_spec(cls, value, what: str) -> dict | None:
    """``cls.from_dict(value).to_dict()``, None for None; a bad value is an AgentLoadError."""
    if value is None:
        return None
    try:
        return cls.from_dict(value, what).to_dict()
    except ValueError as exc:
        raise AgentLoadError(str(exc)) from None


def load_agent(path):
    """Rebuild the policy of a safe agent folder; no code from the files is run.

    Returns
    -------
    policy : stable_baselines3 BasePolicy
        In evaluation mode, on the CPU.
    meta : dict
        The contents of ``agent.json`` (``obs_normalization`` with arrays, ``hybrid``
        and ``features`` checked).

    Raises
    ------
    AgentLoadError
        If ``agent.json`` or the weights file is missing, malformed, modified
        (SHA-256 mismatch) or does not fit the recorded policy; the message names
        the file and the missing piece.
    """
    path = Path(path)
    meta_path = path / AGENT_FILE
    meta = _read_meta(path)
    try:
        check_values(meta, meta_path)
    except ValueProblem as exc:
        raise AgentLoadError(str(exc)) from None
    weights = _checked_weights(path, meta)
    try:
        obs_space = space_from_json(meta["observation_space"],
                                    f"{meta_path}: observation_space")
        act_space = space_from_json(meta["action_space"], f"{meta_path}: action_space")
    except PolicyJsonError as exc:
        raise AgentLoadError(str(exc)) from None
    norm = _norm_arrays(meta["obs_normalization"], obs_space.shape, meta_path)
    try:
        kwargs = settings_from_json(meta["policy_kwargs"])
    except PolicyJsonError as exc:  # its messages name the key, not the file
        raise AgentLoadError(f"{meta_path}: {exc}") from None
    row = ALGORITHMS[meta["algo"]]
    cls_name = row.policy
    try:
        policy_cls = getattr(importlib.import_module(row.policy_module), cls_name)
    except ImportError:
        raise AgentLoadError(f"{meta_path}: a {row.name.upper()} agent needs {row.package}: "
                             f"{row.install()}") from None
    try:
        policy = policy_cls(obs_space, act_space, lambda _: 0.0, **kwargs)
    except TypeError as exc:
        raise AgentLoadError(f"{meta_path}: policy_kwargs do not fit {cls_name}: {exc}") from None
    try:
        state = _safetensors().load_file(str(weights), device="cpu")
    except Exception as exc:  # noqa: BLE001 - SafetensorError, OSError, ...
        raise AgentLoadError(f"cannot read weights {weights}: {exc}") from None
    try:
        check_weights(state, weights)
    except ValueProblem as exc:
        raise AgentLoadError(str(exc)) from None
    target = policy if row.weights == "policy" else getattr(policy, row.weights)
    try:
        target.load_state_dict(state, strict=True)
    except (RuntimeError, TypeError, AttributeError) as exc:
        raise AgentLoadError(f"weights {weights} do not fit the policy in {meta_path}: "
                             f"{exc}") from None
    policy.set_training_mode(False)
    meta["hybrid"] = recorded_spec(ResidualSpec, meta.get("hybrid"), f"{meta_path}: hybrid")
    meta["features"] = recorded_spec(FeatureSpec, meta.get("features"),
                                     f"{meta_path}: features")
    meta["obs_normalization"] = norm
    return policy, meta


def _read_meta(path: Path) -> dict:
    """``agent.json`` of ``path``, checked for its format, version and entries."""
    meta_path = path / AGENT_FILE
    if meta_path.exists():
        checked_file(path, meta_path)
    if not meta_path.is_file():
        raise AgentLoadError(f"{path} is not an agent folder: {AGENT_FILE} is missing")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise AgentLoadError(f"{meta_path} is not valid JSON: {exc}") from None
    except RecursionError:  # e.g. 100k nested [: Python's decoder recurses per level
        raise AgentLoadError(f"{meta_path} is not valid agent JSON: nested too deeply"
                             ) from None
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
    try:
        row = algorithm(meta["algo"])
    except (TypeError, ValueError) as exc:
        raise AgentLoadError(f"{meta_path}: algo: {exc}") from None
    if meta["algo"] != row.name:
        raise AgentLoadError(f"{meta_path}: algo={meta['algo']!r}; allowed: {list(ALGOS)} "
                             "(lower case)")
    if meta["policy_class"] != row.policy:
        raise AgentLoadError(f"{meta_path}: policy_class={meta['policy_class']!r} does not fit "
                             f"algo {row.name!r}; allowed: {row.policy!r}")
    return meta


def _checked_weights(path: Path, meta: dict) -> Path:
    """The weights file that ``meta`` records, present and matching its SHA-256."""
    meta_path, algo = path / AGENT_FILE, meta["algo"]
    info, keys = meta["weights"], ("file", "module", "sha256")
    if not isinstance(info, dict) or set(info) != set(keys):
        got = sorted(info) if isinstance(info, dict) else info
        raise AgentLoadError(f"{meta_path}: weights={got!r}; allowed: a mapping of exactly "
                             f"{list(keys)}" + (f" (unknown: {sorted(set(info) - set(keys))}"
                                               f", missing: {sorted(set(keys) - set(info))})"
                                               if isinstance(info, dict) else ""))
    if info["module"] != ALGORITHMS[algo].weights:
        raise AgentLoadError(f"{meta_path}: weights module {info['module']!r} does not "
                             f"fit {algo.upper()} (expected {ALGORITHMS[algo].weights!r})")
    if not isinstance(info["file"], str) or Path(info["file"]).name != info["file"] \
            or info["file"] in ("", ".", ".."):
        raise AgentLoadError(f"{meta_path}: weights.file={info['file']!r}; allowed: the name "
                             f"of a file in the agent folder (e.g. {WEIGHTS_FILE!r}), no "
                             "folder part")
    weights = path / info["file"]
    if weights.exists():
        checked_file(path, weights)
    if not weights.is_file():
        raise AgentLoadError(f"agent {path} is incomplete: weights file {weights.name} is missing")
    if sha256_file(weights) != info["sha256"]:
        raise AgentLoadError(f"{weights} does not match the SHA-256 recorded in {meta_path} "
                             "(truncated or modified)")
    return weights


def _norm_arrays(norm, shape, meta_path: Path) -> dict | None:
    """The recorded ``obs_normalization`` with ``mean`` and ``var`` as float64 arrays."""
    if norm is None:
        return None
    need = ("mean", "var", "clip_obs", "epsilon")
    if not isinstance(norm, dict) or any(k not in norm for k in need):
        raise AgentLoadError(f"{meta_path}: obs_normalization must give {list(need)} or be "
                             "null")
    try:
        arrays = {key: float_array(norm[key], shape, np.float64,
                                   f"{meta_path}: obs_normalization.{key}")
                  for key in ("mean", "var")}
    except PolicyJsonError as exc:
        raise AgentLoadError(str(exc)) from None
    return {**norm, **arrays}


def normalization_of(meta: dict) -> ObsNormalization | None:
    """The :class:`ObsNormalization` of a loaded ``agent.json`` (see :func:`load_agent`)."""
    norm = meta["obs_normalization"]
    if norm is None:
        return None
    return ObsNormalization(norm["mean"], norm["var"], float(norm.get("count", 0.0)),
                            float(norm["clip_obs"]), float(norm["epsilon"]))
