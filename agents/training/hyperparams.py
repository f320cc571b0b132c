"""The values of the learning algorithms' hyperparameters, checked before any work is done.

:func:`check_hyperparams` checks every keyword argument of an algorithm of
:data:`~tether_gym_agents.common.algorithms.ALGORITHMS` (stable-baselines3's PPO, SAC and
TD3, sb3-contrib's TQC) that a config may set (the row's ``hyperparams``; ``policy`` and
``policy_kwargs``, the row's ``policy_kwargs``), and the sizes train.py's own keys set
(``n_envs``), so that a bad value is one line naming the file, the key, the value and
what is allowed, instead of a traceback from stable-baselines3 or torch, a huge
allocation, a hang or NaNs some updates later (``gamma: 2``). Values are checked as YAML
gives them (plain data): ``activation_fn`` is a name from
:data:`~tether_gym_agents.files.policy_json.ACTIVATIONS`, made a torch class by
:func:`activation_class` when the model is built.

Bounds that size the run (each refused above, before anything is allocated):

* ``n_envs`` <= :data:`MAX_N_ENVS`; a PPO rollout ``n_steps * n_envs`` and an
  off-policy ``buffer_size`` <= :data:`MAX_TRANSITIONS`; ``batch_size`` <= the rollout
  (PPO, with the config's ``n_envs``, default 1) or <= ``buffer_size``.
* ``learning_rate`` (or ``lin_<start>``) in (0, :data:`MAX_LEARNING_RATE`];
  ``n_epochs`` and ``gradient_steps`` <= :data:`MAX_UPDATES`; ``n_critics`` and
  ``n_quantiles`` in the row's ``bounds``.
* ``normalize``'s values: ``norm_obs``/``norm_reward`` true or false, ``clip_obs``/
  ``clip_reward`` finite and > 0, ``gamma`` in [0, 1], ``epsilon`` in (0, 1].
"""

from __future__ import annotations

import math
from typing import Any

from ..common.algorithms import Algorithm, algorithm
from ..files.agent_values import LOG_STD_MAX, LOG_STD_MIN, MAX_PARAMETERS, MAX_WIDTH
from ..files.agent_values import MAX_DEPTH as MAX_LAYERS
from ..files.policy_json import ACTIVATIONS

__all__ = ["MAX_LAYERS", "MAX_WIDTH", "MAX_PARAMETERS", "MAX_N_ENVS", "MAX_TRANSITIONS",
           "MAX_LEARNING_RATE", "MAX_UPDATES", "MAX_LOSS_WEIGHT", "MAX_NOISE", "POLICIES",
           "BUFFER_KWARGS",
           "check_hyperparams", "check_n_envs", "check_rollout", "activation_class",
           "activation_name"]

POLICIES = ("MlpPolicy",)
# The network limits are those an agent file may have (files.agent_values): a run can
# only train what evaluate.py loads (a [200000, 200000] network would need 160 GB).

MAX_N_ENVS = 1024
"""Most envs train.py steps at once on the CPU. The shipped CPU configs use 8 to 64; the
native vector env steps all of them in one process, so more envs give no more speed on
a machine of tens of cores, only larger arrays (1e9 envs asked for 74.5 GiB).
``train.py gpu`` has its own bound."""
MAX_TRANSITIONS = 10_000_000
"""Most transitions a replay buffer (``buffer_size``) or a PPO rollout (``n_steps *
n_envs``) holds: 10 x SB3's default buffer; with the 20-entry float32 observation (kept
twice, obs and next obs) about 1.8 GB. 1e12 asked for 72.8 TiB."""
MAX_LEARNING_RATE = 1.0
"""Largest learning rate (Adam's step is about the learning rate: above 1 every update
overshoots; 1e308 gave NaN actions mid-run)."""
MAX_UPDATES = 1000
"""Most ``n_epochs`` (PPO passes over each rollout; SB3's default 10) and
``gradient_steps`` (per rollout of an off-policy algorithm): 1e9 epochs never ends."""
MAX_LOSS_WEIGHT = 1000.0
"""Largest weight of a loss term (``vf_coef``, ``ent_coef``, the ``caps_*`` weights):
SB3's defaults are 0 to 1; 1e300 made the loss infinite and the actions NaN mid-run."""
MAX_NOISE = 10.0
"""Largest TD3 target noise (``target_policy_noise``, ``target_noise_clip``) and CAPS
perturbation ``caps_sigma``: the policy's actions lie in [-1, 1] and its observations are
normalised to a few units; 1e300 overflowed float32 mid-run."""
BUFFER_KWARGS = {"rollout_buffer_kwargs": (), "replay_buffer_kwargs":
                 ("handle_timeout_termination",)}
