"""stable-baselines3 ``VecEnv`` on the native vector env (no DummyVecEnv, no subprocesses).

:func:`make_sb3_vec_env` builds ``gym.make_vec("tether_gym/TetherLibration-v1",
vectorization_mode="vector_entry_point")`` and wraps it in :class:`TetherSB3VecEnv`,
which speaks SB3's protocol:

* auto-reset on the same step: when sub-env i ends, ``step_wait`` returns its reset
  observation in ``obs[i]``, ``dones[i] = True``, the last observation of the episode
  in ``infos[i]["terminal_observation"]`` and ``infos[i]["TimeLimit.truncated"] =
  truncated and not terminated``; ``reset_infos[i]`` holds the reset info;
* ``infos`` is a list of per-env dicts holding the env's documented ``info`` keys.

Episode statistics for SB3's logger (``rollout/ep_rew_mean``): wrap the result in
``VecMonitor`` (as :mod:`tether_gym_agents.training.run` does), or pass ``monitor=True`` to get
Monitor's ``infos[i]["episode"] = {"r": return, "l": length, "t": seconds}`` from the
adapter itself; ``env_is_wrapped(Monitor)`` then answers True, so ``evaluate_policy``
reads them and ``VecMonitor`` warns that it would count twice.

Sub-envs i and j share one native env, so ``set_attr`` and ``env_method`` act on all
of them at once and accept only ``indices`` that cover every env.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvIndices, VecEnvStepReturn

from tether_gym import ENV_ID
from tether_gym.envs.vector import TetherLibrationVectorEnv

from ..common.features import FeatureSpec, add_features

__all__ = ["TetherSB3VecEnv", "make_sb3_vec_env", "FeatureVecEnv"]

# attributes whose native value is a per-sub-env tuple, or batched where SB3 wants one env's
_PER_ENV = ("np_random", "np_random_seed")
_SINGLE = {"observation_space": "single_observation_space",
           "action_space": "single_action_space"}


def make_sb3_vec_env(num_envs: int = 1, seed: int | None = None,
                     env_kwargs: dict[str, Any] | None = None, monitor: bool = False,
                     parallel: bool | str = "auto") -> TetherSB3VecEnv:
    """SB3 VecEnv of ``num_envs`` TetherLibration envs on one native vector env.

    Parameters
    ----------
    num_envs : int
        Number of sub-envs (>= 1).
    seed : int or None
        Sub-env i is seeded with ``seed + i`` at the first ``reset()`` (SB3's
        ``make_vec_env`` convention); None draws random seeds.
    env_kwargs : dict or None
        Keyword arguments of the env (see ``TetherLibrationEnv``), plus
        ``max_episode_steps`` (a step cap; none by default, the env truncates itself
        after ``orbits_per_episode``).
    monitor : bool
        Report Monitor-style ``"episode"`` infos (see the module docstring); off by
        default: wrap in ``VecMonitor`` instead.
    parallel : bool or "auto"
        Step the sub-envs on numba's threads (see
        :class:`~tether_gym.envs.vector.TetherLibrationVectorEnv`; "auto": from 128
        sub-envs on).
    """
    kwargs = dict(env_kwargs or {})
    kwargs.setdefault("parallel", parallel)
    venv = gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)
    env = TetherSB3VecEnv(venv, monitor=monitor)  # type: ignore[arg-type]
    if seed is not None:
        env.seed(seed)
    return env


class TetherSB3VecEnv(VecEnv):
    """SB3 view of a :class:`~tether_gym.envs.vector.TetherLibrationVectorEnv`.

    Parameters
    ----------
    venv : TetherLibrationVectorEnv
        The native vector env (``gym.make_vec`` result); it is owned and closed by
        this object.
    monitor : bool
        Add Monitor's ``"episode"`` info at the end of each episode.
    """

    def __init__(self, venv: TetherLibrationVectorEnv, monitor: bool = False):
        if not isinstance(venv.unwrapped, TetherLibrationVectorEnv):
            raise TypeError(f"venv must be a TetherLibrationVectorEnv, got "
                            f"{type(venv.unwrapped).__name__}")
        self.venv = venv.unwrapped
        self.monitor = bool(monitor)
        super().__init__(self.venv.num_envs, self.venv.single_observation_space,
                         self.venv.single_action_space)
        self.metadata["render_fps"] = self.venv.metadata["render_fps"]
        self._actions: np.ndarray | None = None
        self._episode_return = np.zeros(self.num_envs)
        self._episode_length = np.zeros(self.num_envs, dtype=np.int64)
        self._t_start = time.time()

    @property
    def config(self):
        """The native env's EnvConfig."""
        return self.venv.config

    # ------------------------------------------------------------------ #
    def reset(self) -> np.ndarray:
        """Reset every sub-env; return the observations.

        The seeds of :meth:`seed` and the options of :meth:`set_options` are used once.
        """
        seeds = list(self._seeds)
        # sub-envs with equal options are reset together (each sub-env exactly once)
        groups: list[tuple[dict, np.ndarray]] = []
        for i, opts in enumerate(self._options):
            for known, mask in groups:
                if known == opts:
                    mask[i] = True
                    break
            else:
                mask = np.zeros(self.num_envs, dtype=np.bool_)
                mask[i] = True
                groups.append((opts, mask))
        obs = np.empty(0)
        for opts, mask in groups:
            call_options = dict(opts)
            if len(groups) > 1:
                call_options["reset_mask"] = mask
            obs, infos = self.venv.reset(seed=seeds, options=call_options or None)
            for i, info in zip(np.flatnonzero(mask).tolist(), _rows(infos, mask), strict=True):
                self.reset_infos[i] = info
        self._reset_seeds()
        self._reset_options()
        self._episode_return[:] = 0.0
        self._episode_length[:] = 0
        return obs

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """Options for the next :meth:`reset`.

        One dict for every sub-env, or a list of exactly ``num_envs`` dicts (None entries
        mean no options).

        Raises
        ------
        ValueError
            If a list has the wrong length (each sub-env must be reset exactly once).
        TypeError
            If ``options`` or an entry is not a dict (or None).
        """
        if options is None or isinstance(options, dict):
            super().set_options(options)
            return
        if isinstance(options, (str, bytes)) or not isinstance(options, Sequence):
            raise TypeError(f"options must be a dict, a list of {self.num_envs} dicts or None, "
                            f"got {type(options).__name__}")
        if len(options) != self.num_envs:
            raise ValueError(f"options has {len(options)} entries but there are "
                             f"{self.num_envs} sub-envs; give one dict per sub-env or a single "
                             "dict for all")
        bad = [i for i, o in enumerate(options) if o is not None and not isinstance(o, dict)]
        if bad:
            raise TypeError(f"options[{bad[0]}] must be a dict or None, got "
                            f"{type(options[bad[0]]).__name__}")
        super().set_options([dict(o or {}) for o in options])

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions of the next :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every sub-env (SB3's protocol: auto-reset on the same step)."""
        if self._actions is None:
            raise RuntimeError("step_async() must be called before step_wait()")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        dones = terminated | truncated
        info_list = _rows(infos)
        self._episode_return += rewards
        self._episode_length += 1
        for info, flag in zip(info_list, (truncated & ~terminated).tolist(), strict=True):
            info["TimeLimit.truncated"] = flag
        if dones.any():
            done_rows = np.flatnonzero(dones)
            reset_obs, reset_infos = self.venv.reset(options={"reset_mask": dones})
            now = time.time()
            for i, reset_info in zip(done_rows.tolist(), _rows(reset_infos, dones), strict=True):
                info = info_list[i]
                info["terminal_observation"] = obs[i].copy()
                if self.monitor:
                    info["episode"] = {"r": round(float(self._episode_return[i]), 6),
                                       "l": int(self._episode_length[i]),
                                       "t": round(now - self._t_start, 6)}
                self.reset_infos[i] = reset_info
            obs[done_rows] = reset_obs[done_rows]
            self._episode_return[done_rows] = 0.0
            self._episode_length[done_rows] = 0
        return obs, rewards.astype(np.float32), dones, info_list

    def close(self) -> None:
        """Close the native env."""
        self.venv.close()

    # ------------------------------------------------------------------ #
    def get_images(self) -> Sequence[np.ndarray | None]:
        """One rgb_array frame per sub-env (None without that render mode)."""
        if self.render_mode != "rgb_array":
            return [None] * self.num_envs
        return list(self.venv.render() or ())

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Attribute of each sub-env: the shared env's value (spaces: the single ones)."""
        indices = list(self._get_indices(indices))
        value = getattr(self.venv, _SINGLE.get(attr_name, attr_name))
        if attr_name in _PER_ENV:
            return [value[i] for i in indices]
        return [value for _ in indices]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the shared env (``indices`` must cover every sub-env)."""
        self._check_all(indices, "set_attr")
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None,
                   **method_kwargs) -> list[Any]:
        """Call a method of the shared env once; its result is repeated per sub-env."""
        self._check_all(indices, "env_method")
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * self.num_envs

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper],
                       indices: VecEnvIndices = None) -> list[bool]:
        """No gymnasium wrappers; Monitor counts as present when ``monitor`` is on."""
        wrapped = self.monitor and issubclass(Monitor, wrapper_class)
        return [wrapped for _ in self._get_indices(indices)]

    def _check_all(self, indices: VecEnvIndices, what: str) -> None:
        if indices is None or sorted(set(self._get_indices(indices))) == list(
                range(self.num_envs)):
            return
        raise ValueError(f"{what}(indices={indices!r}): the {self.num_envs} sub-envs share "
                         "one TetherLibrationVectorEnv, so this acts on all of them; pass "
                         "indices=None")

    def __repr__(self) -> str:
        return f"TetherSB3VecEnv({self.venv!r}, monitor={self.monitor})"


def _rows(infos: dict[str, Any], mask: np.ndarray | None = None) -> list[dict[str, Any]]:
    """Per-env info dicts from gymnasium vector infos, for the envs of ``mask`` (or all).

    The native env's infos carry the same keys for every reporting env; scalars become
    Python floats / str / None as in the single env's info, arrays stay (row) arrays.
    """
    keys = [key for key in infos if key[0] != "_"]
    columns = []
    for key in keys:
        value = infos[key] if mask is None else infos[key][mask]
        columns.append(value.tolist() if value.ndim == 1 else list(value))
    return [dict(zip(keys, values, strict=True)) for values in zip(*columns, strict=True)]


class FeatureVecEnv(VecEnvWrapper):
    """Appends a policy's input features (:mod:`tether_gym_agents.common.features`) to observations.

    It sits below ``VecNormalize`` in training, so the features are normalised like the
    observation, and it also extends each ``terminal_observation``.

    Parameters
    ----------
    venv : VecEnv
        A TetherLibration vec env (one action per tether).
    spec : FeatureSpec
        The features.
    """

    def __init__(self, venv: VecEnv, spec: FeatureSpec):
        self.features = spec
        space = venv.observation_space
        if not isinstance(space, gym.spaces.Box) or venv.action_space.shape is None:
            raise TypeError(f"FeatureVecEnv needs a TetherLibration vec env, got {venv!r}")
        self.n_tethers = venv.action_space.shape[0]
        extra = np.full(spec.size(self.n_tethers), -np.inf, dtype=np.float32)
        super().__init__(venv, observation_space=gym.spaces.Box(
            np.concatenate([space.low, extra]), np.concatenate([space.high, -extra]),
            dtype=np.float32))

    def reset(self) -> np.ndarray:
        """Reset every sub-env; the observations with their features."""
        return add_features(self.features, np.asarray(self.venv.reset()), self.n_tethers)

    def step_wait(self) -> VecEnvStepReturn:
        """The step's results; observations and terminal observations with their features."""
        obs, rewards, dones, infos = self.venv.step_wait()
        for info in infos:
            if "terminal_observation" in info:
                info["terminal_observation"] = add_features(
                    self.features, info["terminal_observation"], self.n_tethers)
        return add_features(self.features, np.asarray(obs), self.n_tethers), rewards, dones, infos
