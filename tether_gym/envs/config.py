"""Validated configuration of the libration environments (single and vector).

``EnvConfig.from_kwargs(**kwargs)`` is what ``gym.make("tether_gym/TetherLibration-v1",
**kwargs)`` goes through: the flat keyword names (the env docstring's Arguments
table) are mapped onto small validated parts (:data:`FLAT_NAMES`, the one list of
them), unknown names are rejected with the list of valid ones and every value is
range-checked by the part that owns it. The parts' values read as attributes of the
config as well (``config.eccentricity`` is ``config.orbit.eccentricity``).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from ..params import (
    EARTH_MU,
    ChainParams,
    OrbitParams,
    ReelParams,
    as_float_tuple,
    check_count,
    check_lengths,
    check_masses,
    check_range,
    renamed_error,
)
from ..physics import Scales, TetherChain
from ..tasks.cost import CostThresholds
from ..tasks.reward import RewardWeights
from .actions import INCREMENT, RATE
from .layout import OBSERVATION

__all__ = ["EnvConfig", "env_config", "Action", "Reference", "Episode", "Randomisation",
           "FLAT_NAMES", "PAPER_INITIAL_THETA", "ACTION_MODES"]

PAPER_INITIAL_THETA = 0.1
"""theta_1(0) [rad] of the paper's Sec. 4.3 case (the other tethers start at 0)."""

MAX_BODIES = 20
"""Largest N: the default lengths 1/(N-1) must stay inside the default length bounds."""
MIN_STEP = 1.0e-4
"""Smallest control and physics step [rad] (60,000 steps per orbit)."""
MAX_CONTROL_STEP = 1.0
"""Largest control step [rad]: at most MAX_CONTROL_STEP / MIN_STEP RK4 substeps."""
MAX_INITIAL_NU = 1.0e4
"""Largest |initial_nu| [rad] (about 1,600 orbits)."""
MAX_LENGTH_RATIO = 0.1
"""Largest L0 / p [-]: the chain must be short against the orbit radius (the gravity
models expand in, or are exact for, a body near the main satellite)."""


def _opt_range(name, value, low, high):
    if value is None:
        return None
    lo, hi = as_float_tuple(name, value, 2)
    check_range(f"{name}[0]", lo, low, high)
    check_range(f"{name}[1]", hi, low, high)
    if lo > hi:
        raise ValueError(f"{name}={value!r} must be (low, high) with low <= high")
    return (lo, hi)


@dataclass(frozen=True)
class Reference:
    """The reference libration theta_d = A sin(w nu) (paper Eq. 8).

    Parameters
    ----------
    amplitude : float
        A [rad], in [0, 1).
    frequency : float
        w [-] (per radian of true anomaly), >= 0.
    """

    amplitude: float = 0.2
    frequency: float = 1.0

    def __post_init__(self) -> None:
        check_range("amplitude", self.amplitude, 0.0, 1.0, high_open=True)
        check_range("frequency", self.frequency, 0.0)


ACTION_MODES = (INCREMENT, RATE)
"""Values of ``action_mode``."""


@dataclass(frozen=True)
class Action:
    """What an action means.

    Parameters
    ----------
    mode : str
        ``"increment"``: the action changes the normalised reel-rate command,
        u <- clip(u + increment_gain * a, -1, 1); ``"rate"``: the action is the
        command, u = clip(a, -1, 1) (the paper's control input).
        Either way l'_cmd = u * max_reel_rate.
    increment_gain : float
        Largest change of u per control step [-], in (0, 2] (``"increment"`` only).
    """

    mode: str = "increment"
    increment_gain: float = 0.25

    def __post_init__(self) -> None:
        if not isinstance(self.mode, str) or self.mode not in ACTION_MODES:
            raise ValueError(f"action_mode={self.mode!r} must be one of {ACTION_MODES}")
        check_range("increment_gain", self.increment_gain, 0.0, 2.0, low_open=True)


