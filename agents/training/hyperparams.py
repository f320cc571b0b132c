"""The values of PPO's, SAC's and TQC's hyperparameters, checked before any work is done.

:func:`check_hyperparams` checks every keyword argument of stable-baselines3's PPO and
SAC (and sb3-contrib's TQC) that a config may set (and ``policy`` and
``policy_kwargs``), so that a bad value is one line naming the key, the value and what
is allowed instead of a traceback from stable-baselines3 or torch, or NaNs some updates
later (``gamma: 2``). Values are checked as YAML gives them (plain data):
``activation_fn`` is a name from :data:`~tether_gym_agents.files.policy_json.ACTIVATIONS`,
made a torch class by :func:`activation_class` when the model is built.
"""

from __future__ import annotations

import math
from typing import Any

from ..files.agent_values import MAX_DEPTH as MAX_LAYERS
from ..files.agent_values import MAX_PARAMETERS, MAX_WIDTH, NET_KEYS, TQC_QUANTILES
from ..files.policy_json import ACTIVATIONS

__all__ = ["MAX_LAYERS", "MAX_WIDTH", "MAX_PARAMETERS", "POLICIES", "check_hyperparams",
           "activation_class", "activation_name"]

POLICIES = ("MlpPolicy",)
# The network limits are those an agent file may have (files.agent_values): a run can
# only train what evaluate.py loads (a [200000, 200000] network would need 160 GB).

_UNIT = "a number in [0, 1]"


class _Bad(ValueError):
    """A value is not allowed; the message says what is."""


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _int_at_least(low: int):
    def check(value):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise _Bad(f"a whole number >= {low}")
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


def _schedule(value):
    """A number > 0 or ``lin_<start>`` with a start > 0."""
    if isinstance(value, str):
        try:
            start = float(value[4:]) if value.startswith("lin_") else math.nan
        except ValueError:
            start = math.nan
        if start > 0.0 and math.isfinite(start):
            return
    elif _is_number(value) and value > 0:
        return
    raise _Bad("a number or 'lin_<start>', > 0 and finite ('lin_<start>' falls linearly from "
               "start to 0 over the run)")


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
            if start > 0 and math.isfinite(start):
                return
    elif _is_number(value) and value >= 0:
        return
    raise _Bad("a finite number >= 0, 'auto' or 'auto_<initial value>' with a value > 0")


def _target_entropy(value):
    if value != "auto" and not _is_number(value):
        raise _Bad("'auto' or a finite number")


def _train_freq(value):
    if isinstance(value, (list, tuple)) and len(value) == 2 and value[1] in ("step", "episode"):
        value = value[0]
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise _Bad("a whole number >= 1 or [n >= 1, 'step' or 'episode']")


def _gradient_steps(value):
    if isinstance(value, bool) or not isinstance(value, int) or (value < 1 and value != -1):
        raise _Bad("a whole number >= 1, or -1 (as many as env steps collected)")


def _kwargs_dict(value):
    if value is not None and not isinstance(value, dict):
        raise _Bad("null or a mapping")


_COMMON = {
    "learning_rate": _schedule, "gamma": _unit, "use_sde": _bool,
    "sde_sample_freq": _sde_sample_freq, "stats_window_size": _int_at_least(1),
}
_CHECKS: dict[str, dict[str, Any]] = {
    "ppo": {**_COMMON, "n_steps": _int_at_least(1), "batch_size": _int_at_least(2),
            "n_epochs": _int_at_least(1), "gae_lambda": _unit, "clip_range": _schedule,
            "clip_range_vf": _optional(_schedule), "normalize_advantage": _bool,
            "ent_coef": _number(0.0), "vf_coef": _number(0.0),
            "max_grad_norm": _number(0.0, low_open=True),
            "target_kl": _optional(_number(0.0, low_open=True)),
            "rollout_buffer_class": _none, "rollout_buffer_kwargs": _kwargs_dict},
    "sac": {**_COMMON, "buffer_size": _int_at_least(1), "learning_starts": _int_at_least(0),
            "batch_size": _int_at_least(1), "tau": _number(0.0, 1.0, low_open=True),
            "train_freq": _train_freq, "gradient_steps": _gradient_steps,
            "action_noise": _none, "replay_buffer_class": _none,
            "replay_buffer_kwargs": _kwargs_dict, "optimize_memory_usage": _bool,
            "n_steps": _int_at_least(1), "ent_coef": _sac_ent_coef,
            "target_update_interval": _int_at_least(1), "target_entropy": _target_entropy,
            "use_sde_at_warmup": _bool,
            # CapsSAC's smoothness weights and perturbation scale (training/caps.py)
            "caps_temporal": _number(0.0), "caps_spatial": _number(0.0),
            "caps_magnitude": _number(0.0), "caps_sigma": _number(0.0)},
}
# sb3-contrib's TQC: SAC's arguments and the quantiles each critic drops from the target
_CHECKS["tqc"] = {**_CHECKS["sac"], "top_quantiles_to_drop_per_net": _int_at_least(0)}
_POLICY_KWARGS: dict[str, dict[str, Any]] = {
    "ppo": {"ortho_init": _bool, "full_std": _bool, "squash_output": _bool},
    "sac": {"clip_mean": _number(0.0, low_open=True), "n_critics": _int_at_least(1)},
}
_POLICY_KWARGS["tqc"] = {**_POLICY_KWARGS["sac"], "n_quantiles": _int_at_least(1)}
_POLICY_KWARGS_COMMON = {"log_std_init": _number(-20.0, 20.0), "use_sde": _bool,
                         "use_expln": _bool, "share_features_extractor": _bool,
                         "normalize_images": _bool}