"""The keys a config may give the buffer: the algorithm sets every other argument of
SB3's RolloutBuffer and ReplayBuffer itself (a repeated or unknown key is a TypeError
inside stable-baselines3)."""

MAX_COST = 1.0e6
"""Largest ``failure_cost`` of PPOLagrangian [-] (1 / (1 - gamma) is 1000 at gamma = 0.999)."""

_UNIT = "a number in [0, 1]"


class _Bad(ValueError):
    """A value is not allowed; the message says what is."""


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _int_at_least(low: int, high: int | None = None):
    def check(value):
        if isinstance(value, bool) or not isinstance(value, int) or value < low \
                or (high is not None and value > high):
            raise _Bad(f"a whole number >= {low}" if high is None
                       else f"a whole number in [{low}, {high}]")
    return check


def _number(low: float, high: float = math.inf, low_open: bool = False):
    def check(value):
        ok = _is_number(value) and (value > low if low_open else value >= low) \
            and value <= high
        if not ok:
            bound = f"> {low:g}" if low_open else f">= {low:g}"
            raise _Bad(f"a finite number {bound}" + (f" and <= {high:g}" if high < math.inf
                                                     else ""))
    return check


def _unit(value):
    if not (_is_number(value) and 0.0 <= value <= 1.0):
        raise _Bad(_UNIT)


def _bool(value):
    if not isinstance(value, bool):
        raise _Bad("true or false")


def _none(value):
    if value is not None:
        raise _Bad("null (train.py sets no class or object here)")


def _optional(check):
    def optional(value):
        if value is not None:
            try:
                check(value)
            except _Bad as exc:
                raise _Bad(f"null or {exc}") from None
    return optional


def _schedule(high: float = math.inf):
    """A number in (0, high] or ``lin_<start>`` with a start in (0, high]."""
    def check(value):
        if isinstance(value, str):
            try:
                start = float(value[4:]) if value.startswith("lin_") else math.nan
            except ValueError:
                start = math.nan
            if 0.0 < start <= high:
                return
        elif _is_number(value) and 0 < value <= high:
            return
        bound = "> 0 and finite" if high == math.inf else f"in (0, {high:g}]"
        raise _Bad(f"a number or 'lin_<start>', {bound} ('lin_<start>' falls linearly from "
                   "start to 0 over the run)")
    return check


def _sde_sample_freq(value):
    if isinstance(value, bool) or not isinstance(value, int) or (value < 1 and value != -1):
        raise _Bad("-1 (only at the start of a rollout) or a whole number >= 1")


def _sac_ent_coef(value):
    if isinstance(value, str):
        if value == "auto":
            return
        if value.startswith("auto_"):
            try:
                start = float(value[5:])
            except ValueError:
                start = math.nan
            if 0 < start <= MAX_LOSS_WEIGHT:
                return
    elif _is_number(value) and 0 <= value <= MAX_LOSS_WEIGHT:
        return
    raise _Bad(f"a number in [0, {MAX_LOSS_WEIGHT:g}], 'auto' or 'auto_<initial value>' with "
               f"a value in (0, {MAX_LOSS_WEIGHT:g}]")


