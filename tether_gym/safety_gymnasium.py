"""Safety-Gymnasium's step convention for the libration envs: the cost as its own return.

Safety-Gymnasium's environments, and the safe-RL code written for them (OmniSafe's
PPO-Lagrangian, CPO, PID-Lagrangian, ...), step as

    obs, reward, cost, terminated, truncated, info = env.step(action)

while a gymnasium env returns five values. ``tether_gym/TetherLibration-v2`` reports its
constraint cost in ``info["cost"]`` (with its parts ``cost_slack``, ``cost_length`` and
``cost_tumble``; definition in :mod:`tether_gym.tasks.cost` and docs/safe_rl.md), which
is where Safety-Gymnasium's own ``SafetyGymnasium2Gymnasium`` wrapper puts it.
:class:`SafetyGymnasiumStep` is the reverse, Safety-Gymnasium's
``Gymnasium2SafetyGymnasium``: ``step`` returns the 6-tuple with ``cost =
float(info["cost"])`` and leaves ``info`` as it is; ``reset`` is unchanged.
:class:`SafetyGymnasiumVectorStep` does the same for the vector env, the costs a
(num_envs,) float64 array (Safety-Gymnasium's vector envs return them so).

Neither depends on Safety-Gymnasium or OmniSafe, and they follow the conventions of
their releases instead: safety-gymnasium 1.0.0 (July 2023) declares
``Requires-Dist: gymnasium (==0.28.1)`` (with ``mujoco (==2.3.3)`` and ``pygame
(==2.1.0)``), and omnisafe 0.5.0 ``Requires-Dist: safety-gymnasium >=0.2.0``, whose
every release from 0.2.0 to 1.0.0 pins gymnasium 0.26.3 or 0.28.1; so neither installs
beside the gymnasium 1.x this package needs (pip: "ResolutionImpossible ...
safety-gymnasium 1.0.0 depends on gymnasium==0.28.1"). A rollout loop written for
Safety-Gymnasium's step runs on these wrappers unchanged. OmniSafe's learners take
their envs through its own registry (``omnisafe.envs.core.CMDP`` subclasses on torch
tensors, the same 6-tuple), which this package does not provide: it imports no torch.

A wrapper of the 6-tuple must stay the outermost: gymnasium's own wrappers (TimeLimit,
RecordEpisodeStatistics, ...) expect five values, so put them inside it.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["SafetyGymnasiumStep", "SafetyGymnasiumVectorStep", "NO_COST"]

NO_COST = ("{where} has no 'cost' entry, which the Safety-Gymnasium step takes its cost "
           "from: wrap an env that reports one, gym.make(\"tether_gym/TetherLibration-v2\") "
           "(v1 reports no cost)")
"""The message of an ``info`` without a cost (``where`` names it)."""


def _require_cost(info: dict, where: str) -> Any:
    """``info["cost"]``, or a ValueError that says which env reports one."""
    try:
        return info["cost"]
    except (KeyError, TypeError):
        raise ValueError(NO_COST.format(where=where)) from None


class SafetyGymnasiumStep(gym.Wrapper):
    """An env whose ``step`` returns ``(obs, reward, cost, terminated, truncated, info)``.

    Safety-Gymnasium's step (its ``Gymnasium2SafetyGymnasium``): ``cost`` [-] is
    ``float(info["cost"])``, the step's constraint cost (for v2, an integer in {0, 1, 2,
    3}: the number of failure bounds the chain came near; :mod:`tether_gym.tasks.cost`).
    ``info`` is passed on unchanged, so its parts stay readable. ``reset`` is the env's.

    Parameters
    ----------
    env : gymnasium.Env
        An env whose ``info`` holds ``"cost"``, e.g.
        ``gym.make("tether_gym/TetherLibration-v2")``.

    Raises
    ------
    ValueError
        From ``reset`` or ``step``, when the env's ``info`` has no ``"cost"`` (v1).
    """

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """The env's reset; refuses an env that reports no cost before the first step."""
        obs, info = self.env.reset(seed=seed, options=options)
        _require_cost(info, "the env's reset info")
        return obs, info

    def step(self, action):  # Safety-Gymnasium's 6-tuple, not gymnasium's 5
        """One step: ``(obs, reward, cost, terminated, truncated, info)``."""
        obs, reward, terminated, truncated, info = self.env.step(action)
        cost = float(_require_cost(info, "the env's step info"))
        return obs, reward, cost, terminated, truncated, info


class SafetyGymnasiumVectorStep(gym.vector.VectorWrapper):
    """A vector env whose ``step`` returns the costs after the rewards (Safety-Gymnasium's).

    The vector form of :class:`SafetyGymnasiumStep`: ``costs`` is ``infos["cost"]`` as a
    (num_envs,) float64 array (a copy; Safety-Gymnasium's vector envs return them so).
    A sub-env reset by the autoreset step reports its reset cost, 0.

    Parameters
    ----------
    env : gymnasium.vector.VectorEnv
        A vector env whose ``infos`` hold ``"cost"``, e.g.
        ``gym.make_vec("tether_gym/TetherLibration-v2", num_envs=8)``.

    Raises
    ------
    ValueError
        From ``reset`` or ``step``, when the infos have no ``"cost"``.
    """

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        """The vector env's reset (an int or one seed per sub-env); refuses one without cost."""
        obs, infos = self.env.reset(seed=seed, options=options)
        _require_cost(infos, "the vector env's reset infos")
        return obs, infos

    def step(self, actions):  # Safety-Gymnasium's 6-tuple, not gymnasium's 5
        """Step every sub-env: ``(obs, rewards, costs, terminations, truncations, infos)``."""
        obs, rewards, terminations, truncations, infos = self.env.step(actions)
        costs = np.array(_require_cost(infos, "the vector env's step infos"), dtype=np.float64)
        return obs, rewards, costs, terminations, truncations, infos
