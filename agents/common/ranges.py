"""Ranges shared by several commands, and how a valid range is written in a message.

Python's ``:g`` keeps six significant digits, so an integer bound such as 2**31 - 1 read
"2.14748e+09": a user could not type the largest value allowed. :func:`interval` writes a
whole-number bound in full and any other bound with ``:g``.
"""

from __future__ import annotations

import math

__all__ = ["bound_text", "interval", "MAX_TORCH_THREADS"]

MAX_TORCH_THREADS = 256
"""Torch threads per process at most (``--torch-threads`` of train.py and evaluate.py):
torch crashed the process (segmentation fault) asked for 100,000."""


def bound_text(value: float) -> str:
    """``value`` in full when it is a whole number (below 1e16), else with ``:g``."""
    if math.isfinite(value) and float(value).is_integer() and abs(value) < 1e16:
        return str(int(value))
    return f"{value:g}"


def interval(low: float, high: float) -> str:
    """The closed range ``[low, high]`` as text, e.g. ``[0, 2147483647]``, ``[1e-08, 1]``."""
    return f"[{bound_text(low)}, {bound_text(high)}]"
