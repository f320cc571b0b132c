"""The values of ``agent.json`` checked before anything is built from them.

Every bound here is checked by :func:`check_values` when an agent is loaded, before the
policy is allocated or the weights are read; a value out of bounds is an
:class:`~.safe_format.AgentLoadError` naming the file, the key, the value and what is
allowed. The bounds (see :mod:`.safe_format`):

* ``env.id``: an env id that tether_gym registers (``tether_gym/...``), or null.
* ``env.kwargs``: a mapping (its values are checked by ``gym.make``).
* ``obs_normalization``: ``mean`` finite, ``var`` finite and >= 0, ``clip_obs`` a finite
  number > 0, ``epsilon`` a finite number in [0, 1], ``count`` (optional) a finite
  number >= 0.
* ``observation_space`` / ``action_space``: a shape of 1 to :data:`MAX_SPACE_DIMS` axes
  whose sizes multiply to 1 .. :data:`MAX_SPACE_SIZE`.
* ``policy_kwargs.net_arch``: a list of layer widths, or a mapping of such lists (``pi``,
  ``vf`` for PPO; ``pi``, ``qf`` for SAC and TQC); each width an integer in 1 ..
  :data:`MAX_WIDTH`, each list at most :data:`MAX_DEPTH` layers; and the networks the
  policy builds together hold at most :data:`MAX_PARAMETERS` parameters.
"""

from __future__ import annotations

import math
from pathlib import Path

__all__ = ["ValueProblem", "TQC_QUANTILES", "MAX_WIDTH", "MAX_DEPTH", "MAX_PARAMETERS",
           "MAX_SPACE_SIZE", "MAX_SPACE_DIMS", "NET_KEYS", "check_values", "tether_gym_env_ids"]

MAX_WIDTH = 4096
"""Widest hidden layer of a loaded policy [units]."""
MAX_DEPTH = 8
"""Most hidden layers of one network of a loaded policy."""
MAX_PARAMETERS = 20_000_000
"""Most parameters (about 80 MB of float32) of the networks a loaded policy builds."""
MAX_SPACE_SIZE = 100_000
"""Most entries of an observation or action."""
MAX_SPACE_DIMS = 4
"""Most axes of an observation or action space."""
NET_KEYS = {"ppo": ("pi", "vf"), "sac": ("pi", "qf"), "tqc": ("pi", "qf")}
"""The networks a mapping ``net_arch`` may name, per algorithm."""
_SAC_CRITICS = 2  # SB3's default n_critics; SAC also builds a target copy of the critics
TQC_QUANTILES = 25
"""sb3-contrib's default ``n_quantiles``: the outputs of each TQC critic."""


class ValueProblem(ValueError):
    """A value of ``agent.json`` is out of the bounds above (the message says which)."""


def tether_gym_env_ids() -> list[str]:
    """The env ids tether_gym registers with gymnasium."""
    import gymnasium as gym

    import tether_gym

    return sorted({tether_gym.ENV_ID} | {k for k in gym.registry if k.startswith("tether_gym/")})


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(value, key: str, allowed: str, ok) -> None:
    if not _is_number(value) or not math.isfinite(value) or not ok(value):
        raise ValueProblem(f"{key}={value!r}; allowed: {allowed}")


def check_env(env) -> None:
    """``env.id`` a tether_gym id or null, ``env.kwargs`` a mapping."""
    if not isinstance(env, dict):
        raise ValueProblem(f"env={env!r}; allowed: a mapping with 'id' and 'kwargs'")
    ids = tether_gym_env_ids()
    if env.get("id") is not None and env.get("id") not in ids:
        raise ValueProblem(f"env.id={env.get('id')!r} is not a tether_gym env; allowed: "
                           f"{ids} or null")
    if not isinstance(env.get("kwargs", {}), dict):
        raise ValueProblem(f"env.kwargs={env.get('kwargs')!r}; allowed: a mapping of "
                           "gym.make arguments")


def check_normalization(norm) -> None:
    """The scalar entries and the entries of ``mean`` and ``var`` (already parsed by value)."""
    if norm is None:
        return
    if not isinstance(norm, dict):
        raise ValueProblem(f"obs_normalization={norm!r}; allowed: a mapping or null")
    _number(norm.get("clip_obs"), "obs_normalization.clip_obs", "a finite number > 0",
            lambda v: v > 0)
    _number(norm.get("epsilon"), "obs_normalization.epsilon", "a finite number in [0, 1]",
            lambda v: 0 <= v <= 1)
    if "count" in norm:
        _number(norm["count"], "obs_normalization.count", "a finite number >= 0",
                lambda v: v >= 0)
    for key, ok, allowed in (("mean", lambda v: True, "finite numbers"),
                             ("var", lambda v: v >= 0, "finite numbers >= 0")):
        values = norm.get(key)
        if not isinstance(values, list):
            raise ValueProblem(f"obs_normalization.{key}={values!r}; allowed: a list of "
                               f"{allowed}")
        for i, value in enumerate(values):
            number = value
            if isinstance(value, str):  # float_list writes inf and nan as strings
                try:
                    number = float(value)
                except ValueError:
                    pass
            if not _is_number(number) or not math.isfinite(number) or not ok(number):
                raise ValueProblem(f"obs_normalization.{key}[{i}]={value!r}; allowed: "
                                   f"{allowed}")


