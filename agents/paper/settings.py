"""Settings of the paper reproduction (see the package docstring)."""

from __future__ import annotations

import math
from typing import Any

ORBIT = 2.0 * math.pi

OPEN_LOOP_SETTINGS: dict[str, Any] = {"control_step": 0.001, "physics_step": 0.001,
                      "reel_time_constant": 0.005, "accel_limit": None,
                      "max_reel_rate": 10.0}
"""Env arguments of the open-loop studies (no acceleration limit, as in the paper)."""

PAPER_SMC_SETTINGS: dict[str, Any] = {"control_step": 0.001, "physics_step": 0.001,
                                      "reel_time_constant": 0.001}
"""The paper's step for the sliding-mode run (Sec. 4.3: RK4, h = 0.001 rad)."""

DEFAULT_SMC_SETTINGS: dict = {}
"""The env's defaults (control step 0.025 rad, RK4 step 0.0125 rad, reel lag 0.0125 rad)."""

TABLE1_LENGTH = 0.5
"""l_i(0) [-] of Table 1."""

FIG5_AMPLITUDES = (0.1, 0.2, 0.3)
FIG6_AMPLITUDES = (0.5, 0.6, 0.7, 0.8, 0.9)
FIG6_ECCENTRICITY = 0.7
PLOT_EXTRA = 'pip install "matplotlib>=3.7"'
