"""Constraint cost of the libration task, v2 (pure function), for safe reinforcement learning.

The reward prices a tension margin; safe-RL methods instead take a separate cost
signal and a limit on its average (Safety-Gymnasium's ``cost``, a Lagrangian's
``cost_limit``). Each control step costs the number of constraints the chain came
near, each part an indicator in {0, 1}:

    cost = c_slack + c_length + c_tumble,

    c_slack  = 1 if min_i T^_i,min < T_c                        (T_c = ``tension``, 0.5)
    c_length = 1 if any l_i < f l_min or l_i > l_max / f        (f = ``length_factor``, 1.25)
    c_tumble = 1 if any |theta_i| >= g pi/2                     (g = ``tumble_fraction``, 0.5)

where T^_i,min [-] is the smallest normalised tension of tether i at the physics
substeps of the step (the quantity whose sign ends the episode as ``"slack"``),
(l_min, l_max) the env's ``length_bounds`` [-] and pi/2 [rad] the tumble angle of
:mod:`tether_gym.tasks.termination`. So the cost of a step is in {0, 1, 2, 3}, and the
step that terminates an episode costs at least 1 (a failure crosses the bound that
its part watches from inside). Its mean over an episode's steps is the fraction of the
episode spent near the failure bounds, counted once per constraint.

Why indicators: they are Safety-Gymnasium's convention (a hazard costs 1 while it is
touched), so a cost limit reads as a fraction of time, and they do not depend on the
reward's weights. T_c defaults to the reward's T_safe (0.5): a tension below half the
paper's nominal margin is where the reward's slack term starts to charge.

:data:`COST_LIMIT` is the benchmark's limit on the mean cost per step of an episode:
the evaluation reports the fraction of episodes above it, and the Lagrangian baseline
is trained against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from numba import njit

from ..params import check_range, weights_from_dict
from ..physics.jit import INLINE
from ..physics.layout import at
from ..physics.state import S
from .termination import TUMBLE_ANGLE

__all__ = ["CostThresholds", "CostParams", "COST_PARTS", "COST_NAMES", "COST_LIMIT",
           "cost_terms"]

COST_PARTS = ("slack", "length", "tumble")
"""The constraint parts, in the order of their ``info`` entries ``cost_<part>``."""
COST_NAMES = ("cost",) + tuple(f"cost_{part}" for part in COST_PARTS)
"""The ``info`` keys of the cost: the total, then its parts."""

COST_LIMIT = 0.01
"""The benchmark's limit on an episode's mean cost per step [-]: 1 % of its steps
near a failure bound (7.5 of the 754 steps of a default episode, about 0.03 orbit)."""


@dataclass(frozen=True)
class CostThresholds:
    """Where each cost part starts (the ``gym.make`` argument ``cost_thresholds``).

    Parameters
    ----------
    tension : float
        T_c [-], > 0: a step whose smallest normalised tension falls below it costs
        ``cost_slack`` = 1. Default 0.5, the reward's T_safe.
    length_factor : float
        f [-], in [1, 10]: a length within a factor f of a bound, l < f l_min or l >
        l_max / f, costs ``cost_length`` = 1. Default 1.25.
    tumble_fraction : float
        g [-], in (0, 1]: a libration |theta_i| >= g pi/2 [rad] costs ``cost_tumble`` = 1.
        Default 0.5 (45 degrees).
    """

    tension: float = 0.5
    length_factor: float = 1.25
    tumble_fraction: float = 0.5

    def __post_init__(self) -> None:
        check_range("tension", self.tension, 0.0, low_open=True)
        check_range("length_factor", self.length_factor, 1.0, 10.0)
        check_range("tumble_fraction", self.tumble_fraction, 0.0, 1.0, low_open=True)

    @classmethod
    def from_dict(cls, values: dict | CostThresholds | None) -> CostThresholds:
        """Build from a dict, rejecting unknown keys with the list of valid ones."""
        return weights_from_dict(cls, values, "cost_thresholds", "thresholds")

    def record(self, length_bounds: tuple[float, float]) -> CostParams:
        """The thresholds as the kernels take them, for the env's ``length_bounds`` [-]."""
        lo, hi = length_bounds
        return CostParams(tension=self.tension, length_low=lo * self.length_factor,
                          length_high=hi / self.length_factor,
                          tumble=self.tumble_fraction * TUMBLE_ANGLE)


class CostParams(NamedTuple):
    """:class:`CostThresholds` as a compiled-code record."""

    tension: float      # T_c [-]
    length_low: float   # f l_min [-]
    length_high: float  # l_max / f [-]
    tumble: float       # g pi/2 [rad]


@njit(**INLINE)
def cost_terms(y, n, tension_min, params, out):
    """Fill ``out`` (len(COST_NAMES)) with the cost and its parts; return the cost.

    ``y`` is the state row after the step, ``tension_min`` (n,) the smallest T^ of each
    tether during it.
    """
    slack = 0.0
    length = 0.0
    tumble = 0.0
    th = at(S.theta, n)
    ln = at(S.length, n)
    for j in range(n):
        if not tension_min[j] >= params.tension:  # NaN counts as slack
            slack = 1.0
        lj = y[ln + j]
        if not (params.length_low <= lj <= params.length_high):
            length = 1.0
        if not abs(y[th + j]) < params.tumble:
            tumble = 1.0
    out[1] = slack
    out[2] = length
    out[3] = tumble
    out[0] = slack + length + tumble
    return out[0]

