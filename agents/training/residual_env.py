"""Residual RL on top of the sliding-mode law: the training side of the hybrid.

The hybrid commands

    u = filter(clip(u_base(obs) + scale * a_rl, -1, 1))

with u_base the paper's sliding-mode law
(:class:`~tether_gym_agents.baselines.smc.SlidingModeController`)
designed on the env's *nominal* model, a_rl in [-1, 1]^n the learned residual and
``filter`` the optional model-based safety filter (:class:`tether_gym.safety.SafetyFilter`,
predicting on the same nominal model). :class:`ResidualVecEnv` puts everything but a_rl
inside a stable-baselines3 vector env, so PPO or SAC learn a_rl on it unchanged; at
evaluation :class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` computes the same sum
around the trained agent.

:class:`~tether_gym_agents.hybrids.residual_spec.ResidualSpec` (re-exported here) is the
plain-data description of a hybrid: the ``residual`` key of a training config, the
``"hybrid"`` entry of ``agent.json``.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from tether_gym.physics import STATE
from tether_gym.safety import FilterResult, SafetyFilter
from tether_gym.wrappers import state_of

from ..baselines.smc import SlidingModeController
from ..common.obs import ObservationLayout
from ..hybrids.policies import state_from_observation
from ..hybrids.residual_spec import DEFAULT_SCALE, BaseLaw, ResidualSpec

__all__ = ["BaseLaw", "ResidualSpec", "ResidualVecEnv", "DEFAULT_SCALE", "INFO_KEYS"]

INFO_KEYS = ("filter_active", "filter_correction", "filter_feasible")
"""Entries :class:`ResidualVecEnv` adds to every step's ``infos[i]`` (as
:data:`tether_gym.wrappers.INFO_KEYS`; False, 0.0, True without a filter)."""
_STATE_KEYS = ("nu", *STATE.names)


def _config_view(venv: VecEnv) -> SimpleNamespace:
    """An object with the TetherLibration ``config`` and nominal ``model`` of ``venv``."""
    try:
        cfg = venv.get_attr("config", indices=[0])[0]
    except AttributeError:
        cfg = None
    if cfg is None or not hasattr(cfg, "model") or not hasattr(cfg, "param_rows"):
        raise TypeError(f"venv must be a vector env of tether_gym/TetherLibration-v1 (e.g. "
                        f"make_sb3_vec_env), got {type(venv).__name__} without its config")
    return SimpleNamespace(config=cfg, model=cfg.model)


class ResidualVecEnv(VecEnvWrapper):
    """SB3 vector env whose action is the residual a_rl of the hybrid (module docstring).

    On every step the base law's action is computed for all sub-envs in one batch from
    their current observations (after an auto-reset: the new episode's first
    observation, which SB3 returns in place of the terminal one), ``scale * action`` is
    added, the sum is clipped to [-1, 1], filtered when a filter is given, cast to
    float32 (as :class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` returns it) and sent
    to the wrapped env. ``infos[i]`` gets :data:`INFO_KEYS` of that step.

    Parameters
    ----------
    venv : VecEnv
        SB3 vector env of ``tether_gym/TetherLibration-v1`` with ``action_mode="rate"``
        and raw (not normalised) observations: put ``VecNormalize`` above this wrapper.
    base : object with ``predict``
        The base law for batches of observations (B, obs_dim) -> actions (B, n) in
        [-1, 1], deterministic, e.g. ``SlidingModeController.for_env(...)``.
    scale : float
        Weight of the residual [-], finite and >= 0.
    safety_filter : SafetyFilter or None
        Filter of the summed command (None: unfiltered). It is given the true state of
        each sub-env from the env's ``info`` (reset info after a reset), as
        :class:`tether_gym.wrappers.SafetyFilterWrapper` does, or the state read from
        the observation (:func:`~tether_gym_agents.hybrids.policies.state_from_observation`)
        for a sub-env whose info lacks it.

    Raises
    ------
    ValueError
        If the env is not in rate mode, ``scale`` is negative or not finite, or the
        filter is for another number of tethers.
    TypeError
        If ``venv`` is not a TetherLibration vector env, ``base`` has no ``predict`` or
        ``safety_filter`` is not a SafetyFilter.

    Notes
    -----
    Counters over the wrapper's life: ``filter_steps`` (filtered commands) and
    ``filter_interventions`` (of those, the ones the filter changed).
    """

    def __init__(self, venv: VecEnv, base, scale: float,
                 safety_filter: SafetyFilter | None = None):
        view = _config_view(venv)
        self.layout = ObservationLayout.from_env(view)
        self.layout.require_rate_mode(type(self).__name__)
        if not hasattr(base, "predict"):
            raise TypeError(f"base must have a predict method, got {type(base).__name__}")
        if isinstance(scale, bool) or not isinstance(scale, (int, float, np.floating)) \
                or not math.isfinite(scale) or scale < 0:
            raise ValueError(f"scale={scale!r} must be a finite number >= 0")
        if safety_filter is not None:
            if not isinstance(safety_filter, SafetyFilter):
                raise TypeError(f"safety_filter must be a SafetyFilter or None, got "
                                f"{type(safety_filter).__name__}")
            if safety_filter.n != self.layout.n_tethers:
                raise ValueError(f"the filter is for {safety_filter.n} tethers, the env has "
                                 f"{self.layout.n_tethers}")
        super().__init__(venv)
        self.base = base
        self.scale = float(scale)
        self.safety_filter = safety_filter
        self.filter_steps = 0
        self.filter_interventions = 0
        self._obs: np.ndarray | None = None
        self._infos: list[dict] = [{} for _ in range(self.num_envs)]
        self._result: FilterResult | None = None

    @classmethod
    def from_spec(cls, venv: VecEnv, spec: ResidualSpec) -> ResidualVecEnv:
        """The hybrid of ``spec`` on ``venv``: base law and filter on its nominal model.

        The nominal model is the env's configured e and masses (under domain
        randomisation the drawn values stay hidden from both), as ``evaluate.py``'s
        ``smc`` and ``smc_filtered`` use on scenarios without a ``nominal`` entry.
        """
        if not isinstance(spec, ResidualSpec):
            raise TypeError(f"spec must be a ResidualSpec, got {type(spec).__name__}")
        view = _config_view(venv)
        base = SlidingModeController.for_env(view)
        flt = SafetyFilter.for_env(view) if spec.filter else None
        return cls(venv, base, spec.scale, flt)

    # ------------------------------------------------------------------ #
    def reset(self) -> VecEnvObs:
        """Reset every sub-env; remember the observations and reset infos."""
        obs = self.venv.reset()
        self._obs = np.array(obs, copy=True)
        self._infos = [dict(i) for i in self._reset_infos()]
        self.reset_infos = list(self._reset_infos())
        return obs

    def _reset_infos(self) -> list[dict]:
        infos = getattr(self.venv, "reset_infos", None)
        inner = getattr(self.venv, "unwrapped", None)
        if inner is not None and inner is not self.venv:  # wrappers keep stale copies
            infos = getattr(inner, "reset_infos", infos)
        return list(infos) if infos is not None else [{} for _ in range(self.num_envs)]

    def commands(self, actions: np.ndarray) -> np.ndarray:
        """clip(base(obs) + scale * actions, -1, 1) (B, n) float64, before the filter."""
        if self._obs is None:
            raise RuntimeError("call reset() before step()")
        n = self.layout.n_tethers
        a = np.asarray(actions, dtype=np.float64)
        if a.size != self.num_envs * n:
            raise ValueError(f"actions must have shape ({self.num_envs}, {n}), got {a.shape}")
        base, _ = self.base.predict(self._obs, deterministic=True)
        base = np.asarray(base, dtype=np.float64).reshape(self.num_envs, n)
        return np.clip(base + self.scale * a.reshape(self.num_envs, n), -1.0, 1.0)

    def _states(self) -> tuple[np.ndarray, np.ndarray]:
        """(nu (B,), state rows (B, 4n)) of the sub-envs now: info where it has them."""
        assert self._obs is not None
        nu, y = state_from_observation(self.layout, np.asarray(self._obs))
        for i, info in enumerate(self._infos):
            if all(k in info for k in _STATE_KEYS):
                nu[i], y[i] = state_of(info)
        return nu, y

    def step_async(self, actions: np.ndarray) -> None:
        """Send the hybrid's commands for the residual ``actions`` to the wrapped env."""
        cmd = self.commands(actions)
        self._result = None
        if self.safety_filter is not None:
            nu, y = self._states()
            res = self.safety_filter.project(nu, y, cmd)
            self._result = res
            cmd = res.command
            self.filter_steps += int(res.active.shape[0])
            self.filter_interventions += int(res.active.sum())
        self.venv.step_async(cmd.astype(np.float32))

    def step_wait(self) -> VecEnvStepReturn:
        """Step; the returned observations become the base law's next input."""
        obs, rewards, dones, infos = self.venv.step_wait()
        res = self._result
        resets = self._reset_infos()
        for i, info in enumerate(infos):
            if res is None:
                info.update(filter_active=False, filter_correction=0.0, filter_feasible=True)
            else:
                info.update(filter_active=bool(res.active[i]),
                            filter_correction=float(res.correction[i]),
                            filter_feasible=bool(res.feasible[i]))
            self._infos[i] = resets[i] if dones[i] else info
            if dones[i]:
                self.reset_infos[i] = resets[i]
        self._obs = np.array(obs, copy=True)
        return obs, rewards, dones, infos

    def __repr__(self) -> str:
        return (f"ResidualVecEnv({self.venv!r}, base={self.base!r}, scale={self.scale}, "
                f"filtered={self.safety_filter is not None})")
