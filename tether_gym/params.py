"""Validated, immutable parameters of the tethered chain and its orbit.

The model is dimensionless (Shi, Zhu & Zhu (2019), Sec. 2);
:class:`tether_gym.physics.scales.Scales` is the one object that converts between
SI units and the dimensionless variables:

=============================  ===============================  =====================
quantity                       dimensionless form               scale
=============================  ===============================  =====================
independent variable           true anomaly nu [rad]            time t = t(nu)
tether length L_i [m]          l_i = L_i / L0 [-]               L0 (initial total)
reel rate dL_i/dt [m/s]        l_i' = dl_i/dnu [-]              nu_dot * L0
reel accel d2L_i/dt2 [m/s^2]   see :func:`physics.orbit`        L0 * n^2
mass m_i [kg]                  M_i = m_i / m_tot [-]            m_tot (subsatellites)
tension T_i [N]                T^_i = T_i/(nu_dot^2 L0 m_tot)   nu_dot^2 L0 m_tot
=============================  ===============================  =====================

``n = sqrt(mu / p^3)`` is the orbit's rate scale [rad/s]; ``nu_dot = n k^2`` with
``k = 1 + e cos(nu)`` (docs/model.md, "Dimensionless variables").
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from enum import Enum

import numpy as np

__all__ = [
    "EARTH_MU",
    "Gravity",
    "OrbitParams",
    "ChainParams",
    "ReelParams",
    "check_masses",
    "check_lengths",
    "check_finite",
    "check_range",
    "check_count",
    "as_float_tuple",
    "renamed_error",
]

EARTH_MU = 3.986004418e14
"""Earth's gravitational parameter mu [m^3/s^2] (398600.4418 km^3/s^2)."""


class Gravity(str, Enum):
    """Gravity model of the subsatellites relative to the main satellite.

    ``GRADIENT``: the potential expanded to second order in L/r (the model behind
    the paper's Eqs. 7 and 10); the dimensionless equations depend on e and M_i only.
    ``FULL``: exact inverse-square gravity; needs ``length_ratio = L0 / p``.
    """

    GRADIENT = "gradient"
    FULL = "full"

    @classmethod
    def parse(cls, value: str | Gravity) -> Gravity:
        """The model named by ``value`` (case-insensitive); TypeError/ValueError otherwise."""
        if isinstance(value, Gravity):
            return value
        if not isinstance(value, str):
            raise TypeError(f"gravity must be a str, got {type(value).__name__} {value!r}")
        try:
            return cls(value.lower())
        except ValueError:
            valid = ", ".join(repr(g.value) for g in cls)
            raise ValueError(f"gravity={value!r} is not one of {valid}") from None


def check_finite(name: str, value) -> None:
    """Raise ValueError if ``value`` holds NaN or inf."""
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}={value!r} must be finite (no NaN or inf)")


