"""Gymnasium environments of tether_gym: the single env and its native vector env."""

from .config import EnvConfig
from .tether_libration import TetherLibrationEnv
from .vector import TetherLibrationVectorEnv

__all__ = ["EnvConfig", "TetherLibrationEnv", "TetherLibrationVectorEnv"]
