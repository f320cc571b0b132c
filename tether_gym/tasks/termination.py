"""Why an episode ends early: slack, tumbling, lengths out of bounds, non-finite state.

Pure functions of the state; the environments call :func:`failure_code` once per
control step. Codes are the values of :class:`Failure` (0 = healthy).
"""

from __future__ import annotations

import math
from enum import IntEnum

from numba import njit

from ..physics.jit import INLINE
from ..physics.layout import at
from ..physics.state import S

__all__ = ["Failure", "failure_code", "TUMBLE_ANGLE"]

TUMBLE_ANGLE = 0.5 * math.pi
"""|theta_i| >= pi/2 [rad]: the body has swung above the horizontal (tumbling)."""


class Failure(IntEnum):
    """Reason an episode terminated; ``str(Failure.SLACK) == "slack"``."""

    NONE = 0
    NONFINITE = 1
    SLACK = 2
    TUMBLE = 3
    LENGTH = 4
    DIVERGED = 5

    def __str__(self) -> str:
        return self.name.lower()

    @property
    def label(self) -> str | None:
        """The ``info["failure"]`` value: None while healthy, else the lower-case name."""
        return None if self is Failure.NONE else str(self)


DIVERGENCE_BOUND = 1.0e6
"""|y_i| or |T^_i| beyond this [-] is a diverged integration, not a physical state: a
healthy chain keeps every entry of order one (and an entry beyond float32's range would
turn into inf in the observation)."""

KEEP_PREVIOUS = (int(Failure.NONFINITE), int(Failure.DIVERGED))
"""Codes after which the env keeps the last healthy state (and gives the lowest reward)."""


@njit(**INLINE)
def failure_code(y, tension_min, length_min, length_max):
    """Failure code of one state row y = [theta, theta', l, l'] (checked in this order).

    * NONFINITE: any entry of y or of the tensions is NaN or inf;
    * DIVERGED: any entry of y or of the tensions beyond +-DIVERGENCE_BOUND;
    * SLACK: any T^_i <= 0 at a substep boundary of the last control step;
    * TUMBLE: any |theta_i| >= pi/2;
    * LENGTH: any l_i outside [length_min, length_max].
    """
    n = tension_min.shape[0]
    for i in range(y.shape[0]):
        if not math.isfinite(y[i]):
            return 1
    for j in range(n):
        if not math.isfinite(tension_min[j]):
            return 1
    for i in range(y.shape[0]):
        if abs(y[i]) > DIVERGENCE_BOUND:
            return 5
    for j in range(n):
        if abs(tension_min[j]) > DIVERGENCE_BOUND:
            return 5
    for j in range(n):
        if tension_min[j] <= 0.0:
            return 2
    th = at(S.theta, n)
    ln = at(S.length, n)
    for j in range(n):
        if abs(y[th + j]) >= TUMBLE_ANGLE:
            return 3
    for j in range(n):
        lj = y[ln + j]
        if lj < length_min or lj > length_max:
            return 4
    return 0
