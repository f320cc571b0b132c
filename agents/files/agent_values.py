"""The values of ``agent.json`` checked before anything is built from them.

Every bound here is checked by :func:`check_values` when an agent is loaded, before the
policy is allocated or the weights are read; a value out of bounds is an
:class:`~.safe_format.AgentLoadError` naming the file, the key, the value and what is
allowed. The bounds (see :mod:`.safe_format`):

* ``env.id``: an env id that tether_gym registers (``tether_gym/...``), or null.
* ``env.kwargs``: a mapping that tether_gym's own check of ``gym.make``'s arguments
  (``EnvConfig.from_kwargs``: known names, finite values in range) accepts; no env is
  built.
* ``obs_normalization``: ``mean`` finite with ``|mean|`` <= :data:`MAX_OBS_MEAN`,
  ``var`` finite in [0, :data:`MAX_OBS_VAR`], ``var + epsilon`` > 0 (the divisor's
  square), ``clip_obs`` a finite number > 0, ``epsilon`` a finite number in [0, 1],
  ``count`` (optional) a finite number >= 0.
* ``observation_space`` / ``action_space``: a shape of 1 to :data:`MAX_SPACE_DIMS` axes
  whose sizes multiply to 1 .. :data:`MAX_SPACE_SIZE`; a Box's ``low`` and ``high`` one
  entry per element, each a number or +-inf (never NaN; the action space's finite),
  ``low`` <= ``high``.
* ``policy_kwargs.net_arch``: a list of layer widths, or a mapping of such lists (the
  algorithm's ``net_keys``: ``pi``/``vf`` for PPO; ``pi``/``qf`` for SAC, TQC and TD3);
  each width an integer in 1 .. :data:`MAX_WIDTH`, each list at most :data:`MAX_DEPTH`
  layers; and the networks the policy builds together (counted from the algorithm's row
  of :data:`~tether_gym_agents.common.algorithms.ALGORITHMS`: actor outputs, critics,
  target copies) hold at most :data:`MAX_PARAMETERS` parameters. The counts that size
  the networks (``n_critics``, ``n_quantiles``) lie in the row's ``bounds``.
* ``policy_kwargs.log_std_init`` finite in [:data:`LOG_STD_MIN`, :data:`LOG_STD_MAX`];
  ``clip_mean`` a finite number > 0.
* the weights (:func:`check_weights`): float32 or float64 tensors (what ``save_agent``
  writes: the policy's own dtype), every entry finite.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..common.algorithms import algorithm

__all__ = ["ValueProblem", "check_running_stats", "MAX_WIDTH", "MAX_DEPTH", "MAX_PARAMETERS",
           "MAX_SPACE_SIZE", "MAX_SPACE_DIMS", "MAX_OBS_MEAN", "MAX_OBS_VAR", "LOG_STD_MIN",
           "LOG_STD_MAX", "WEIGHT_DTYPES", "check_values", "check_weights",
           "tether_gym_env_ids"]

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
MAX_OBS_MEAN = 1e6
"""Largest ``|mean|`` of the observation statistics. The env's observations are angles
[rad], rates and lengths of order 1 to 100; a running mean of 1e6 is already no
statistic of it, and 1e308 would make ``obs - mean`` meaningless in float32."""
MAX_OBS_VAR = 1e12
"""Largest ``var`` of the observation statistics (a standard deviation of 1e6, the
square of :data:`MAX_OBS_MEAN`): above it every normalised observation is 0."""
LOG_STD_MIN, LOG_STD_MAX = -20.0, 20.0
"""Bounds of ``log_std_init`` (SAC clamps its log_std to [-20, 2]; e**20 is 5e8 action
units, far beyond any action box)."""
WEIGHT_DTYPES = ("float32", "float64")
"""The dtypes of the tensors ``save_agent`` writes (the policy's own; loading never casts:
int8, bool or float16 weights would be cast silently into another policy)."""


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
    """``env.id`` a tether_gym id or null, ``env.kwargs`` arguments the env accepts."""
    if not isinstance(env, dict):
        raise ValueProblem(f"env={env!r}; allowed: a mapping with 'id' and 'kwargs'")
    ids = tether_gym_env_ids()
    if env.get("id") is not None and env.get("id") not in ids:
        raise ValueProblem(f"env.id={env.get('id')!r} is not a tether_gym env; allowed: "
                           f"{ids} or null")
    kwargs = env.get("kwargs", {})
    if not isinstance(kwargs, dict):
        raise ValueProblem(f"env.kwargs={kwargs!r}; allowed: a mapping of "
                           "gym.make arguments")
    from tether_gym.envs import EnvConfig

    try:  # the env's own validation of gym.make's arguments; nothing is built
        EnvConfig.from_kwargs(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ValueProblem(f"env.kwargs: {' '.join(str(exc).split())}") from None


_STATS = {"mean": (lambda v: abs(v) <= MAX_OBS_MEAN,
                   f"finite numbers with |mean| <= {MAX_OBS_MEAN:g}"),
          "var": (lambda v: 0 <= v <= MAX_OBS_VAR,
                  f"finite numbers >= 0 and <= {MAX_OBS_VAR:g}")}


def _statistic(value, key: str, kind: str) -> float:
    """One entry of a running ``mean`` or ``var`` (``kind``) within the bounds above."""
    ok, allowed = _STATS[kind]
    number = value
    if isinstance(value, str):  # float_list writes inf and nan as strings
        try:
            number = float(value)
        except ValueError:
            pass
    if not _is_number(number) or not math.isfinite(number) or not ok(number):
        raise ValueProblem(f"{key}={value!r}; allowed: {allowed}")
    return number


def check_running_stats(name: str, mean, var, count) -> None:
    """A running mean/variance (VecNormalize's, as a checkpoint's ``.npz`` holds them).

    ``mean`` and ``var`` array-likes whose entries lie in the bounds of
    ``obs_normalization`` (module docstring), ``count`` a finite number >= 0.

    Raises
    ------
    ValueProblem
        ``"<name>_mean[i]=nan; allowed: ..."`` for the first entry out of bounds.
    """
    import numpy as np

    for kind, values in (("mean", mean), ("var", var)):
        for i, value in enumerate(np.asarray(values, dtype=np.float64).ravel().tolist()):
            _statistic(value, f"{name}_{kind}[{i}]", kind)
    number = np.asarray(count, dtype=np.float64)
    if number.size != 1 or not math.isfinite(float(number)) or float(number) < 0:
        raise ValueProblem(f"{name}_count={count!r}; allowed: a finite number >= 0")


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
    for key in ("mean", "var"):
        values = norm.get(key)
        if not isinstance(values, list):
            raise ValueProblem(f"obs_normalization.{key}={values!r}; allowed: a list of "
                               f"{_STATS[key][1]}")
        for i, value in enumerate(values):
            number = _statistic(value, f"obs_normalization.{key}[{i}]", key)
            if key == "var" and number + norm["epsilon"] <= 0:
                raise ValueProblem(f"obs_normalization.var[{i}]={value!r} with epsilon="
                                   f"{norm['epsilon']!r} divides by zero; allowed: var + "
                                   "epsilon > 0")


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


def _count(kwargs: dict, key: str, default: int, bounds: tuple[int, int]) -> int:
    """A whole number of ``policy_kwargs`` in ``bounds`` (its default when absent)."""
    value = kwargs.get(key, default)
    low, high = bounds
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ValueProblem(f"policy_kwargs.{key}={value!r}; allowed: a whole number in "
                           f"[{low}, {high}]")
    return value


def _row_count(row, kwargs: dict, key: str) -> int:
    """``n_critics``/``n_quantiles`` of the row (1 where the row builds no such count)."""
    if key not in row.defaults:
        return 1
    return _count(kwargs, key, row.defaults[key], row.bounds.get(key, (1, MAX_WIDTH)))


def check_net_arch(algo: str, kwargs, n_obs: int, n_act: int) -> None:
    """``net_arch`` within the width, depth and parameter bounds, before anything is built.

    The parameters are counted from the algorithm's row of the table: the actor (its
    :attr:`~tether_gym_agents.common.algorithms.Algorithm.actor_outputs` per action) and
    the critics (one value network, or ``n_critics`` Q networks of ``n_quantiles``
    outputs each), times their ``copies`` (target networks).
    """
    if not isinstance(kwargs, dict):
        return  # reported by settings_from_json
    row = algorithm(algo)
    arch = kwargs.get("net_arch", [64, 64])
    key = "policy_kwargs.net_arch"
    if arch is None:
        arch = [64, 64]
    actor_key, critic_key = row.net_keys
    if isinstance(arch, dict):
        extra = set(arch) - set(row.net_keys)
        if extra:
            raise ValueProblem(f"{key} names {sorted(extra)}; allowed for {algo.upper()}: "
                               f"{list(row.net_keys)}")
        pi = _layers(arch.get(actor_key, []), f"{key}.{actor_key}")
        other = _layers(arch.get(critic_key, []), f"{key}.{critic_key}")
    else:
        pi = other = _layers(arch, key)
    n_critics = _row_count(row, kwargs, "n_critics")
    outputs = _row_count(row, kwargs, "n_quantiles")
    actor = _mlp_parameters(n_obs, pi, row.actor_outputs * n_act)
    if row.critic == "value":
        critic = _mlp_parameters(n_obs, other, 1)
    else:
        critic = n_critics * _mlp_parameters(n_obs + n_act, other, outputs)
    total = row.copies[0] * actor + row.copies[1] * critic
    if total > MAX_PARAMETERS:
        raise ValueProblem(f"{key}={arch!r} builds about {total:,} parameters for "
                           f"{n_obs} observations and {n_act} actions; allowed: at most "
                           f"{MAX_PARAMETERS:,}")


def check_policy_numbers(kwargs) -> None:
    """``log_std_init`` and ``clip_mean`` of ``policy_kwargs``: finite and in range."""
    if not isinstance(kwargs, dict):
        return  # reported by settings_from_json
    if kwargs.get("log_std_init") is not None:
        _number(kwargs["log_std_init"], "policy_kwargs.log_std_init",
                f"a finite number in [{LOG_STD_MIN:g}, {LOG_STD_MAX:g}]",
                lambda v: LOG_STD_MIN <= v <= LOG_STD_MAX)
    if kwargs.get("clip_mean") is not None:
        _number(kwargs["clip_mean"], "policy_kwargs.clip_mean", "a finite number > 0",
                lambda v: v > 0)


def _bound(value) -> float | None:
    """A recorded Box bound as a float (``"inf"``/``"-inf"`` allowed); None if malformed."""
    if isinstance(value, str) and value in ("inf", "-inf"):
        return float(value)
    if _is_number(value) and not math.isnan(value):
        return float(value)
    return None


def check_box(space, key: str, size: int, finite: bool = False) -> None:
    """A Box's ``low`` and ``high``: ``size`` numbers (or +-inf) each, ``low <= high``.

    With ``finite`` (the action space: actions are scaled from its bounds) +-inf is
    refused too.
    """
    if space.get("type") != "Box":
        return  # reported by space_from_json (only Box spaces are read)
    bounds = {}
    for side in ("low", "high"):
        values = space.get(side)
        if not isinstance(values, list) or len(values) != size:
            raise ValueProblem(f"{key}.{side}={values!r}; allowed: a list of {size} numbers "
                               f"(one per entry of {key}.shape={space.get('shape')!r})")
        bounds[side] = [_bound(v) for v in values]
        for i, (value, number) in enumerate(zip(values, bounds[side], strict=True)):
            if number is None:
                raise ValueProblem(f"{key}.{side}[{i}]={value!r}; allowed: a number, "
                                   "'inf' or '-inf' (not NaN)")
            if finite and not math.isfinite(number):
                raise ValueProblem(f"{key}.{side}[{i}]={value!r}; allowed: a finite number "
                                   "(actions are scaled between low and high)")
    for i, (low, high) in enumerate(zip(bounds["low"], bounds["high"], strict=True)):
        if not low <= high:  # type: ignore[operator]
            raise ValueProblem(f"{key}.low[{i}]={low!r} > {key}.high[{i}]={high!r}; "
                               "allowed: low <= high")


def check_weights(state: dict, weights: Path) -> None:
    """The tensors of ``policy.safetensors``: float32/float64, every entry finite.

    Raises
    ------
    ValueProblem
        Naming ``weights``, the tensor and its dtype or its first non-finite entry.
    """
    import torch

    for name, tensor in state.items():
        dtype = str(tensor.dtype).removeprefix("torch.")
        if dtype not in WEIGHT_DTYPES:
            raise ValueProblem(f"{weights}: tensor {name!r} has dtype {dtype}; allowed: "
                               f"{list(WEIGHT_DTYPES)} (as save_agent writes; never cast)")
        bad = ~torch.isfinite(tensor)
        if bool(bad.any()):
            index = tuple(int(i) for i in bad.nonzero()[0])
            raise ValueProblem(f"{weights}: tensor {name!r}{list(index)} = "
                               f"{float(tensor[index])}; allowed: finite numbers")


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
        check_box(meta["observation_space"], "observation_space", n_obs)
        check_box(meta["action_space"], "action_space", n_act, finite=True)
        check_net_arch(meta["algo"], meta["policy_kwargs"], n_obs, n_act)
        check_policy_numbers(meta["policy_kwargs"])
        check_normalization(meta["obs_normalization"])
    except ValueProblem as exc:
        raise ValueProblem(f"{meta_path}: {exc}") from None