@dataclass(frozen=True)
class Episode:
    """How an episode starts, is stepped and ends.

    Parameters
    ----------
    initial_nu : float
        nu at reset [rad].
    initial_theta : tuple of float or None
        theta_i(0) [rad] before randomisation, in (-pi/2, pi/2); None: (0.1, 0, ...).
    control_step, physics_step : float
        True anomaly per env step and per RK4 step [rad]; physics_step divides
        control_step.
    orbits_per_episode : float
        Episode length [orbits], in (0, 1000].
    length_bounds : tuple of float
        (low, high) allowed l_i [-].
    """

    initial_nu: float = 0.0
    initial_theta: tuple[float, ...] | None = None
    control_step: float = 0.025
    physics_step: float = 0.0125
    orbits_per_episode: float = 3.0
    length_bounds: tuple[float, float] = (0.05, 1.5)

    def __post_init__(self) -> None:
        check_range("initial_nu", self.initial_nu, -MAX_INITIAL_NU, MAX_INITIAL_NU)
        if self.initial_theta is not None:
            theta0 = as_float_tuple("initial_theta", self.initial_theta)
            if max(abs(t) for t in theta0) >= 0.5 * math.pi:
                raise ValueError(f"initial_theta={self.initial_theta!r} must lie in "
                                 "(-pi/2, pi/2)")
            object.__setattr__(self, "initial_theta", theta0)
        check_range("control_step", self.control_step, MIN_STEP, MAX_CONTROL_STEP)
        check_range("physics_step", self.physics_step, MIN_STEP, self.control_step)
        ratio = self.control_step / self.physics_step
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ValueError(f"control_step={self.control_step!r} must be a whole multiple of "
                             f"physics_step={self.physics_step!r} (ratio {ratio:.6g})")
        check_range("orbits_per_episode", self.orbits_per_episode, 0.0, 1000.0, low_open=True)
        lo, hi = as_float_tuple("length_bounds", self.length_bounds, 2)
        if not 0.0 <= lo < hi:
            raise ValueError(f"length_bounds={self.length_bounds!r} must be (low, high) "
                             "with 0 <= low < high")
        object.__setattr__(self, "length_bounds", (lo, hi))

    @property
    def n_substeps(self) -> int:
        """RK4 steps per control step."""
        return int(round(self.control_step / self.physics_step))

    @property
    def length(self) -> float:
        """Episode length in true anomaly [rad]."""
        return 2.0 * math.pi * self.orbits_per_episode

    @property
    def max_steps(self) -> int:
        """Control steps per episode (the env truncates itself after this many)."""
        return int(math.ceil(self.length / self.control_step - 1e-9))


@dataclass(frozen=True)
class Randomisation:
    """What is drawn per episode and what disturbs it.

    Parameters
    ----------
    init_theta_range, init_dtheta_range, init_length_range : float
        Half-widths of the uniform draws of theta_i(0) [rad], theta_i'(0) [rad/rad]
        and l_i(0) [-] around their nominal values.
    eccentricity_range : tuple of float or None
        (low, high) to draw e per episode.
    mass_range : float or None
        Relative half-width to draw each mass, in [0, 1).
    obs_noise : float
        Standard deviation of the observation noise on theta, theta', l, l'.
    obs_bias : float
        Constant offset added to every observed theta_i [rad] (a misaligned attitude
        sensor), in [-0.5, 0.5].
    disturbance : float
        Bound of the uniform disturbance d on theta'' (paper Eq. 20) [rad/rad^2].
    observe_params : bool, "eccentricity" or None
        What closes the observation: True e and the mass fractions M_i,
        ``"eccentricity"`` e alone, False neither; None: e and M_i exactly when
        randomised.
    """

    init_theta_range: float = 0.0
    init_dtheta_range: float = 0.0
    init_length_range: float = 0.0
    eccentricity_range: tuple[float, float] | None = None
    mass_range: float | None = None
    obs_noise: float = 0.0
    obs_bias: float = 0.0
    disturbance: float = 0.0
    observe_params: bool | str | None = None

    def __post_init__(self) -> None:
        check_range("init_theta_range", self.init_theta_range, 0.0, 0.5 * math.pi)
        check_range("init_dtheta_range", self.init_dtheta_range, 0.0, 10.0)
        check_range("init_length_range", self.init_length_range, 0.0)
        check_range("obs_noise", self.obs_noise, 0.0, 10.0)
        check_range("obs_bias", self.obs_bias, -0.5, 0.5)
        check_range("disturbance", self.disturbance, 0.0, 100.0)
        object.__setattr__(self, "eccentricity_range",
                           _opt_range("eccentricity_range", self.eccentricity_range, 0.0, 0.99))
        if self.mass_range is not None:
            check_range("mass_range", self.mass_range, 0.0, 1.0, high_open=True)
        observe = self.observe_params
        if isinstance(observe, str) and observe != "eccentricity":
            raise ValueError(f"observe_params={observe!r} must be True, False, None or "
                             "'eccentricity' (e alone; the only string it takes)")
        if not (observe is None or isinstance(observe, (bool, str))):
            raise TypeError(f"observe_params must be True, False, 'eccentricity' or None, got "
                            f"{observe!r}")

    @property
    def randomised(self) -> bool:
        """True when e or the masses are drawn per episode."""
        return self.eccentricity_range is not None or self.mass_range is not None


