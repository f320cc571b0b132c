"""Hyperparameter files (``configs/<algo>.yml``) and env kwargs: read, checked, resolved.

A hyperparameter file is YAML keyed by env id with a ``default`` block (rl-baselines3-zoo's
layout); besides the algorithm's keyword arguments it holds ``train.py``'s own keys
(:data:`RUN_KEYS`). Every check raises :class:`ConfigError` with a message that names
the file, the key and the valid values.
"""

from __future__ import annotations

import difflib
import importlib
import math
from pathlib import Path

import gymnasium as gym

import tether_gym

from ..common.algorithms import ALGORITHMS, algorithm, split_name
from ..common.env_kwargs import parse_env_kwargs as _parse_env_kwargs
from ..common.features import FeatureSpec
from ..common.jsonio import to_jsonable
from ..common.obs import with_rate_mode
from ..common.yamlio import YamlFileError, load_yaml_file
from ..hybrids.residual_spec import ResidualSpec
from .hyperparams import activation_class, check_hyperparams

__all__ = ["ConfigError", "CONFIG_DIR", "RUN_KEYS", "NORMALIZE_KEYS", "SCHEDULE_KEYS",
           "load_hyperparams", "with_schedules", "residual_spec", "feature_spec",
           "parse_env_kwargs", "resolve_env_kwargs", "rate_mode_for", "check_env",
           "check_env_id", "algo_class", "check_algo_params", "check_counts", "fit_rollout",
           "NOISE_TYPES", "NOISE_STD_MAX", "action_noise", "MAX_TIMESTEPS",
           "config_algo", "training_distribution"]

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"


def config_algo(path: str | Path) -> str | None:
    """The algorithm a packaged config of :data:`CONFIG_DIR` is for, or None.

    The longest algorithm name the file's stem is or starts with followed by ``_``:
    ``ppo_fast.yml`` is PPO's (``--algo ppo --config ...``), ``ppo_lag.yml`` is
    ``ppo_lag``'s, ``gpu_ppo.yml`` none (``train.py gpu``'s own format).
    """
    stem = Path(path).stem
    names = [name for name in ALGORITHMS if stem == name or stem.startswith(name + "_")]
    return max(names, key=len) if names else None


def training_distribution() -> dict:
    """``agents/configs/ppo.yml``'s env arguments: the learners' training distribution.

    The shipped PPO agents' (random masses, eccentricity and initial libration,
    disturbance, observation noise); the Minari datasets and DAgger record and label
    episodes on it.
    """
    return dict(load_hyperparams(CONFIG_DIR / "ppo.yml", "ppo", tether_gym.ENV_ID)
                .get("env_kwargs") or {})


RUN_KEYS = ("policy", "n_envs", "n_timesteps", "normalize", "env_kwargs", "eval_freq",
            "checkpoint_freq", "residual", "features", "noise_type", "noise_std",
            "init_policy", "bc_term")
NOISE_TYPES = ("normal", "ornstein-uhlenbeck")
"""``noise_type`` values (rl-baselines3-zoo's names): Gaussian or Ornstein-Uhlenbeck noise
of standard deviation ``noise_std`` on every action entry, in the policy's action box
[-1, 1], for the algorithms whose row says ``action_noise`` (SAC, TQC, TD3)."""
NOISE_STD_MAX = 1.0
"""Largest ``noise_std``: the half width of the policy's action box [-]."""
MAX_TIMESTEPS = 10**12
"""Most env steps one run trains (the shipped runs train 3e6; 1e30 would never end)."""
NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")

# A fixed value the user types clears the config's random range of the same quantity.
RANGE_OF = {"eccentricity": ("eccentricity_range",), "masses": ("mass_range",),
            "initial_theta": ("init_theta_range",), "initial_lengths": ("init_length_range",)}
# Per-tether lists: a config's list with equal entries applies to any number of bodies.
PER_TETHER = ("masses", "initial_lengths", "initial_theta")


