"""Baselines and RL agents for tether_gym (installed as ``tether_gym_agents``).

The repository keeps this package in ``agents/``; it is installed under the name
``tether_gym_agents`` so that it cannot clash with other top-level ``agents``
packages. ``tether_gym`` itself never imports it.
"""

from .baselines.open_loop import AngleSource, PeriodicReel, RandomPolicy, ZeroStateReel
from .baselines.smc import SlidingModeController
from .common.obs import ObservationLayout, ReelRatePolicy

__all__ = [
    "SlidingModeController",
    "ZeroStateReel",
    "PeriodicReel",
    "AngleSource",
    "RandomPolicy",
    "ReelRatePolicy",
    "ObservationLayout",
]
