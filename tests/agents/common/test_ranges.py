"""A valid range in a message: whole-number bounds in full, so the largest value allowed
can be typed as read (before: ``:g`` wrote 2**31 - 1 as 2.14748e+09)."""

from __future__ import annotations

import math

import pytest

from tether_gym_agents.common.ranges import bound_text, interval
from tether_gym_agents.training.distill_cli import main as distill_main


@pytest.mark.parametrize("value, text", [
    (2**31 - 1, "2147483647"), (1 << 24, "16777216"), (1e10, "10000000000"), (0, "0"),
    (-20.0, "-20"), (1e-8, "1e-08"), (0.35, "0.35"), (math.inf, "inf"), (1e300, "1e+300"),
])
def test_bound_text(value, text):
    assert bound_text(value) == text


def test_a_written_integer_bound_reads_back_as_the_bound():
    for value in (2**31 - 1, 4194304, 10**15 + 1):
        assert int(bound_text(value)) == value


def test_interval():
    assert interval(1, 2**31 - 1) == "[1, 2147483647]"
    assert interval(1e-8, 1.0) == "[1e-08, 1]"


def test_distill_names_the_largest_seed_in_full(capsys):
    assert distill_main(["--seed", str(2**31), "--out", "/tmp/unused"]) == 2
    err = capsys.readouterr().err
    assert "[0, 2147483647]" in err, err