def _target_entropy(value):
    if value != "auto" and not _is_number(value):
        raise _Bad("'auto' or a finite number")


def _train_freq(value):
    if isinstance(value, (list, tuple)) and len(value) == 2 and value[1] in ("step", "episode"):
        value = value[0]
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise _Bad("a whole number >= 1 or [n >= 1, 'step' or 'episode']")


def _gradient_steps(value):
    if isinstance(value, bool) or not isinstance(value, int) \
            or not (1 <= value <= MAX_UPDATES or value == -1):
        raise _Bad(f"a whole number in [1, {MAX_UPDATES}], or -1 (as many as env steps "
                   "collected)")


def _buffer_kwargs(key: str):
    allowed = BUFFER_KWARGS[key]

    def check(value):
        if value is not None and not isinstance(value, dict):
            raise _Bad(f"null or a mapping of {list(allowed)}")
        unknown = sorted(set(value or {}) - set(allowed))
        if unknown:
            raise _Bad(f"null or a mapping of {list(allowed)}; {unknown} not allowed (the "
                       "algorithm sets the buffer's other arguments itself)")
        for item in (value or {}).values():
            _bool(item)
    return check


_CHECKS: dict[str, Any] = {
    # every algorithm
    "learning_rate": _schedule(MAX_LEARNING_RATE), "gamma": _unit, "use_sde": _bool,
    "sde_sample_freq": _sde_sample_freq, "stats_window_size": _int_at_least(1),
    "batch_size": _int_at_least(1),
    # on-policy (PPO)
    "n_epochs": _int_at_least(1, MAX_UPDATES), "gae_lambda": _unit,
    "clip_range": _schedule(), "clip_range_vf": _optional(_schedule()),
    "normalize_advantage": _bool, "vf_coef": _number(0.0, MAX_LOSS_WEIGHT),
    "max_grad_norm": _number(0.0, low_open=True),
    "target_kl": _optional(_number(0.0, low_open=True)), "rollout_buffer_class": _none,
    "rollout_buffer_kwargs": _buffer_kwargs("rollout_buffer_kwargs"),
    # off-policy (SAC, TQC, TD3)
    "buffer_size": _int_at_least(1, MAX_TRANSITIONS), "learning_starts": _int_at_least(0),
    "tau": _number(0.0, 1.0, low_open=True), "train_freq": _train_freq,
    "gradient_steps": _gradient_steps, "action_noise": _none, "replay_buffer_class": _none,
    "replay_buffer_kwargs": _buffer_kwargs("replay_buffer_kwargs"),
    "optimize_memory_usage": _bool, "target_update_interval": _int_at_least(1),
    "target_entropy": _target_entropy, "use_sde_at_warmup": _bool,
    "top_quantiles_to_drop_per_net": _int_at_least(0),
    "policy_delay": _int_at_least(1, MAX_UPDATES),
    "target_policy_noise": _number(0.0, MAX_NOISE),
    "target_noise_clip": _number(0.0, MAX_NOISE),
    # PPOLagrangian's constraint (training/lagrangian.py): a limit on the mean cost per
    # step (at most 3, the largest cost of a step), the multiplier's step and start
    "cost_limit": _number(0.0, 3.0), "lagrange_lr": _number(0.0, MAX_LOSS_WEIGHT),
    "lagrange_init": _number(0.0, MAX_LOSS_WEIGHT),
    "failure_cost": _number(0.0, MAX_COST),
    # CapsSAC's/CapsTQC's smoothness weights and perturbation scale (training/caps.py)
    "caps_temporal": _number(0.0, MAX_LOSS_WEIGHT),
    "caps_spatial": _number(0.0, MAX_LOSS_WEIGHT),
    "caps_magnitude": _number(0.0, MAX_LOSS_WEIGHT), "caps_sigma": _number(0.0, MAX_NOISE),
}
"""The check of each keyword an algorithm of the table may take (its row's
``hyperparams`` say which it takes; ``n_steps``, ``batch_size`` and ``ent_coef`` depend
on on/off-policy: :func:`_checks`)."""
_POLICY_KWARGS: dict[str, Any] = {
    "log_std_init": _number(LOG_STD_MIN, LOG_STD_MAX), "use_sde": _bool, "use_expln": _bool,
    "share_features_extractor": _bool, "normalize_images": _bool, "ortho_init": _bool,
    "full_std": _bool, "squash_output": _bool, "clip_mean": _number(0.0, low_open=True),
}
_NORMALIZE: dict[str, Any] = {
    "norm_obs": _bool, "norm_reward": _bool,
    "clip_obs": _number(0.0, low_open=True), "clip_reward": _number(0.0, low_open=True),
    "gamma": _unit, "epsilon": _number(0.0, 1.0, low_open=True),
}
"""The check of each key of a config's ``normalize`` mapping (VecNormalize's keyword
arguments; an unknown key is reported by the config reader)."""
"""The check of each ``policy_kwargs`` key (its row's ``policy_kwargs`` say which it takes;
``net_arch``, ``activation_fn``, ``optimizer_kwargs`` and the counts: :func:`_policy_checks`)."""
_OPTIMIZER = {"eps": _number(0.0, 1.0, low_open=True), "weight_decay": _number(0.0, 1.0),
              "amsgrad": _bool}


