"""Task layer: reference librations, open-loop reel laws, reward and termination."""

from .reference import (
    desired_libration,
    periodic_length_small_amplitude,
    periodic_reel_rate,
    tension_positivity_polynomial,
    zero_state_length,
    zero_state_reel_rate,
)
from .reward import COMPONENTS, PENALTIES, RewardWeights, reward_terms
from .termination import Failure, failure_code

__all__ = [
    "desired_libration",
    "zero_state_reel_rate",
    "zero_state_length",
    "periodic_reel_rate",
    "periodic_length_small_amplitude",
    "tension_positivity_polynomial",
    "RewardWeights",
    "reward_terms",
    "COMPONENTS",
    "PENALTIES",
    "Failure",
    "failure_code",
]