class ConfigError(ValueError):
    """A hyperparameter file, command-line value or env kwarg is invalid."""


SCHEDULE_KEYS = ("learning_rate", "clip_range")
"""Hyperparameters that may be written ``lin_<start>`` (rl-baselines3-zoo's notation)."""


def _linear(start: float):
    """SB3 schedule falling linearly from ``start`` to 0 over the run (progress 1 -> 0)."""
    def schedule(progress_remaining: float) -> float:
        return progress_remaining * start

    return schedule


def _lin_start(value: str) -> float:
    """The start of a ``lin_<start>`` value; NaN when it is not one."""
    try:
        return float(value[4:]) if value.startswith("lin_") else math.nan
    except ValueError:
        return math.nan


def with_schedules(params: dict) -> dict:
    """``params`` as the algorithm takes them.

    Every ``lin_<start>`` value of :data:`SCHEDULE_KEYS` is made a schedule and
    ``policy_kwargs.activation_fn`` (a name) the torch class.
    """
    out = {k: (_linear(_lin_start(v)) if k in SCHEDULE_KEYS and isinstance(v, str) else v)
           for k, v in params.items()}
    kwargs = out.get("policy_kwargs")
    if isinstance(kwargs, dict) and "activation_fn" in kwargs:
        out["policy_kwargs"] = {**kwargs,
                                "activation_fn": activation_class(kwargs["activation_fn"])}
    return out


PPO_DEFAULTS = {"n_steps": 2048, "batch_size": 64}
"""stable-baselines3's PPO defaults of the rollout's size."""


def fit_rollout(params: dict, algo: str, n_envs: int, timesteps: int
                ) -> tuple[dict, str | None]:
    """``params`` whose PPO rollout fits in a budget of ``timesteps``, and a note saying so.

    PPO collects ``n_steps * n_envs`` env steps before each update and never stops
    inside a rollout: a budget below one rollout would train a whole rollout (2048
    steps for ``--timesteps 64`` with SB3's defaults). Such a run collects rollouts of
    ``n_steps = ceil(timesteps / n_envs)`` (at least 2 env steps) instead, with
    ``batch_size`` at most the rollout. An off-policy algorithm (``learning_starts`` at or
    above the budget: no gradient step) is only noted. Returns ``(params, None)`` when
    nothing changes.
    """
    if not algorithm(algo).on_policy:
        starts = params.get("learning_starts", 100)
        if isinstance(starts, int) and starts >= timesteps:
            return params, (f"--timesteps {timesteps} <= learning_starts {starts}: "
                            f"{algo.upper()} takes no "
                            "gradient step in this run (it only fills the replay buffer)")
        return params, None
    n_steps = params.get("n_steps", PPO_DEFAULTS["n_steps"])
    if n_steps * n_envs <= timesteps:
        return params, None
    fitted = max(math.ceil(timesteps / n_envs), 2 if n_envs == 1 else 1)
    batch = min(params.get("batch_size", PPO_DEFAULTS["batch_size"]), fitted * n_envs)
    note = (f"--timesteps {timesteps} is less than one PPO rollout (n_steps {n_steps} x "
            f"{n_envs} env(s) = {n_steps * n_envs} env steps): this run uses n_steps {fitted}"
            f" and batch_size {batch} ({fitted * n_envs} env steps per update)")
    return {**params, "n_steps": fitted, "batch_size": batch}, note


def check_algo_params(params: dict, algo: str, source: str) -> None:
    """Raise ConfigError for the first hyperparameter value the algorithm would reject.

    ``params`` are a config's keys as read (``policy`` included); every value is
    checked before any env or model is built (:mod:`.hyperparams`; the action noise
    here).
    """
    try:
        check_hyperparams(params, algo, source, params.get("policy"))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    _check_noise(params, algo, source)