def _layers(value) -> None:
    ok = isinstance(value, list) and len(value) <= MAX_LAYERS and all(
        isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= MAX_WIDTH for w in value)
    if not ok or sum(a * b for a, b in zip(value[:-1], value[1:], strict=True)) \
            > MAX_PARAMETERS:
        raise _Bad(f"a list of at most {MAX_LAYERS} layer widths, whole numbers in "
                   f"[1, {MAX_WIDTH}], with at most {MAX_PARAMETERS} weights between them")


def _net_arch(row: Algorithm):
    nets = row.net_keys

    def check(value):
        if isinstance(value, dict) and value and set(value) <= set(nets):
            try:
                for net in value.values():
                    _layers(net)
                return
            except _Bad:
                pass
        elif isinstance(value, list):
            try:
                _layers(value)
                return
            except _Bad:
                pass
        raise _Bad(f"a list of at most {MAX_LAYERS} layer widths in [1, {MAX_WIDTH}] (e.g. "
                   f"[64, 64], at most {MAX_PARAMETERS} weights) or a mapping of "
                   f"{' and '.join(nets)} to such lists")
    return check


def _activation(value):
    if activation_name(value) is None:
        raise _Bad(f"one of {list(ACTIVATIONS)} (torch.nn's class name)")


def activation_name(value) -> str | None:
    """The torch.nn class name of an ``activation_fn`` value (``Tanh``, ``nn.Tanh``, a class)."""
    if isinstance(value, type) and value.__module__.split(".")[0] == "torch":
        value = value.__name__
    if not isinstance(value, str):
        return None
    name = value.removeprefix("torch.").removeprefix("nn.")
    return name if name in ACTIVATIONS else None


def activation_class(value):
    """The torch.nn class of an ``activation_fn`` value checked by :func:`check_hyperparams`."""
    import torch

    return getattr(torch.nn, activation_name(value) or str(value))


def _optimizer_kwargs(value):
    if not isinstance(value, dict):
        raise _Bad(f"a mapping of {sorted(_OPTIMIZER)} and betas")
    for key, item in value.items():
        if key == "betas":
            if not (isinstance(item, (list, tuple)) and len(item) == 2
                    and all(_is_number(b) and 0 <= b < 1 for b in item)):
                raise _Bad("betas: two numbers in [0, 1)")
        elif key in _OPTIMIZER:
            try:
                _OPTIMIZER[key](item)
            except _Bad as exc:
                raise _Bad(f"{key}: {exc}") from None
        else:
            raise _Bad(f"a mapping of {sorted(_OPTIMIZER) + ['betas']}; {key!r} is not one")


