"""Gymnasium environments of tether_gym."""

from .config import EnvConfig
from .tether_libration import TetherLibrationEnv

__all__ = ["EnvConfig", "TetherLibrationEnv"]
