"""The plain-data description of a residual hybrid (no heavy imports).

A :class:`ResidualSpec` is the ``residual`` key of a training config
(``agents/configs/ppo_residual.yml``), the ``"hybrid"`` entry of an ``agent.json`` and
:attr:`tether_gym_agents.files.trained.TrainedAgent.hybrid`;
:mod:`tether_gym_agents.training.residual_env`
trains the hybrid it describes and :mod:`tether_gym_agents.evaluation.benchmark` evaluates it.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from enum import Enum
from typing import Any

from ..common.jsonio import checked_mapping

__all__ = ["BaseLaw", "ResidualSpec", "DEFAULT_SCALE", "check_scale"]

DEFAULT_SCALE = 0.2
"""Default weight of the residual [-] (see ``agents/configs/ppo_residual.yml``)."""


def check_scale(value: Any, name: str = "scale") -> float:
    """``float(value)`` after checking it is a weight of the residual: finite and >= 0.

    Raises
    ------
    ValueError
        For a bool, a non-number, NaN, inf or a negative number; the message names
        ``name`` and the value.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(value) or value < 0:
        raise ValueError(f"{name} {value!r} must be a finite number >= 0")
    return float(value)


class BaseLaw(Enum):
    """The model-based law under the residual."""

    SMC = "smc"


@dataclass(frozen=True)
class ResidualSpec:
    """What a residual hybrid is made of (plain data).

    Parameters
    ----------
    base : BaseLaw
        The base law (``"smc"``: the paper's sliding-mode law, default gains).
    scale : float
        Weight of the residual [-], finite and >= 0 (0: the base law alone).
    filter : bool
        Whether the summed command goes through the safety filter.
    """

    base: BaseLaw = BaseLaw.SMC
    scale: float = DEFAULT_SCALE
    filter: bool = True

    KEYS = ("base", "scale", "filter")

    @classmethod
    def from_dict(cls, data: Any, what: str = "residual") -> ResidualSpec:
        """Validate a mapping ``{base, scale, filter}`` (all optional; defaults above).

        Raises
        ------
        ValueError
            For a non-mapping, an unknown key or a bad value; the message names ``what``,
            the key and the valid keys or values.
        """
        data = checked_mapping(data, cls.KEYS, what)
        valid_bases = [b.value for b in BaseLaw]
        base = data.get("base", cls.base.value)
        if base not in valid_bases:
            raise ValueError(f"{what}: base {base!r} is not one of {valid_bases}")
        scale = check_scale(data.get("scale", cls.scale), f"{what}: scale")
        use_filter = data.get("filter", cls.filter)
        if not isinstance(use_filter, bool):
            raise ValueError(f"{what}: filter {use_filter!r} must be true or false")
        return cls(BaseLaw(base), scale, use_filter)

    def to_dict(self) -> dict:
        """The JSON/YAML form: ``{"base": "smc", "scale": 0.2, "filter": true}``."""
        return {"base": self.base.value, "scale": self.scale, "filter": self.filter}