_PARTS: dict[str, tuple[type, dict[str, str]]] = {
    # part: (class, {flat keyword: field of the part})
    "orbit": (OrbitParams, {"eccentricity": "eccentricity",
                            "semi_latus_rectum": "semi_latus_rectum", "mu": "mu"}),
    "chain": (ChainParams, {"masses": "masses", "initial_lengths": "initial_lengths",
                            "total_tether_length": "total_tether_length",
                            "gravity": "gravity"}),
    "reels": (ReelParams, {"accel_limit": "accel_limit", "speed_limit": "speed_limit",
                           "reel_time_constant": "time_constant",
                           "max_reel_rate": "max_rate"}),
    "action": (Action, {"action_mode": "mode", "increment_gain": "increment_gain"}),
    "reference": (Reference, {"amplitude": "amplitude", "frequency": "frequency"}),
    "episode": (Episode, {"initial_nu": "initial_nu", "initial_theta": "initial_theta",
                          "control_step": "control_step", "physics_step": "physics_step",
                          "orbits_per_episode": "orbits_per_episode",
                          "length_bounds": "length_bounds"}),
    "randomisation": (Randomisation, {f.name: f.name for f in fields(Randomisation)}),
}
FLAT_NAMES: dict[str, tuple[str, str]] = {
    flat: (part, attr) for part, (_, names) in _PARTS.items() for flat, attr in names.items()}
"""Flat ``gym.make`` keyword -> (part, field): the one map between the two."""

_DEFAULTS = {"eccentricity": 0.2, "semi_latus_rectum": 8.52e6, "mu": EARTH_MU,
             "total_tether_length": 2.0e4, "gravity": "gradient"}