def _check_noise(params: dict, algo: str, source: str) -> None:
    """``noise_type`` and ``noise_std``: both or neither, in range, for an off-policy row."""
    given = [k for k in ("noise_type", "noise_std") if k in params]
    if not given:
        return
    row = algorithm(algo)
    if not row.action_noise:
        raise ConfigError(f"{source}: {given[0]}: {algo.upper()} takes no action noise; "
                          "remove noise_type and noise_std")
    if len(given) == 1:
        missing = "noise_std" if given[0] == "noise_type" else "noise_type"
        raise ConfigError(f"{source}: {given[0]} needs {missing} (give both, or neither for "
                          "no action noise)")
    kind, std = params["noise_type"], params["noise_std"]
    if kind not in NOISE_TYPES:
        raise ConfigError(f"{source}: noise_type: {kind!r} must be one of {list(NOISE_TYPES)}")
    if isinstance(std, bool) or not isinstance(std, (int, float)) or not math.isfinite(std) \
            or not 0 <= std <= NOISE_STD_MAX:
        raise ConfigError(f"{source}: noise_std: {std!r} must be a number in [0, "
                          f"{NOISE_STD_MAX}] (in the policy's action box [-1, 1])")


def action_noise(run: dict, n_actions: int):
    """The SB3 ``ActionNoise`` of a run's checked ``noise_type``/``noise_std``; None if absent."""
    if "noise_type" not in run:
        return None
    import numpy as np
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    cls = NormalActionNoise if run["noise_type"] == "normal" else OrnsteinUhlenbeckActionNoise
    return cls(mean=np.zeros(n_actions), sigma=float(run["noise_std"]) * np.ones(n_actions))


def algo_class(algo: str):
    """The class that trains ``algo``: its row's ``model`` (:mod:`..common.algorithms`).

    stable-baselines3's PPO and TD3 for ``"ppo"`` and ``"td3"``; for ``"sac"``
    :class:`~tether_gym_agents.training.caps.CapsSAC`, which is SAC step for step unless
    a config sets its ``caps_*`` smoothness weights; for ``"tqc"`` likewise CapsTQC on
    sb3-contrib's TQC. A library that is not installed is a ConfigError with the pip
    command of the row's extra, before any work.
    """
    row = algorithm(algo)
    module, name = split_name(row.model)
    try:
        return getattr(importlib.import_module(module), name)
    except ImportError:
        raise ConfigError(f"--algo {row.name} needs {row.requirement}: {row.install()}"
                          ) from None


def load_hyperparams(path: Path, algo: str, env_id: str) -> dict:
    """Hyperparameters for ``env_id`` from a YAML file keyed by env id with a ``default`` block.

    The env id's block overrides ``default``. (rl-baselines3-zoo reads only the env
    id's block, so the shipped files keep that block complete and put only
    ``train.py``'s own keys, ``eval_freq`` and ``checkpoint_freq``, in ``default``.)

    Raises
    ------
    ConfigError
        On a missing file, a malformed document or an unknown key (the message lists
        the valid keys).
    """
    path = Path(path)
    try:
        doc = load_yaml_file(path, what="config file") or {}
    except YamlFileError as exc:
        raise ConfigError(str(exc)) from None
    if not isinstance(doc, dict) or not all(isinstance(v, (dict, type(None)))
                                            for v in doc.values()):
        raise ConfigError(f"{path} must map env ids (and 'default') to hyperparameters")
    if env_id not in doc and "default" not in doc:  # an empty file too: no silent defaults
        raise ConfigError(f"{path} has no block for {env_id} and no 'default' block (blocks: "
                          f"{sorted(map(str, doc))})")
    params = dict(doc.get("default") or {})
    params.update(doc.get(env_id) or {})
    algo_class(algo)  # a missing library is reported before the file is read further
    row = algorithm(algo)
    valid = set(RUN_KEYS) | set(row.hyperparams)
    if not row.action_noise:
        valid -= {"noise_type", "noise_std"}
    unknown = sorted(set(params) - valid)
    if unknown:
        raise ConfigError(f"unknown key(s) {unknown} in {path} for {algo.upper()}; valid keys: "
                          f"{sorted(valid)}")
    norm = params.get("normalize", False)
    if isinstance(norm, dict):
        bad = sorted(set(norm) - set(NORMALIZE_KEYS))
        if bad:
            raise ConfigError(f"{path}: unknown normalize key(s) {bad}; valid: "
                              f"{list(NORMALIZE_KEYS)}")
    elif not isinstance(norm, bool):
        raise ConfigError(f"{path}: normalize must be true, false or a dict, got {norm!r}")
    check_counts(params, str(path))
    if not isinstance(params.get("env_kwargs") or {}, dict):
        raise ConfigError(f"{path}: env_kwargs must be a mapping, got {params['env_kwargs']!r}")
    check_algo_params(params, algo, str(path))
    if "residual" in params:
        residual_spec(params["residual"], str(path))
    if "features" in params:
        feature_spec(params["features"], str(path))
    return params


