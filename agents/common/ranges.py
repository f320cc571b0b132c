"""How a valid range is written in an error or help message.

Python's ``:g`` keeps six significant digits, so an integer bound such as 2**31 - 1 read
"2.14748e+09": a user could not type the largest value allowed. :func:`interval` writes a
whole-number bound in full and any other bound with ``:g``.
"""

from __future__ import annotations

import math

__all__ = ["bound_text", "interval"]


def bound_text(value: float) -> str:
    """``value`` in full when it is a whole number (below 1e16), else with ``:g``."""
    if math.isfinite(value) and float(value).is_integer() and abs(value) < 1e16:
        return str(int(value))
    return f"{value:g}"


def interval(low: float, high: float) -> str:
    """The closed range ``[low, high]`` as text, e.g. ``[0, 2147483647]``, ``[1e-08, 1]``."""
    return f"[{bound_text(low)}, {bound_text(high)}]"