def _ent_coef_ppo(value):
    _number(0.0, MAX_LOSS_WEIGHT)(value)


def _checks(row: Algorithm) -> dict[str, Any]:
    """The check of each keyword ``row``'s model takes (but ``policy_kwargs``)."""
    out = {key: _CHECKS[key] for key in row.hyperparams if key in _CHECKS}
    if row.on_policy:
        out.update(n_steps=_int_at_least(1, MAX_TRANSITIONS),
                   batch_size=_int_at_least(2, MAX_TRANSITIONS), ent_coef=_ent_coef_ppo)
    else:  # n_steps: the n-step return of an off-policy algorithm
        out.update(n_steps=_int_at_least(1, MAX_UPDATES),
                   batch_size=_int_at_least(1, MAX_TRANSITIONS))
        if "ent_coef" in row.hyperparams:
            out["ent_coef"] = _sac_ent_coef
    return {key: check for key, check in out.items() if key in row.hyperparams}


def _policy_checks(row: Algorithm) -> dict[str, Any]:
    """The check of each ``policy_kwargs`` key ``row``'s policy takes."""
    out: dict[str, Any] = {"net_arch": _net_arch(row), "activation_fn": _activation,
                           "optimizer_kwargs": _optimizer_kwargs}
    out.update({key: _POLICY_KWARGS[key] for key in row.policy_kwargs if key in _POLICY_KWARGS})
    for key, default in row.defaults.items():  # n_critics, n_quantiles
        out[key] = _int_at_least(*row.bounds.get(key, (1, default)))
    return {key: check for key, check in out.items() if key in row.policy_kwargs}


def check_n_envs(value, where: str) -> None:
    """``n_envs`` (a config's or ``--n-envs``): a whole number in [1, :data:`MAX_N_ENVS`].

    Raises
    ------
    ValueError
        ``"<where>: <value> must be a whole number in [1, 1024] ..."``.
    """
    whole = (isinstance(value, (int, float)) and not isinstance(value, bool)
             and math.isfinite(value) and value == int(value))
    if not whole or not 1 <= value <= MAX_N_ENVS:
        raise ValueError(f"{where}: {value!r} must be a whole number in [1, {MAX_N_ENVS}] "
                         "(envs stepped at once on the CPU; train.py gpu takes more)")