def check_counts(params: dict, source: str) -> None:
    """``n_envs``, ``n_timesteps``, ``eval_freq``, ``checkpoint_freq``: whole numbers >= 1.

    A float that is whole (``1e5``) is accepted; NaN and inf are refused before any
    conversion to int.

    Raises
    ------
    ConfigError
        ``"<source>: <key>: <value> must be a whole number >= 1"``.
    """
    for key in ("n_envs", "n_timesteps", "eval_freq", "checkpoint_freq"):
        if key in params:
            value = params[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value < 1 or value != int(value):
                raise ConfigError(f"{source}: {key}: {value!r} must be a whole number >= 1")
    if params.get("n_timesteps", 1) > MAX_TIMESTEPS:
        raise ConfigError(f"{source}: n_timesteps: {params['n_timesteps']!r} must be a whole "
                          f"number in [1, {MAX_TIMESTEPS}]")


def residual_spec(value, source: str) -> ResidualSpec | None:
    """The validated ``residual`` key of a config (None: no hybrid).

    ``residual: {base: smc, scale: 0.2, filter: true}`` trains the residual of the
    hybrid u = filter(clip(u_smc + scale * a, -1, 1))
    (:mod:`tether_gym_agents.training.residual_env`).

    Raises
    ------
    ConfigError
        On an unknown key or value (the message names the valid ones).
    """
    return _config_spec(ResidualSpec, value, f"{source}: residual")


def feature_spec(value, source: str) -> FeatureSpec | None:
    """The validated ``features`` key of a config (None: the observation alone).

    ``features: {name: symlog_errors, scale: 0.001}`` makes the policy's network see
    symlog(e / S) and symlog(e' / S) beside the observation
    (:mod:`tether_gym_agents.common.features`).
    """
    return _config_spec(FeatureSpec, value, f"{source}: features")


def _config_spec(cls, value, what: str):
    """``cls.from_dict(value)``, None for None; a bad value is a ConfigError."""
    if value is None:
        return None
    try:
        return cls.from_dict(value, what)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def rate_mode_for(spec: ResidualSpec | None, env_kwargs: dict, source: str,
                   notes: list[str]) -> dict:
    """``env_kwargs`` with ``action_mode="rate"`` when a residual hybrid is trained."""
    if spec is None:
        return env_kwargs
    if "action_mode" not in env_kwargs:
        notes.append(f"{source}'s residual sets action_mode='rate' (the hybrid commands reel "
                     "rates)")
    try:
        return with_rate_mode(env_kwargs, f"{source}'s residual (the hybrid commands reel rates)")
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def parse_env_kwargs(items: list[str]) -> dict:
    """``--env-kwargs key=value ...`` as a dict (:mod:`tether_gym_agents.common.env_kwargs`).

    Raises
    ------
    ConfigError
        On a malformed entry or a value that is not a Python literal (no code is
        evaluated); the message names the flag and the entry.
    """
    try:
        return _parse_env_kwargs(items, flag="--env-kwargs")
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def resolve_env_kwargs(config_kwargs: dict, user_kwargs: dict, source: str,
                       default_n_bodies: int = 3) -> tuple[dict, list[str]]:
    """Env kwargs of a run: the user's values win over the config's.

    * A fixed value typed by the user clears the config's random range of the same
      quantity (``eccentricity`` clears ``eccentricity_range``, ``masses`` clears
      ``mass_range``, ``initial_theta`` clears ``init_theta_range``,
      ``initial_lengths`` clears ``init_length_range``), unless the user typed the
      range too.
    * A per-tether list of the config (``masses``, ``initial_lengths``,
      ``initial_theta``) whose entries are all equal applies to any ``n_bodies``; an
      unequal one of the wrong length is an error naming the config line.

    Returns
    -------
    kwargs : dict
        The resolved env kwargs (plain lists, no tuples).
    notes : list of str
        What was changed, to print.
    """
    config_kwargs = dict(config_kwargs or {})
    notes = []
    for key in user_kwargs:
        for range_key in RANGE_OF.get(key, ()):
            if range_key in config_kwargs and range_key not in user_kwargs:
                notes.append(f"--env-kwargs {key}={user_kwargs[key]!r} clears {source}'s "
                             f"{range_key}: {config_kwargs[range_key]!r}")
                del config_kwargs[range_key]
    kwargs = to_jsonable({**config_kwargs, **user_kwargs})
    n_bodies = kwargs.get("n_bodies", default_n_bodies)
    if isinstance(n_bodies, int) and not isinstance(n_bodies, bool) and n_bodies >= 2:
        n = n_bodies - 1
        for key in PER_TETHER:
            value = kwargs.get(key)
            if key in user_kwargs or not isinstance(value, list) or len(value) == n:
                continue
            if value and all(v == value[0] for v in value):
                kwargs[key] = [value[0]] * n
                notes.append(f"{source}'s {key}: {value!r} applied to n_bodies={n_bodies} as "
                             f"{kwargs[key]!r}")
            else:
                raise ConfigError(f"{source}: env_kwargs {key}: {value!r} has {len(value)} "
                                  f"entries, but n_bodies={n_bodies} needs {n}; give {key} in "
                                  "--env-kwargs or edit that line")
    return kwargs, notes


def check_env(env_id: str, kwargs: dict, items: list[str], source: str) -> None:
    """Build the env once with the resolved kwargs: bad values fail here, before training.

    ``render_mode`` is None or ``'rgb_array'`` (the training envs are stepped in one
    vector env, which opens no window).
    """
    typed = f"--env-kwargs {' '.join(items)}" if items else "no --env-kwargs"
    if kwargs.get("render_mode") not in (None, "rgb_array"):
        raise ConfigError(f"invalid env kwargs ({typed}; {source}): render_mode="
                          f"{kwargs['render_mode']!r} must be None or 'rgb_array' (training "
                          "steps its envs in one vector env, which opens no window)")
    try:
        env = gym.make(env_id, **kwargs)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"invalid env kwargs ({typed}; {source}): {exc}") from None
    except gym.error.Error as exc:  # e.g. a missing dependency of another package's env
        raise ConfigError(f"env {env_id!r} cannot be made: {exc}") from None
    spaces = env.observation_space, env.action_space
    env.close()
    if not all(isinstance(space, gym.spaces.Box) and len(space.shape) == 1
               for space in spaces):
        got = [f"{type(space).__name__} of shape {space.shape}" for space in spaces]
        raise ConfigError(f"env {env_id!r} observes a {got[0]} and acts with a {got[1]}; "
                          "train.py trains MLP policies on a 1-D Box observation and 1-D "
                          "Box (continuous) actions, as tether_gym's")


def check_env_id(env_id: str) -> None:
    """Raise ConfigError for an unregistered env id (with a "did you mean")."""
    ids = [i for i in gym.registry if i.startswith("tether_gym/")]
    if env_id not in gym.registry:
        close = difflib.get_close_matches(env_id, ids or list(gym.registry), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(f"unknown env id {env_id!r}{hint}; tether_gym ids: {ids}")
