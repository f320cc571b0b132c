"""Validated configuration of the libration environments (single and vector).

``EnvConfig.from_kwargs(**kwargs)`` is what ``gym.make("tether_gym/TetherLibration-v0",
**kwargs)`` goes through: unknown names are rejected with the list of valid ones and
every value is range-checked.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field

import numpy as np

from ..params import (
    EARTH_MU,
    ChainParams,
    Gravity,
    OrbitParams,
    ReelParams,
    as_float_tuple,
    check_range,
)
from ..physics import TetherChain, kernels
from ..tasks.reward import RewardWeights

__all__ = ["EnvConfig", "PAPER_INITIAL_THETA"]

PAPER_INITIAL_THETA = 0.1
"""theta_1(0) [rad] of the paper's Sec. 4.3 case (the other tethers start at 0)."""


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
class EnvConfig:
    """All arguments of the libration environment; see TetherLibrationEnv's docstring."""

    n_bodies: int = 3
    masses: tuple[float, ...] | None = None
    initial_lengths: tuple[float, ...] | None = None
    initial_theta: tuple[float, ...] | None = None
    initial_nu: float = 0.0
    eccentricity: float = 0.2
    semi_latus_rectum: float = 8.52e6
    mu: float = EARTH_MU
    total_tether_length: float = 2.0e4
    gravity: str = "gradient"
    amplitude: float = 0.2
    frequency: float = 1.0
    control_step: float = 0.025
    physics_step: float = 0.0125
    max_reel_rate: float = 0.5
    accel_limit: float | None = 0.01
    speed_limit: float | None = None
    reel_time_constant: float = 0.0125
    length_bounds: tuple[float, float] = (0.05, 1.5)
    orbits_per_episode: float = 3.0
    init_theta_range: float = 0.0
    init_dtheta_range: float = 0.0
    init_length_range: float = 0.0
    obs_noise: float = 0.0
    disturbance: float = 0.0
    eccentricity_range: tuple[float, float] | None = None
    mass_range: float | None = None
    observe_params: bool | None = None
    reward_weights: RewardWeights = field(default_factory=RewardWeights)
    render_mode: str | None = None

    # ------------------------------------------------------------------ #
    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_kwargs(cls, **kwargs) -> EnvConfig:
        """Validate keyword arguments; unknown names raise ValueError listing valid ones."""
        valid = cls.names()
        unknown = [k for k in kwargs if k not in valid]
        if unknown:
            hints = []
            for k in unknown:
                close = difflib.get_close_matches(k, valid, n=1)
                hints.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
            raise ValueError(f"unknown argument(s) {', '.join(hints)}; valid arguments: "
                             f"{', '.join(valid)}")
        return cls(**kwargs)

    def __post_init__(self) -> None:  # noqa: C901 - a flat list of checks
        if isinstance(self.n_bodies, bool) or not isinstance(self.n_bodies, (int, np.integer)):
            raise TypeError(f"n_bodies must be an int, got {type(self.n_bodies).__name__} "
                            f"{self.n_bodies!r}")
        if self.n_bodies < 2:
            raise ValueError(f"n_bodies={self.n_bodies!r} must be >= 2 (one tether or more)")
        n = int(self.n_bodies) - 1
        set_ = object.__setattr__
        set_(self, "n_bodies", int(self.n_bodies))
        masses = self.masses if self.masses is not None else ((1.0, 2.0) if n == 2 else (1.0,) * n)
        lengths = self.initial_lengths if self.initial_lengths is not None else (1.0 / n,) * n
        theta0 = (self.initial_theta if self.initial_theta is not None
                  else (PAPER_INITIAL_THETA,) + (0.0,) * (n - 1))
        set_(self, "masses", as_float_tuple("masses", masses, n))
        set_(self, "initial_lengths", as_float_tuple("initial_lengths", lengths, n))
        set_(self, "initial_theta", as_float_tuple("initial_theta", theta0, n))
        if min(self.masses) <= 0:
            raise ValueError(f"masses={self.masses!r} must all be > 0")
        if min(self.initial_lengths) <= 0:
            raise ValueError(f"initial_lengths={self.initial_lengths!r} must all be > 0")
        if max(abs(t) for t in self.initial_theta) >= 0.5 * math.pi:
            raise ValueError(f"initial_theta={self.initial_theta!r} must lie in (-pi/2, pi/2)")
        check_range("initial_nu", self.initial_nu)
        # the physical parameter objects validate e, p, mu, L0, gravity, limits
        set_(self, "gravity", Gravity.parse(self.gravity).value)
        self.orbit  # noqa: B018 - validates
        self.chain  # noqa: B018
        self.reel  # noqa: B018
        check_range("amplitude", self.amplitude, 0.0, 1.0, high_open=True)
        check_range("frequency", self.frequency, 0.0)
        check_range("control_step", self.control_step, 0.0, 1.0, low_open=True)
        check_range("physics_step", self.physics_step, 0.0, self.control_step, low_open=True)
        ratio = self.control_step / self.physics_step
        if abs(ratio - round(ratio)) > 1e-9 * ratio:
            raise ValueError(f"control_step={self.control_step!r} must be a whole multiple of "
                             f"physics_step={self.physics_step!r} (ratio {ratio:.6g})")
        if self.reel_time_constant < 0.5 * self.physics_step:
            raise ValueError(f"reel_time_constant={self.reel_time_constant!r} must be >= "
                             f"physics_step / 2 = {0.5 * self.physics_step!r} for a stable "
                             "RK4 reel response")
        check_range("max_reel_rate", self.max_reel_rate, 0.0, 10.0, low_open=True)
        lo, hi = as_float_tuple("length_bounds", self.length_bounds, 2)
        if not 0.0 <= lo < hi:
            raise ValueError(f"length_bounds={self.length_bounds!r} must be (low, high) "
                             "with 0 <= low < high")
        if not all(lo < l0 < hi for l0 in self.initial_lengths):
            raise ValueError(f"initial_lengths={self.initial_lengths!r} must lie inside "
                             f"length_bounds={(lo, hi)!r}")
        set_(self, "length_bounds", (lo, hi))
        check_range("orbits_per_episode", self.orbits_per_episode, 0.0, 1000.0, low_open=True)
        check_range("init_theta_range", self.init_theta_range, 0.0, 0.5 * math.pi)
        check_range("init_dtheta_range", self.init_dtheta_range, 0.0, 10.0)
        check_range("init_length_range", self.init_length_range, 0.0, min(self.initial_lengths),
                    high_open=True)
        check_range("obs_noise", self.obs_noise, 0.0, 10.0)
        check_range("disturbance", self.disturbance, 0.0, 100.0)
        set_(self, "eccentricity_range", _opt_range("eccentricity_range",
                                                    self.eccentricity_range, 0.0, 0.99))
        if self.mass_range is not None:
            check_range("mass_range", self.mass_range, 0.0, 1.0, high_open=True)
        if self.observe_params is not None and not isinstance(self.observe_params, bool):
            raise TypeError(f"observe_params must be True, False or None, got "
                            f"{self.observe_params!r}")
        set_(self, "reward_weights", RewardWeights.from_dict(
            self.reward_weights if not isinstance(self.reward_weights, RewardWeights)
            else dataclasses.asdict(self.reward_weights)))
        if self.render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode={self.render_mode!r} must be None, 'rgb_array' "
                             "or 'human'")

    # ------------------------------------------------------------------ #
    @property
    def n_tethers(self) -> int:
        return self.n_bodies - 1

    @property
    def orbit(self) -> OrbitParams:
        return OrbitParams(self.eccentricity, self.semi_latus_rectum, self.mu)

    @property
    def chain(self) -> ChainParams:
        return ChainParams(self.masses, self.initial_lengths, self.total_tether_length,
                           self.gravity)

    @property
    def reel(self) -> ReelParams:
        return ReelParams(self.accel_limit, self.speed_limit, self.reel_time_constant)

    @property
    def model(self) -> TetherChain:
        """The chain with the configured (nominal) e, masses and gravity model."""
        return TetherChain(self.masses, self.eccentricity, self.gravity,
                           self.total_tether_length / self.semi_latus_rectum)

    @property
    def n_substeps(self) -> int:
        return int(round(self.control_step / self.physics_step))

    @property
    def episode_length(self) -> float:
        """Episode length in true anomaly [rad]."""
        return 2.0 * math.pi * self.orbits_per_episode

    @property
    def max_episode_steps(self) -> int:
        """Control steps per episode (the env truncates itself after this many)."""
        return int(math.ceil(self.episode_length / self.control_step - 1e-9))

    @property
    def randomised(self) -> bool:
        """True when e or the masses are drawn per episode (they enter the observation)."""
        return self.eccentricity_range is not None or self.mass_range is not None

    @property
    def with_params(self) -> bool:
        """Whether e and the mass fractions close the observation.

        ``observe_params`` if given, else :attr:`randomised`. False with randomisation
        trains a policy that must be robust to parameters it cannot see.
        """
        return self.randomised if self.observe_params is None else self.observe_params

    @property
    def obs_dim(self) -> int:
        n = self.n_tethers
        return 2 + 4 * n + 2 + ((1 + n) if self.with_params else 0)

    @property
    def rate_scale(self) -> float:
        """n = sqrt(mu / p^3) [rad/s]."""
        return self.orbit.rate_scale

    @property
    def accel_scale(self) -> float:
        """L0 n^2 [m/s^2]: physical reel acceleration per unit of k^4 l'' - 2 e s k^3 l'."""
        return self.total_tether_length * self.rate_scale**2

    def param_row(self, eccentricity: float, masses) -> np.ndarray:
        """Kernel parameter row for given e and subsatellite masses."""
        return self.param_rows(np.array([eccentricity], dtype=float),
                               np.asarray(masses, dtype=float)[None, :])[0]

    def param_rows(self, eccentricity: np.ndarray, masses: np.ndarray) -> np.ndarray:
        """Kernel parameter rows (B, 6+n) for e of shape (B,) and masses of shape (B, n).

        The layout is :func:`tether_gym.physics.kernels.pack_params`'s, with the tail
        mass fractions Mt_j = sum_{i>=j} M_i / sum_i M_i of each row; masses of shape
        (n,) are shared by every row.
        """
        eccentricity = np.asarray(eccentricity, dtype=float)
        m = np.asarray(masses, dtype=float)
        m = np.broadcast_to(m, eccentricity.shape + m.shape[-1:])
        frac = m / m.sum(axis=-1, keepdims=True)
        tail = np.cumsum(frac[:, ::-1], axis=-1)[:, ::-1]
        grav = (kernels.GRAVITY_FULL if self.gravity == Gravity.FULL.value
                else kernels.GRAVITY_GRADIENT)
        a_bound = math.inf if self.accel_limit is None else self.accel_limit / self.accel_scale
        v_bound = (math.inf if self.speed_limit is None
                   else self.speed_limit / (self.total_tether_length * self.rate_scale))
        head = kernels.pack_params(0.0, (), grav,
                                   self.total_tether_length / self.semi_latus_rectum,
                                   a_bound, v_bound, self.reel_time_constant)
        rows = np.empty((m.shape[0], kernels.P_TAIL + m.shape[1]))
        rows[:, :kernels.P_TAIL] = head
        rows[:, kernels.P_ECC] = eccentricity
        rows[:, kernels.P_TAIL:] = tail
        return rows

    @property
    def accel_reference(self) -> float:
        """a_ref / (L0 n^2) [-]: the accel limit (or 0.01 m/s^2) made dimensionless."""
        return (0.01 if self.accel_limit is None else self.accel_limit) / self.accel_scale