def space_size(space, key: str) -> int:
    """The number of entries of a recorded space (its shape checked)."""
    shape = space.get("shape") if isinstance(space, dict) else None
    if (not isinstance(shape, list) or not 1 <= len(shape) <= MAX_SPACE_DIMS
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 1
                       for s in shape)):
        raise ValueProblem(f"{key}.shape={shape!r}; allowed: a list of 1 to "
                           f"{MAX_SPACE_DIMS} integers >= 1")
    size = math.prod(shape)
    if size > MAX_SPACE_SIZE:
        raise ValueProblem(f"{key}.shape={shape!r} has {size} entries; allowed: at most "
                           f"{MAX_SPACE_SIZE}")
    return size


def _layers(widths, key: str) -> list[int]:
    if not isinstance(widths, list) or len(widths) > MAX_DEPTH:
        raise ValueProblem(f"{key}={widths!r}; allowed: a list of at most {MAX_DEPTH} layer "
                           f"widths")
    for i, width in enumerate(widths):
        if (not isinstance(width, int) or isinstance(width, bool)
                or not 1 <= width <= MAX_WIDTH):
            raise ValueProblem(f"{key}[{i}]={width!r}; allowed: an integer in 1 .. {MAX_WIDTH}")
    return widths


def _mlp_parameters(n_in: int, widths: list[int], n_out: int) -> int:
    sizes = [n_in, *widths, n_out]
    return sum((a + 1) * b for a, b in zip(sizes[:-1], sizes[1:], strict=True))


def _count(kwargs: dict, key: str, default: int) -> int:
    """A whole number >= 1 of ``policy_kwargs`` (its default when absent)."""
    value = kwargs.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_WIDTH:
        raise ValueProblem(f"policy_kwargs.{key}={value!r}; allowed: a whole number in "
                           f"[1, {MAX_WIDTH}]")
    return value


def check_net_arch(algo: str, kwargs, n_obs: int, n_act: int) -> None:
    """``net_arch`` within the width, depth and parameter bounds, before anything is built."""
    if not isinstance(kwargs, dict):
        return  # reported by settings_from_json
    arch = kwargs.get("net_arch", [64, 64])
    key = "policy_kwargs.net_arch"
    if arch is None:
        arch = [64, 64]
    if isinstance(arch, dict):
        extra = set(arch) - set(NET_KEYS[algo])
        if extra:
            raise ValueProblem(f"{key} names {sorted(extra)}; allowed for {algo.upper()}: "
                               f"{list(NET_KEYS[algo])}")
        pi = _layers(arch.get(NET_KEYS[algo][0], []), f"{key}.{NET_KEYS[algo][0]}")
        other = _layers(arch.get(NET_KEYS[algo][1], []), f"{key}.{NET_KEYS[algo][1]}")
    else:
        pi = other = _layers(arch, key)
    if algo in ("sac", "tqc"):
        outputs = 1 if algo == "sac" else _count(kwargs, "n_quantiles", TQC_QUANTILES)
        n_critics = _SAC_CRITICS if algo == "sac" else _count(kwargs, "n_critics", _SAC_CRITICS)
        critics = 2 * n_critics * _mlp_parameters(n_obs + n_act, other, outputs)
        total = _mlp_parameters(n_obs, pi, 2 * n_act) + critics
    else:
        total = _mlp_parameters(n_obs, pi, n_act) + _mlp_parameters(n_obs, other, 1)
    if total > MAX_PARAMETERS:
        raise ValueProblem(f"{key}={arch!r} builds about {total:,} parameters for "
                           f"{n_obs} observations and {n_act} actions; allowed: at most "
                           f"{MAX_PARAMETERS:,}")


def check_values(meta: dict, meta_path: Path) -> None:
    """Check the recorded values of ``agent.json`` against the bounds of this module.

    Raises
    ------
    ValueProblem
        Naming ``meta_path``, the key, the value and what is allowed.
    """
    try:
        check_env(meta["env"])
        n_obs = space_size(meta["observation_space"], "observation_space")
        n_act = space_size(meta["action_space"], "action_space")
        check_net_arch(meta["algo"], meta["policy_kwargs"], n_obs, n_act)
        check_normalization(meta["obs_normalization"])
    except ValueProblem as exc:
        raise ValueProblem(f"{meta_path}: {exc}") from None