def check_rollout(params: dict, algo: str, n_envs: int, source: str) -> None:
    """The sizes of one update, checked before anything is allocated.

    A PPO rollout ``n_steps * n_envs`` of at most :data:`MAX_TRANSITIONS` and at least
    ``batch_size``; an off-policy ``batch_size`` of at most ``buffer_size``. ``params`` as
    a run uses them (after ``fit_rollout``), with the run's ``n_envs``.

    Raises
    ------
    ValueError
        Naming ``source``, the keys, their values and the allowed range.
    """
    row = algorithm(algo)
    batch = params.get("batch_size", 64 if row.on_policy else 256)
    if not _whole(batch) or not _whole(n_envs):
        return  # reported by check_hyperparams
    if row.on_policy:
        n_steps = params.get("n_steps", 2048)
        if not _whole(n_steps):
            return
        rollout = n_steps * n_envs
        if rollout > MAX_TRANSITIONS:
            raise ValueError(f"{source}: n_steps x n_envs: {n_steps} x {n_envs} = {rollout} "
                             f"must be <= {MAX_TRANSITIONS} (env steps in one rollout)")
        if batch > rollout:
            raise ValueError(f"{source}: batch_size: {batch} must be <= n_steps x n_envs = "
                             f"{n_steps} x {n_envs} = {rollout} (the rollout it is drawn from)")
    else:
        size = params.get("buffer_size", 1_000_000)
        if _whole(size) and batch > size:
            raise ValueError(f"{source}: batch_size: {batch} must be <= buffer_size ({size}), "
                             "the replay buffer it is drawn from")


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _non_finite(value, where: str):
    """The first NaN or inf in plain data (``where`` its key path), or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return where, value
    items = value.items() if isinstance(value, dict) else (
        enumerate(value) if isinstance(value, list) else ())
    for key, item in items:
        found = _non_finite(item, f"{where}[{key}]" if isinstance(key, int) else
                            f"{where}.{key}")
        if found:
            return found
    return None


def check_hyperparams(params: dict, algo: str, source: str, policy=None) -> None:
    """Raise ValueError naming the first value of ``params`` the algorithm would reject.

    Parameters
    ----------
    params : dict
        The config's keys as read from YAML (the algorithm's keywords, ``policy_kwargs``
        included, and train.py's own keys, of which ``n_envs`` and the NaN/inf in
        ``env_kwargs`` and ``normalize`` are checked here; the others by the caller).
    algo : str
        A name of :data:`~tether_gym_agents.common.algorithms.ALGORITHMS`.
    source : str
        The file the values came from (the start of the message).
    policy : str or None
        The config's ``policy`` (None: not given, MlpPolicy).

    Raises
    ------
    ValueError
        ``"<source>: <key>: <value> must be <allowed>"``.
    """
    row = algorithm(algo)
    if policy is not None and policy not in POLICIES:
        raise ValueError(f"{source}: policy: {policy!r} must be one of {list(POLICIES)} (the "
                         "observation is a flat vector)")
    for key in ("env_kwargs", "normalize"):  # JSON would record NaN as null
        found = _non_finite(params.get(key), key)
        if found:
            raise ValueError(f"{source}: {found[0]}: {found[1]!r} must be finite")
    if isinstance(params.get("normalize"), dict):
        for key, value in params["normalize"].items():
            if key in _NORMALIZE:
                _run(_NORMALIZE[key], f"{source}: normalize.{key}", value)
    if "n_envs" in params:
        check_n_envs(params["n_envs"], f"{source}: n_envs")
    for key, check in _checks(row).items():
        if key in params:
            _run(check, f"{source}: {key}", params[key])
    kwargs = params.get("policy_kwargs")
    if kwargs is not None and not isinstance(kwargs, dict):
        raise ValueError(f"{source}: policy_kwargs: {kwargs!r} must be a mapping (no code is "
                         "evaluated)")
    checks = _policy_checks(row)
    for key, value in (kwargs or {}).items():
        if key not in checks:
            raise ValueError(f"{source}: policy_kwargs: unknown key {key!r} for "
                             f"{algo.upper()}; allowed: {sorted(checks)}")
        _run(checks[key], f"{source}: policy_kwargs.{key}", value)
    if "n_quantiles" in row.defaults and "top_quantiles_to_drop_per_net" in row.hyperparams:
        _keeps_quantiles(params, row, source)
    check_rollout(params, algo, int(params.get("n_envs", 1)), source)


def _keeps_quantiles(params: dict, row: Algorithm, source: str) -> None:
    """TQC's target keeps n_quantiles - top_quantiles_to_drop_per_net > 0 per critic."""
    kwargs = params.get("policy_kwargs") or {}
    n_quantiles = kwargs.get("n_quantiles", row.defaults["n_quantiles"])
    drop = params.get("top_quantiles_to_drop_per_net", 2)
    if isinstance(n_quantiles, int) and isinstance(drop, int) and drop >= n_quantiles:
        raise ValueError(f"{source}: top_quantiles_to_drop_per_net: {drop!r} must be < "
                         f"policy_kwargs.n_quantiles ({n_quantiles}): each critic keeps "
                         "at least one quantile for the target")


def _run(check, where: str, value) -> None:
    try:
        check(value)
    except _Bad as exc:
        raise ValueError(f"{where}: {value!r} must be {exc}") from None
