"""Residual RL on top of the sliding-mode law: the training side of the hybrid.

The hybrid commands

    u = filter(clip(u_base(obs) + scale * a_rl, -1, 1))

with u_base the paper's sliding-mode law
(:class:`~tether_gym_agents.baselines.smc.SlidingModeController`)
designed on the env's *nominal* model, a_rl in [-1, 1]^n the learned residual and
``filter`` the optional model-based safety filter (:class:`tether_gym.safety.SafetyFilter`,
predicting on the same nominal model). :class:`ResidualVecEnv` puts everything but a_rl
inside a stable-baselines3 vector env, so any algorithm of the table
(:data:`~tether_gym_agents.common.algorithms.ALGORITHMS`) learns a_rl on it unchanged; at
evaluation :class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` computes the same sum
around the trained agent.

**The filter's input is the observation**, at training as at evaluation: both filter
through :class:`tether_gym.wrappers.FilterInTheLoop` at the state read from the
observation (:meth:`~tether_gym_agents.common.obs.ObservationLayout.state`: float32,
with the env's ``obs_noise``), so the residual learns behind the filter it is
evaluated behind. Earlier versions of this module gave the filter the true state from
the env's ``info`` instead, and the shipped ``smc_residual`` seeds were trained so
(their evaluation is the same as ever). The difference, measured on the training distribution of
``ppo_residual.yml`` (``obs_noise`` 1e-3; 8 envs x 1600 steps = 12 800 states,
stepping with the true-state filter) by projecting the same desired command from both
inputs: with shipped seed 0 as the residual, the filter intervened on 0.69 % of the
states (true state) and 0.70 % (observation), the two inputs disagreed on whether to
intervene on 0.10 % and gave different commands on 0.74 % (largest |du| per state:
median 1.5e-3, 90th percentile 0.02, at most 1 where one side found no feasible
command); with an untrained residual (std e^-3.5) 2.0 % interventions, 0.33 %
disagreement, 1.9 % different commands (median 1.5e-3; the 0.22 % of states where one
side finds no feasible command differ by up to 1.7).

:class:`~tether_gym_agents.hybrids.residual_spec.ResidualSpec` (re-exported here) is the
plain-data description of a hybrid: the ``residual`` key of a training config, the
``"hybrid"`` entry of ``agent.json``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from tether_gym.envs.config import env_config
from tether_gym.safety import SafetyFilter
from tether_gym.wrappers import INFO_KEYS, FilterInTheLoop

from ..baselines.smc import SlidingModeController
from ..common.obs import ObservationLayout, require_predict
from ..hybrids.residual_spec import DEFAULT_SCALE, BaseLaw, ResidualSpec, check_scale

__all__ = ["BaseLaw", "ResidualSpec", "ResidualVecEnv", "DEFAULT_SCALE", "INFO_KEYS"]


def _config_view(venv: VecEnv) -> SimpleNamespace:
    """An object with the TetherLibration ``config`` and nominal ``model`` of ``venv``."""
    cfg = env_config(venv)
    return SimpleNamespace(config=cfg, model=cfg.model)


class ResidualVecEnv(VecEnvWrapper):
    """SB3 vector env whose action is the residual a_rl of the hybrid (module docstring).

    On every step the base law's action is computed for all sub-envs in one batch from
    their current observations (after an auto-reset: the new episode's first
    observation, which SB3 returns in place of the terminal one), ``scale * action`` is
    added, the sum is clipped to [-1, 1], filtered when a filter is given, cast to
    float32 (as :class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` returns it) and sent
    to the wrapped env. ``infos[i]`` gets :data:`INFO_KEYS` of that step (the
    declaration of :mod:`tether_gym.wrappers`).

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
        Filter of the summed command (None: unfiltered). It predicts from the state read
        from each sub-env's observation (:meth:`ObservationLayout.state`), as the
        evaluated :class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` does
        (module docstring).

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
    ``filter_interventions`` (of those, the ones the filter changed); ``loop`` is the
    :class:`~tether_gym.wrappers.FilterInTheLoop` that keeps them.
    """

    def __init__(self, venv: VecEnv, base, scale: float,
                 safety_filter: SafetyFilter | None = None):
        self.layout = ObservationLayout.from_env(venv)
        self.layout.require_rate_mode(type(self).__name__)
        self.base = require_predict("base", base)
        self.scale = check_scale(scale)
        self.loop = FilterInTheLoop(safety_filter, self.layout.n_tethers)
        super().__init__(venv)
        self._obs: np.ndarray | None = None

    @property
    def safety_filter(self) -> SafetyFilter | None:
        """The filter of the summed command (None: unfiltered)."""
        return self.loop.safety_filter

    @property
    def filter_steps(self) -> int:
        """Filtered commands so far."""
        return self.loop.steps

    @property
    def filter_interventions(self) -> int:
        """Of those, the ones the filter changed."""
        return self.loop.interventions

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
        """Reset every sub-env; remember the observations and pass the reset infos on."""
        obs = self.venv.reset()
        self._obs = np.array(obs, copy=True)
        self.reset_infos = self._reset_infos()
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

    def step_async(self, actions: np.ndarray) -> None:
        """Send the hybrid's commands for the residual ``actions`` to the wrapped env."""
        cmd = self.commands(actions)
        obs = self._obs
        assert obs is not None  # commands() checked it
        cmd = self.loop(lambda: self.layout.state(obs), cmd)
        self.venv.step_async(cmd.astype(np.float32))

    def step_wait(self) -> VecEnvStepReturn:
        """Step; the returned observations become the base law's next input."""
        obs, rewards, dones, infos = self.venv.step_wait()
        resets = self._reset_infos()
        for i, info in enumerate(infos):
            info.update(self.loop.info(i))
            if dones[i]:
                self.reset_infos[i] = resets[i]
        self._obs = np.array(obs, copy=True)
        return obs, rewards, dones, infos

    def __repr__(self) -> str:
        return (f"ResidualVecEnv({self.venv!r}, base={self.base!r}, scale={self.scale}, "
                f"filtered={self.safety_filter is not None})")
