"""``python train.py``: train a PPO or SAC agent, one seed or a fan-out of seeds."""

from ..training.train import main

__all__ = ["main"]