@dataclass(frozen=True)
class EnvConfig:
    """All arguments of the libration environment, as validated parts.

    Build it with :meth:`from_kwargs` (the flat ``gym.make`` names); see
    TetherLibrationEnv's docstring for every argument.
    """

    n_bodies: int = 3
    orbit: OrbitParams = field(default_factory=OrbitParams)
    chain: ChainParams = field(default_factory=ChainParams)
    reels: ReelParams = field(default_factory=ReelParams)
    action: Action = field(default_factory=Action)
    reference: Reference = field(default_factory=Reference)
    episode: Episode = field(default_factory=Episode)
    randomisation: Randomisation = field(default_factory=Randomisation)
    reward_weights: RewardWeights = field(default_factory=RewardWeights)
    cost_thresholds: CostThresholds = field(default_factory=CostThresholds)
    render_mode: str | None = None

    # ------------------------------------------------------------------ #
    @classmethod
    def names(cls) -> list[str]:
        """The flat keyword names, in the Arguments table's order."""
        return ["n_bodies", *FLAT_NAMES, "reward_weights", "cost_thresholds", "render_mode"]

    @classmethod
    def from_kwargs(cls, **kwargs: Any) -> EnvConfig:
        """Validate flat keyword arguments; unknown names raise ValueError listing valid ones."""
        valid = cls.names()
        unknown = [k for k in kwargs if k not in valid]
        if unknown:
            hints = []
            for k in unknown:
                close = difflib.get_close_matches(k, valid, n=1)
                hints.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
            raise ValueError(f"unknown argument(s) {', '.join(hints)}; valid arguments: "
                             f"{', '.join(valid)}")
        n = check_count("n_bodies", kwargs.get("n_bodies", 3), 2, MAX_BODIES,
                        "one tether or more") - 1
        given = dict(kwargs)
        # chain defaults that depend on N
        if given.get("masses") is None:
            given["masses"] = (1.0, 2.0) if n == 2 else (1.0,) * n
        if given.get("initial_lengths") is None:
            given["initial_lengths"] = (1.0 / n,) * n
        given["masses"] = check_masses(given["masses"], n)
        given["initial_lengths"] = check_lengths("initial_lengths", given["initial_lengths"], n)
        if given.get("initial_theta") is None:
            given["initial_theta"] = (PAPER_INITIAL_THETA,) + (0.0,) * (n - 1)
        given["initial_theta"] = as_float_tuple("initial_theta", given["initial_theta"], n)
        parts = {}
        for part, (klass, names) in _PARTS.items():
            values = {attr: given[flat] if flat in given else _DEFAULTS.get(flat)
                      for flat, attr in names.items()
                      if flat in given or flat in _DEFAULTS}
            try:
                parts[part] = klass(**values)
            except (TypeError, ValueError) as exc:  # name the gym.make argument
                raise renamed_error(exc, {attr: flat for flat, attr in names.items()
                                          if attr != flat}) from None
        config = cls(n_bodies=n + 1, **parts,
                     reward_weights=RewardWeights.from_dict(kwargs.get("reward_weights")),
                     cost_thresholds=CostThresholds.from_dict(kwargs.get("cost_thresholds")),
                     render_mode=kwargs.get("render_mode"))
        return config

    def __post_init__(self) -> None:
        ratio = self.scales.length_ratio
        if ratio > MAX_LENGTH_RATIO:
            raise ValueError(f"total_tether_length / semi_latus_rectum = {ratio:g} (L0="
                             f"{self.chain.total_tether_length!r}, p="
                             f"{self.orbit.semi_latus_rectum!r}) must be <= "
                             f"{MAX_LENGTH_RATIO:g}: the chain must be short against the orbit")
        if self.chain.n_tethers != self.n_bodies - 1:
            raise ValueError(f"n_bodies={self.n_bodies!r} needs {self.n_bodies - 1} masses, got "
                             f"masses={self.chain.masses!r}")
        lo, hi = self.episode.length_bounds
        lengths = self.chain.initial_lengths
        if not all(lo < l0 < hi for l0 in lengths):
            raise ValueError(f"initial_lengths={lengths!r} must lie inside "
                             f"length_bounds={(lo, hi)!r}")
        factor = self.cost_thresholds.length_factor
        if lo * factor >= hi / factor:
            raise ValueError(f"cost_thresholds['length_factor']={factor!r} leaves no cost-free "
                             f"length inside length_bounds={(lo, hi)!r}: it must be < "
                             f"sqrt(l_max / l_min) = {(hi / lo) ** 0.5:g}")
        check_range("init_length_range", self.randomisation.init_length_range, 0.0,
                    min(lengths), high_open=True)
        if self.reels.time_constant < 0.5 * self.episode.physics_step:
            raise ValueError(f"reel_time_constant={self.reels.time_constant!r} must be >= "
                             f"physics_step / 2 = {0.5 * self.episode.physics_step!r} for a "
                             "stable RK4 reel response")
        if self.render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode={self.render_mode!r} must be None, 'rgb_array' "
                             "or 'human'")

    def __getattr__(self, name: str) -> Any:
        """Flat names read through to their part (``config.eccentricity``)."""
        try:
            part, attr = FLAT_NAMES[name]
        except KeyError:
            raise AttributeError(f"{type(self).__name__} has no attribute {name!r}") from None
        return getattr(object.__getattribute__(self, part), attr)

    # ------------------------------------------------------------------ #
    @property
    def n_tethers(self) -> int:
        """n = N - 1."""
        return self.n_bodies - 1

    @property
    def scales(self) -> Scales:
        """SI <-> dimensionless conversions of this configuration."""
        return Scales(self.orbit, self.chain.total_tether_length)

    @property
    def model(self) -> TetherChain:
        """The chain with the configured (nominal) e, masses and gravity model."""
        return TetherChain(self.chain.masses, self.orbit.eccentricity, self.chain.gravity,
                           self.scales.length_ratio)

    @property
    def n_substeps(self) -> int:
        """RK4 steps per control step."""
        return self.episode.n_substeps

    @property
    def episode_length(self) -> float:
        """Episode length in true anomaly [rad]."""
        return self.episode.length

    @property
    def max_episode_steps(self) -> int:
        """Control steps per episode (the env truncates itself after this many)."""
        return self.episode.max_steps

    @property
    def randomised(self) -> bool:
        """True when e or the masses are drawn per episode."""
        return self.randomisation.randomised

    @property
    def observed(self) -> dict[str, bool]:
        """The optional observation groups that are on: ``{"eccentricity": .., "masses": ..}``.

        From ``observe_params``: True both, ``"eccentricity"`` e alone, False neither,
        None both exactly when :attr:`randomised`. Randomisation without them trains a
        policy that must be robust to parameters it cannot see.
        """
        observe = self.randomisation.observe_params
        if observe is None:
            observe = self.randomised
        return {"eccentricity": observe is True or observe == "eccentricity",
                "masses": observe is True}

    @property
    def obs_dim(self) -> int:
        """Length of one observation (OBSERVATION layout)."""
        return OBSERVATION.size(self.n_tethers, **self.observed)

    def param_rows(self, eccentricity, masses) -> np.ndarray:
        """Kernel parameter rows for e of shape (...,) and masses of shape (..., n)."""
        return self.scales.param_rows(eccentricity, masses, self.chain.gravity, self.reels)

    def nominal_params(self, eccentricity=None, masses=None, reel_time_constant=None,
                       accel_limit=None) -> np.ndarray:
        """The parameter row (P,) of a model that differs from this configuration's.

        Each argument left None is the configuration's own: eccentricity e [-], masses
        (any common unit), ``reel_time_constant`` tau [rad] and ``accel_limit``
        [m/s^2] (the env arguments of those names). Model-based controllers and the
        safety filter predict with it under model mismatch.
        """
        reels = self.reels
        if reel_time_constant is not None:
            reels = replace(reels, time_constant=reel_time_constant)
        if accel_limit is not None:
            reels = replace(reels, accel_limit=accel_limit)
        return self.scales.param_rows(self.eccentricity if eccentricity is None else eccentricity,
                                      self.masses if masses is None else masses,
                                      self.chain.gravity, reels)

    @property
    def accel_reference(self) -> float:
        """a_ref / (L0 n^2) [-]: the accel limit (or 0.01 m/s^2) made dimensionless."""
        limit = self.reels.accel_limit
        return self.scales.accel_bound(0.01 if limit is None else limit)


def env_config(env: Any):
    """The :class:`~tether_gym.envs.config.EnvConfig` of a TetherLibration env.

    ``env`` is the env, wrapped or not, its vector env, a stable-baselines3 VecEnv of
    it (its first sub-env's, by ``get_attr``), or any object whose ``config`` (or
    ``unwrapped.config``) is an EnvConfig.

    Raises
    ------
    TypeError
        Naming the type of ``env`` when it has no such configuration.
    """
    cfg = getattr(getattr(env, "unwrapped", env), "config", None)
    if cfg is None and callable(getattr(env, "get_attr", None)):
        try:
            cfg = env.get_attr("config", indices=[0])[0]
        except AttributeError:
            cfg = None
    if cfg is None or not hasattr(cfg, "param_rows"):
        raise TypeError(f"env must be a tether_gym/TetherLibration env (wrapped or vector), "
                        f"got {type(env).__name__} without its config")
    return cfg
