"""State of a batch of libration environments, shared by the single and vector env.

Each row has its own random generator, so row b of a vector env seeded with s_b
draws exactly what a single env seeded with s_b draws, in the same order: at reset
the randomised parameters (e, then the masses), then the initial perturbations
(theta, theta', l), then the observation noise; at each step the disturbance, then
the observation noise.
"""

from __future__ import annotations

import numpy as np

from ..physics import kernels
from ..tasks.reference import periodic_reel_rate, reference
from ..tasks.reward import COMPONENTS
from ..tasks.termination import Failure
from .config import EnvConfig
from .step_kernel import step_batch, write_obs

__all__ = ["ChainBatch", "RESET_OPTION_KEYS"]

RESET_OPTION_KEYS = ("nu", "theta", "dtheta", "length", "dlength")


def _check_options(options, n):
    """Validate reset options; return a dict of float arrays (or float for nu)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(set(options) - set(RESET_OPTION_KEYS))
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; valid keys: {list(RESET_OPTION_KEYS)}")
    out = {}
    for key, value in options.items():
        arr = np.asarray(value, dtype=float)
        if key == "nu":
            if arr.shape != ():
                raise ValueError(f"options['nu']={value!r} must be a scalar [rad]")
        elif arr.shape != (n,):
            raise ValueError(f"options[{key!r}]={value!r} must have shape ({n},), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"options[{key!r}]={value!r} must be finite")
        out[key] = arr
    if "theta" in out and np.any(np.abs(out["theta"]) >= 0.5 * np.pi):
        raise ValueError(f"options['theta']={options['theta']!r} must lie in (-pi/2, pi/2)")
    if "length" in out and np.any(out["length"] <= 0):
        raise ValueError(f"options['length']={options['length']!r} must be > 0")
    return out


class ChainBatch:
    """Arrays and step logic for ``num`` environments with one :class:`EnvConfig`."""

    def __init__(self, config: EnvConfig, num: int):
        self.config = config
        self.num = num
        n = config.n_tethers
        self.n = n
        self.nu = np.zeros(num)
        self.y = np.zeros((num, 4 * n))
        self.par = np.tile(config.param_row(config.eccentricity, config.masses), (num, 1))
        self.dist = np.zeros((num, n))
        self.noise = np.zeros((num, 4 * n))
        self.obs = np.zeros((num, config.obs_dim), dtype=np.float32)
        self.reward = np.zeros(num)
        self.components = np.zeros((num, len(COMPONENTS)))
        self.failure = np.zeros(num, dtype=np.int64)
        self.tension_min = np.zeros((num, n))
        self.tension_end = np.zeros((num, n))
        self.deriv_end = np.zeros((num, 4 * n))
        self.steps = np.zeros(num, dtype=np.int64)
        self.nu_end = np.zeros(num)
        self.weights = config.reward_weights.as_tuple()
        self.with_params = config.randomised

    # ------------------------------------------------------------------ #
    def reset_row(self, b: int, rng: np.random.Generator, options=None) -> None:
        """Draw row b's parameters and initial state (options override the draw)."""
        cfg = self.config
        n = self.n
        opts = _check_options(options, n)
        ecc = cfg.eccentricity
        masses = np.asarray(cfg.masses)
        if cfg.eccentricity_range is not None:
            ecc = float(rng.uniform(*cfg.eccentricity_range))
        if cfg.mass_range is not None:
            masses = masses * rng.uniform(1.0 - cfg.mass_range, 1.0 + cfg.mass_range, n)
        self.par[b] = cfg.param_row(ecc, masses)
        nu0 = float(opts.get("nu", cfg.initial_nu))
        ref, dref, _ = reference(nu0, cfg.amplitude, cfg.frequency)
        theta = np.asarray(cfg.initial_theta) + rng.uniform(-1, 1, n) * cfg.init_theta_range
        dtheta = dref + rng.uniform(-1, 1, n) * cfg.init_dtheta_range
        length = np.asarray(cfg.initial_lengths) + rng.uniform(-1, 1, n) * cfg.init_length_range
        theta = opts.get("theta", theta)
        dtheta = opts.get("dtheta", dtheta)
        length = opts.get("length", length)
        # Reels start at the rate of the open-loop law (paper Eq. 10) on the reference.
        dlength = opts.get("dlength", periodic_reel_rate(nu0, ref, dref, length, ecc,
                                                         cfg.amplitude, cfg.frequency))
        self.nu[b] = nu0
        self.nu_end[b] = nu0 + cfg.episode_length
        self.y[b] = np.concatenate([theta, dtheta, length, dlength])
        self.steps[b] = 0
        self.failure[b] = 0
        self.reward[b] = 0.0
        self.components[b] = 0.0
        self._static_tension(b)
        self._draw_noise(b, rng)
        write_obs(self.nu[b], self.y[b], cfg.amplitude, cfg.frequency, self.par[b],
                  self.with_params, self.noise[b], self.obs[b])

    def _static_tension(self, b: int) -> None:
        """Tension and derivatives at row b's state with the reels holding their rate."""
        n = self.n
        nu = self.nu[b:b + 1]
        y = self.y[b]
        dl = y[3 * n:].reshape(1, n)
        ddl = np.empty((1, n))
        kernels.reel_batch(nu, dl, dl, self.par[b:b + 1], ddl)
        ddth = np.empty((1, n))
        kernels.accel_batch(nu, y[:n].reshape(1, n), y[n:2 * n].reshape(1, n),
                            y[2 * n:3 * n].reshape(1, n), dl, ddl, self.par[b:b + 1], ddth,
                            self.tension_end[b:b + 1])
        self.tension_min[b] = self.tension_end[b]
        self.deriv_end[b] = np.concatenate([y[n:2 * n], ddth[0], y[3 * n:], ddl[0]])

    def _draw_noise(self, b: int, rng: np.random.Generator) -> None:
        if self.config.obs_noise > 0.0:
            self.noise[b] = rng.normal(0.0, self.config.obs_noise, 4 * self.n)

    # ------------------------------------------------------------------ #
    def step(self, action: np.ndarray, rngs) -> None:
        """One control step of every row; ``rngs[b]`` draws row b's disturbance and noise."""
        cfg = self.config
        if cfg.disturbance > 0.0 or cfg.obs_noise > 0.0:
            for b in range(self.num):
                if cfg.disturbance > 0.0:
                    self.dist[b] = rngs[b].uniform(-cfg.disturbance, cfg.disturbance, self.n)
                self._draw_noise(b, rngs[b])
        step_batch(self.nu, self.y, action, cfg.max_reel_rate, self.dist, self.par,
                   cfg.physics_step, cfg.n_substeps, cfg.amplitude, cfg.frequency,
                   self.weights, cfg.length_bounds[0], cfg.length_bounds[1],
                   cfg.accel_reference, self.with_params, self.noise, self.obs, self.reward,
                   self.components, self.failure, self.tension_min, self.tension_end,
                   self.deriv_end)
        self.steps += 1

    def truncated(self) -> np.ndarray:
        """Rows whose episode has reached its length in true anomaly."""
        return self.nu >= self.nu_end - 1e-9

    # ------------------------------------------------------------------ #
    def info(self, b: int) -> dict:
        """The documented ``info`` dict of row b (fresh arrays)."""
        n = self.n
        y = self.y[b]
        cfg = self.config
        nu = float(self.nu[b])
        phase = cfg.frequency * nu
        ecc = float(self.par[b, kernels.P_ECC])
        k = 1.0 + ecc * np.cos(nu)
        ddl = self.deriv_end[b, 3 * n:]
        dl = y[3 * n:]
        accel = cfg.accel_scale * (k**4 * ddl - 2.0 * ecc * np.sin(nu) * k**3 * dl)
        info = {
            "nu": nu,
            "theta": y[:n].copy(),
            "dtheta": y[n:2 * n].copy(),
            "length": y[2 * n:3 * n].copy(),
            "dlength": dl.copy(),
            "ddlength": ddl.copy(),
            "tension": self.tension_end[b].copy(),
            "tension_min": self.tension_min[b].copy(),
            "theta_ref": float(cfg.amplitude * np.sin(phase)),
            "dtheta_ref": float(cfg.amplitude * cfg.frequency * np.cos(phase)),
            "reel_accel": accel,
            "eccentricity": ecc,
            "failure": Failure(int(self.failure[b])).label,
        }
        for name, value in zip(COMPONENTS, self.components[b]):
            info[name] = float(value)
        return info
