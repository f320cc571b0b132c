"""Input features that a trained policy computes from the env's observation.

A policy's network may see, besides the observation of ``TetherLibration``, features
computed from it by a fixed, named function: they are part of the policy (like the
observation normalisation), not of the env, so the env and its id do not change. A
:class:`FeatureSpec` names them; it is the ``features`` key of a training config, the
``"features"`` entry of an ``agent.json`` and :attr:`TrainedAgent.features
<tether_gym_agents.files.trained.TrainedAgent>`. Files hold only the name and numbers, never
code.

The one feature set, ``symlog_errors``, appends for each tether i

    symlog(e_i / S),  symlog(e_i' / S),    symlog(x) = sign(x) ln(1 + |x|),

from the observation's tracking errors e_i = theta_i - theta_d [rad] and
e_i' = theta_i' - theta_d' [rad/rad], with the scale S [rad] (the same number in
[rad/rad] for e_i'). Why: the observation normalisation divides e_i by its
training-time standard deviation (about 0.04 rad, set by the first-orbit transient),
which leaves errors of 1e-3 to 1e-2 rad, the benchmark's precision range, within about
0.2 of a unit of the network's input. The logarithm spreads that range over a unit
or more, and stays linear below S (docs/task_design.md, "Errors on a log scale").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tether_gym.envs.layout import OBSERVATION

from .jsonio import checked_mapping

__all__ = ["FeatureSpec", "FEATURE_SETS", "add_features"]

FEATURE_SETS = ("symlog_errors",)
"""Names of the feature sets a spec may name."""


@dataclass(frozen=True)
class FeatureSpec:
    """Which features a policy appends to its observation (plain data).

    Parameters
    ----------
    name : str
        One of :data:`FEATURE_SETS`.
    scale : float
        S [rad] of symlog(e / S): finite and > 0.
    """

    name: str = "symlog_errors"
    scale: float = 1.0e-3

    KEYS = ("name", "scale")

    @classmethod
    def from_dict(cls, data: Any, what: str = "features") -> FeatureSpec:
        """Validate a mapping ``{name, scale}`` (``scale`` optional).

        Raises
        ------
        ValueError
            For a non-mapping, an unknown key or a bad value; the message names ``what``,
            the key and the valid keys or values.
        """
        data = checked_mapping(data, cls.KEYS, what)
        name = data.get("name")
        if name not in FEATURE_SETS:
            raise ValueError(f"{what}: name {name!r} is not one of {list(FEATURE_SETS)}")
        scale = data.get("scale", cls.scale)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) \
                or not math.isfinite(scale) or scale <= 0:
            raise ValueError(f"{what}: scale {scale!r} must be a finite number > 0 [rad]")
        return cls(name, float(scale))

    def to_dict(self) -> dict:
        """The JSON/YAML form: ``{"name": "symlog_errors", "scale": 0.001}``."""
        return {"name": self.name, "scale": self.scale}

    def size(self, n_tethers: int) -> int:
        """Entries appended to an observation of n tethers."""
        return 2 * n_tethers


def add_features(spec: FeatureSpec | None, obs: np.ndarray, n_tethers: int) -> np.ndarray:
    """``obs`` (..., D) followed by the features of ``spec`` (float32); ``obs`` if None.

    ``obs`` is the env's observation of n tethers (OBSERVATION layout, any optional
    groups after the errors).
    """
    if spec is None:
        return obs
    sl = OBSERVATION.slices(n_tethers)
    e = obs[..., sl["error"]].astype(np.float64)
    de = obs[..., sl["derror"]].astype(np.float64)
    s = spec.scale
    extra = np.concatenate([np.sign(e) * np.log1p(np.abs(e) / s),
                            np.sign(de) * np.log1p(np.abs(de) / s)], axis=-1)
    return np.concatenate([obs, extra.astype(np.float32)], axis=-1)
