"""Baselines and RL agents for tether_gym (installed as ``tether_gym_agents``).

The repository keeps this package in ``agents/``; it is installed under the name
``tether_gym_agents`` so that it cannot clash with other top-level ``agents``
packages. ``tether_gym`` itself never imports it.

Evaluate a controller of your own beside the shipped ones: register it with
:func:`register_policy` and score it with :func:`evaluate` (or ``evaluate.py NAME``
through :func:`tether_gym_agents.cli.evaluate.main`). Importing the package loads
neither torch nor stable-baselines3.

Subpackages, from the bottom up (imports only go down): ``common``, ``baselines``,
``hybrids``, ``files``, then ``evaluation``, ``training`` and ``accel`` (siblings),
``paper``, ``cli``. What each holds, module by module: the diagram of
docs/architecture.md (the one list of modules).
"""

from .baselines.open_loop import AngleSource, PeriodicReel, RandomPolicy, ZeroStateReel
from .baselines.smc import SlidingModeController
from .common.obs import ObservationLayout, ReelRatePolicy
from .evaluation.benchmark import EvalOptions, evaluate
from .evaluation.registry import PolicyKind, register_policy

__all__ = [
    "SlidingModeController",
    "ZeroStateReel",
    "PeriodicReel",
    "AngleSource",
    "RandomPolicy",
    "ReelRatePolicy",
    "ObservationLayout",
    "register_policy",
    "PolicyKind",
    "evaluate",
    "EvalOptions",
]
