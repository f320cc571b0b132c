"""``tether_gym/TetherLibration-v1``: v2 without the cost entries of ``info``.

v2 adds the constraint cost (``info["cost"]`` and its parts, :mod:`tether_gym.tasks.cost`)
and the ``cost_thresholds`` argument; observations, actions, rewards, terminations and
trajectories are v1's, bitwise. v1 stays registered so that code and agent files made
for it get exactly what they got: the same compiled step, with the cost entries left
out of ``info`` (and ``cost_thresholds`` refused).
"""

from __future__ import annotations

from typing import Any

from ..tasks.cost import COST_NAMES
from .tether_libration import TetherLibrationEnv
from .vector import TetherLibrationVectorEnv

__all__ = ["TetherLibrationEnvV1", "TetherLibrationVectorEnvV1"]

_DROPPED = frozenset(COST_NAMES) | frozenset("_" + name for name in COST_NAMES)
"""The v2 ``info`` keys (and their vector-env masks) that v1 does not return."""


def _v1_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    if "cost_thresholds" in kwargs:
        raise ValueError("cost_thresholds is an argument of tether_gym/TetherLibration-v2; v1 "
                         "returns no cost (make the v2 env for a cost signal)")
    return kwargs


def _v1_info(info: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in info.items() if key not in _DROPPED}


class TetherLibrationEnvV1(TetherLibrationEnv):
    """TetherLibration-v1: :class:`TetherLibrationEnv` without the cost entries of ``info``."""

    def __init__(self, render_mode: str | None = None, **kwargs: Any):
        super().__init__(render_mode=render_mode, **_v1_kwargs(kwargs))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """v2's reset, without the cost entries of ``info``."""
        obs, info = super().reset(seed=seed, options=options)
        return obs, _v1_info(info)

    def step(self, action):
        """v2's step, without the cost entries of ``info``."""
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, reward, terminated, truncated, _v1_info(info)


class TetherLibrationVectorEnvV1(TetherLibrationVectorEnv):
    """TetherLibration-v1's vector env: no cost entries in ``info``."""

    def __init__(self, num_envs: int = 1, max_episode_steps: int | None = None,
                 render_mode: str | None = None, parallel: bool | str = "auto", **kwargs: Any):
        super().__init__(num_envs, max_episode_steps, render_mode, parallel,
                         **_v1_kwargs(kwargs))

    def _infos(self, mask):
        return _v1_info(super()._infos(mask))