def check_count(name: str, value, low: int, high: int, why: str) -> int:
    """``value`` as an int in [low, high] (``why``: what the range means, for the message).

    Raises TypeError for a value that is not an integer (a bool, float or string) and
    ValueError for one outside the range.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an int, got {type(value).__name__} {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{name}={value!r} must be in [{low}, {high}] ({why})")
    return int(value)


def check_range(
    name: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``float(value)`` after checking it is a finite real in the given range.

    Raises
    ------
    TypeError
        If ``value`` is not a real number.
    ValueError
        If it is NaN, inf or outside the range; the message names the value and the
        valid range.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    v = float(value)
    lo_br = "(" if low_open else "["
    hi_br = ")" if high_open else "]"
    rng = f"{lo_br}{'-inf' if low is None else low}, {'inf' if high is None else high}{hi_br}"
    if not math.isfinite(v):
        raise ValueError(f"{name}={value!r} must be finite; valid range {rng}")
    bad_low = low is not None and (v <= low if low_open else v < low)
    bad_high = high is not None and (v >= high if high_open else v > high)
    if bad_low or bad_high:
        raise ValueError(f"{name}={value!r} is outside the valid range {rng}")
    return v


def as_float_tuple(name: str, value, length: int | None = None) -> tuple[float, ...]:
    """Convert a sequence to a tuple of finite floats, checking its length.

    Raises TypeError naming ``name`` for anything but a sequence of real numbers (bools,
    strings and complex numbers included).
    """
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise TypeError(f"{name}={value!r} must be a sequence of numbers, got "
                        f"{type(value).__name__}")
    try:
        raw = np.asarray(value)
    except ValueError as exc:  # ragged nesting
        raise ValueError(f"{name}={value!r} must be a flat sequence of numbers: {exc}") from None
    if raw.dtype.kind not in "iuf" or any(
            isinstance(x, (bool, np.bool_)) for x in np.ravel(np.asarray(value, dtype=object))):
        raise TypeError(f"{name}={value!r} must hold real numbers (no bools, strings or "
                        "complex numbers)")
    arr = raw.astype(float)
    if arr.ndim != 1:
        raise ValueError(f"{name}={value!r} must be one-dimensional, got shape {arr.shape}")
    if length is not None and arr.shape[0] != length:
        raise ValueError(f"{name}={value!r} must have {length} entries, got {arr.shape[0]}")
    check_finite(name, arr)
    return tuple(float(x) for x in arr)


def renamed_error(exc: Exception, names: Mapping[str, str], prefix: str = "") -> Exception:
    """``exc`` (a TypeError or ValueError of these checks) told in the caller's names.

    The checks above begin their message with the name they were given (``"name=value
    ..."`` or ``"name must ..."``). A message that begins with a key of ``names`` gets
    that key replaced by its value (a field of a part by the argument a user passed,
    ``time_constant`` by ``reel_time_constant``); any other message gets ``prefix`` put
    in front. Returns a new exception of the same type (``exc`` itself when nothing
    changes).
    """
    message = str(exc)
    for field, name in names.items():
        if re.match(rf"{re.escape(field)}(=| must )", message):
            return type(exc)(name + message[len(field):])
    return type(exc)(prefix + message) if prefix else exc


def check_masses(masses, n: int | None = None) -> tuple[float, ...]:
    """Subsatellite masses as a tuple of floats, each > 0 (n of them when given)."""
    masses = as_float_tuple("masses", masses, n)
    if len(masses) < 1:
        raise ValueError(f"masses={masses!r}: need at least one subsatellite (N >= 2)")
    if min(masses) <= 0.0:
        raise ValueError(f"masses={masses!r} must all be > 0")
    return masses


def check_lengths(name: str, lengths, n: int | None = None) -> tuple[float, ...]:
    """Tether lengths l_i [-] as a tuple of floats, each > 0 (n of them when given)."""
    lengths = as_float_tuple(name, lengths, n)
    if not lengths or min(lengths) <= 0.0:
        raise ValueError(f"{name}={lengths!r} must all be > 0")
    return lengths


@dataclass(frozen=True)
class OrbitParams:
    """Keplerian orbit of the main satellite.

    Parameters
    ----------
    eccentricity : float
        e [-], in [0, 1).
    semi_latus_rectum : float
        p [m] (the paper's focal parameter), > 0. Paper Table 1: 8520 km.
    mu : float
        Gravitational parameter [m^3/s^2], > 0. Default: Earth's.
    """

    eccentricity: float = 0.2
    semi_latus_rectum: float = 8.52e6
    mu: float = EARTH_MU

    def __post_init__(self) -> None:
        check_range("eccentricity", self.eccentricity, 0.0, 1.0, high_open=True)
        check_range("semi_latus_rectum", self.semi_latus_rectum, 0.0, low_open=True)
        check_range("mu", self.mu, 0.0, low_open=True)

    @property
    def rate_scale(self) -> float:
        """n = sqrt(mu / p^3) [rad/s]; nu_dot = n k^2."""
        return math.sqrt(self.mu / self.semi_latus_rectum**3)

    @property
    def period(self) -> float:
        """Orbital period 2 pi / sqrt(mu / a^3) with a = p / (1 - e^2) [s]."""
        a = self.semi_latus_rectum / (1.0 - self.eccentricity**2)
        return 2.0 * math.pi * math.sqrt(a**3 / self.mu)


@dataclass(frozen=True)
class ChainParams:
    """The tethered chain: subsatellite masses, tether lengths and gravity model.

    Parameters
    ----------
    masses : tuple of float
        m_1 ... m_{N-1} in any common unit, each > 0 (normalised to M_i = m_i / m_tot).
        Paper Table 1: M1/M2 = 0.5, i.e. (1, 2).
    initial_lengths : tuple of float
        l_i(0) = L_i(0) / L0 [-], each > 0, one per tether. Table 1: (0.5, 0.5).
    total_tether_length : float
        L0 [m], the initial total tether length, > 0. The paper gives none; 20 km
        reproduces its Sec. 4.3 results
        (docs/model.md#parameters-the-paper-does-not-give).
    gravity : Gravity or str
        ``"gradient"`` (default) or ``"full"``.
    """

    masses: tuple[float, ...] = (1.0, 2.0)
    initial_lengths: tuple[float, ...] = (0.5, 0.5)
    total_tether_length: float = 2.0e4
    gravity: Gravity = Gravity.GRADIENT

    def __post_init__(self) -> None:
        masses = check_masses(self.masses)
        lengths = check_lengths("initial_lengths", self.initial_lengths, len(masses))
        check_range("total_tether_length", self.total_tether_length, 0.0, low_open=True)
        object.__setattr__(self, "masses", masses)
        object.__setattr__(self, "initial_lengths", lengths)
        object.__setattr__(self, "gravity", Gravity.parse(self.gravity))

    @property
    def n_bodies(self) -> int:
        """N, the number of bodies including the main satellite."""
        return len(self.masses) + 1

    @property
    def n_tethers(self) -> int:
        """N - 1."""
        return len(self.masses)


@dataclass(frozen=True)
class ReelParams:
    """Reel actuators, one per tether (:func:`tether_gym.physics.kernels._reel`).

    Parameters
    ----------
    accel_limit : float or None
        |d2L_i/dt2| bound [m/s^2], > 0; None for no limit. Paper Sec. 4.3: 0.01.
    speed_limit : float or None
        |dL_i/dt| bound on the commanded reel speed [m/s], > 0; None for no limit.
    time_constant : float
        tau [rad] of the first-order reel response l'' = (l'_cmd - l') / tau that
        the acceleration limit then saturates, > 0.
    max_rate : float
        Largest commanded reel rate |l'_cmd| [-] (an action of +-1), in (0, 10].
    """

    accel_limit: float | None = 0.01
    speed_limit: float | None = None
    time_constant: float = 0.0125
    max_rate: float = 0.5

    def __post_init__(self) -> None:
        if self.accel_limit is not None:
            check_range("accel_limit", self.accel_limit, 0.0, low_open=True)
        if self.speed_limit is not None:
            check_range("speed_limit", self.speed_limit, 0.0, low_open=True)
        check_range("time_constant", self.time_constant, 0.0, low_open=True)
        check_range("max_reel_rate", self.max_rate, 0.0, 10.0, low_open=True)



def weights_from_dict(cls, values, argument: str, noun: str):
    """A frozen dataclass ``cls`` of defaults from a ``gym.make`` dict argument.

    None gives the defaults, an instance of ``cls`` is returned as it is, a dict
    overrides fields by name. Errors name ``argument`` (e.g. ``reward_weights['effort']``):
    TypeError for anything but a dict, ValueError for an unknown key (listing the valid
    ones) or a value its field refuses.
    """
    if values is None:
        return cls()
    if isinstance(values, cls):
        return values
    if not isinstance(values, dict):
        raise TypeError(f"{argument}={values!r} must be a dict of {noun} (or None), got "
                        f"{type(values).__name__}")
    valid = set(asdict(cls()))
    unknown = sorted(set(values) - valid)
    if unknown:
        raise ValueError(f"unknown {argument} keys {unknown}; valid keys: {sorted(valid)}")
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:  # name the argument the user passed
        raise renamed_error(exc, {key: f"{argument}[{key!r}]" for key in valid},
                            prefix=f"{argument}: ") from None