_OPTIMIZER = {"eps": _number(0.0, low_open=True), "weight_decay": _number(0.0),
              "amsgrad": _bool}


def _layers(value) -> None:
    ok = isinstance(value, list) and len(value) <= MAX_LAYERS and all(
        isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= MAX_WIDTH for w in value)
    if not ok or sum(a * b for a, b in zip(value[:-1], value[1:], strict=True)) \
            > MAX_PARAMETERS:
        raise _Bad(f"a list of at most {MAX_LAYERS} layer widths, whole numbers in "
                   f"[1, {MAX_WIDTH}], with at most {MAX_PARAMETERS} weights between them")


def _net_arch(algo: str):
    nets = NET_KEYS[algo]

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


def _policy_kwargs_checks(algo: str) -> dict[str, Any]:
    return {"net_arch": _net_arch(algo), "activation_fn": _activation,
            "optimizer_kwargs": _optimizer_kwargs, **_POLICY_KWARGS_COMMON,
            **_POLICY_KWARGS[algo]}


def check_hyperparams(params: dict, algo: str, source: str, policy=None) -> None:
    """Raise ValueError naming the first value of ``params`` that PPO/SAC would reject.

    Parameters
    ----------
    params : dict
        The algorithm's keyword arguments as read from YAML (``policy_kwargs`` included;
        keys not listed here, such as train.py's own, are left to the caller).
    algo : str
        ``"ppo"``, ``"sac"`` or ``"tqc"``.
    source : str
        The file the values came from (the start of the message).
    policy : str or None
        The config's ``policy`` (None: not given, MlpPolicy).

    Raises
    ------
    ValueError
        ``"<source>: <key>: <value> must be <allowed>"``.
    """
    if policy is not None and policy not in POLICIES:
        raise ValueError(f"{source}: policy: {policy!r} must be one of {list(POLICIES)} (the "
                         "observation is a flat vector)")
    for key, check in _CHECKS[algo].items():
        if key in params:
            _run(check, f"{source}: {key}", params[key])
    if algo == "tqc":
        _tqc_keeps_quantiles(params, source)
    kwargs = params.get("policy_kwargs")
    if kwargs is None:
        return
    if not isinstance(kwargs, dict):
        raise ValueError(f"{source}: policy_kwargs: {kwargs!r} must be a mapping (no code is "
                         "evaluated)")
    checks = _policy_kwargs_checks(algo)
    for key, value in kwargs.items():
        if key not in checks:
            raise ValueError(f"{source}: policy_kwargs: unknown key {key!r} for "
                             f"{algo.upper()}; allowed: {sorted(checks)}")
        _run(checks[key], f"{source}: policy_kwargs.{key}", value)


def _tqc_keeps_quantiles(params: dict, source: str) -> None:
    """TQC's target keeps n_quantiles - top_quantiles_to_drop_per_net > 0 per critic."""
    kwargs = params.get("policy_kwargs")
    n_quantiles = (kwargs.get("n_quantiles", TQC_QUANTILES) if isinstance(kwargs, dict)
                   else TQC_QUANTILES)
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
