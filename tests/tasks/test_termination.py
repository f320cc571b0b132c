"""failure_code: each reason, and their order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_gym.tasks.termination import Failure, failure_code


def _row(theta=(0.1, 0.0), length=(0.5, 0.5)):
    return np.array([*theta, 0.2, 0.2, *length, 0.0, 0.0])


@pytest.mark.parametrize(("y", "tension", "expected"), [
    (_row(), (1.0, 1.0), Failure.NONE),
    (_row(theta=(math.nan, 0.0)), (1.0, 1.0), Failure.NONFINITE),
    (_row(), (1.0, math.inf), Failure.NONFINITE),
    (_row(), (1.0, 0.0), Failure.SLACK),
    (_row(theta=(0.0, -math.pi / 2)), (1.0, 1.0), Failure.TUMBLE),
    (_row(theta=(0.0, math.pi / 2 - 1e-12)), (1.0, 1.0), Failure.NONE),
    (_row(length=(0.5, 0.049)), (1.0, 1.0), Failure.LENGTH),
    (_row(length=(1.51, 0.5)), (1.0, 1.0), Failure.LENGTH),
    (_row(theta=(2.0, 0.0), length=(2.0, 0.5)), (-1.0, 1.0), Failure.SLACK),  # first reason
])
def test_failure_codes(y, tension, expected):
    assert failure_code(y, np.asarray(tension, dtype=float), 0.05, 1.5) == expected


def test_labels():
    assert Failure.NONE.label is None
    assert [f.label for f in Failure][1:] == ["nonfinite", "slack", "tumble", "length",
                                              "diverged"]
