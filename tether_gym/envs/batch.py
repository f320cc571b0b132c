"""State of a batch of libration environments, shared by the single and vector env.

Each row has its own random generator, so row b of a vector env seeded with s_b
draws exactly what a single env seeded with s_b draws, in the same order: at reset
the randomised parameters (e, then the masses), then the initial perturbations
(theta, theta', l), then the observation noise; at each step the disturbance, then
the observation noise.

:meth:`ChainBatch.step` can advance a subset of the rows (the vector env leaves the
rows it is about to auto-reset alone) and can spread the rows over numba's threads;
every row runs the same compiled code either way, so the results do not change.
"""

from __future__ import annotations

import numpy as np

from ..physics import kernels
from ..tasks.reference import desired_libration, periodic_reel_rate
from ..tasks.reward import COMPONENTS
from ..tasks.termination import Failure
from .config import EnvConfig
from .step_kernel import info_batch, step_rows, step_rows_parallel, write_obs

__all__ = ["ChainBatch", "RESET_OPTION_KEYS", "INFO_KEYS"]

RESET_OPTION_KEYS = ("nu", "theta", "dtheta", "length", "dlength")

INFO_KEYS = ("nu", "theta", "dtheta", "length", "dlength", "ddlength", "tension", "tension_min",
             "theta_ref", "dtheta_ref", "reel_accel", "eccentricity", "failure") + COMPONENTS
"""Keys of the ``info`` dict, in order."""

_FAILURE_LABELS = tuple(Failure(code).label for code in range(len(Failure)))


def _check_options(options, n):
    """Validate reset options; return a dict of float arrays (or float for nu)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(set(options) - set(RESET_OPTION_KEYS))
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; "
                         f"valid keys: {list(RESET_OPTION_KEYS)}")
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
        self._par_nominal = config.param_row(config.eccentricity, config.masses)
        self.par = np.tile(self._par_nominal, (num, 1))
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
        self.with_params = config.with_params
        # config properties that build objects, evaluated once (step() runs per env step)
        self._accel_scale = config.accel_scale
        self._accel_reference = config.accel_reference
        self._length_nominal = np.asarray(config.initial_lengths, dtype=float)
        self._n_substeps = config.n_substeps
        self._length_min, self._length_max = config.length_bounds
        self._random_step = config.disturbance > 0.0 or config.obs_noise > 0.0
        self._all_rows = np.arange(num, dtype=np.int64)
        self._theta_ref = np.zeros(num)
        self._dtheta_ref = np.zeros(num)
        self._reel_accel = np.zeros((num, n))

    # ------------------------------------------------------------------ #
    def reset_row(self, b: int, rng: np.random.Generator, options=None) -> None:
        """Draw row b's parameters and initial state (options override the draw)."""
        cfg = self.config
        n = self.n
        opts = _check_options(options, n)
        ecc = cfg.eccentricity
        if cfg.randomised:
            masses = np.asarray(cfg.masses)
            if cfg.eccentricity_range is not None:
                ecc = float(rng.uniform(*cfg.eccentricity_range))
            if cfg.mass_range is not None:
                masses = masses * rng.uniform(1.0 - cfg.mass_range, 1.0 + cfg.mass_range, n)
            self.par[b] = cfg.param_row(ecc, masses)
        else:  # the nominal row, built once in __init__
            self.par[b] = self._par_nominal
        nu0 = float(opts.get("nu", cfg.initial_nu))
        ref, dref, _ = desired_libration(nu0, cfg.amplitude, cfg.frequency)
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
    def step(self, action: np.ndarray, rngs, rows: np.ndarray | None = None,
             n_chunks: int = 0) -> None:
        """One control step of every row, or of the rows listed in ``rows``.

        ``action`` is a float64 (num, n) array; ``rngs[b]`` draws row b's disturbance
        and noise. ``rows`` (int64 indices) leaves the other rows untouched (no
        physics, no random draws). ``n_chunks`` > 0 splits the rows into that many
        chunks run on numba's threads (bitwise the same results).
        """
        cfg = self.config
        if self._random_step:
            for b in (range(self.num) if rows is None else rows):
                if cfg.disturbance > 0.0:
                    self.dist[b] = rngs[b].uniform(-cfg.disturbance, cfg.disturbance, self.n)
                self._draw_noise(b, rngs[b])
        tail = (self.nu, self.y, action, cfg.max_reel_rate, self.dist, self.par,
                cfg.physics_step, self._n_substeps, cfg.amplitude, cfg.frequency, self.weights,
                self._length_min, self._length_max, self._accel_reference, self._length_nominal,
                self.with_params,
                self.noise, self.obs, self.reward, self.components, self.failure,
                self.tension_min, self.tension_end, self.deriv_end)
        if rows is None:
            rows = self._all_rows
        if n_chunks > 0:
            step_rows_parallel(rows, min(n_chunks, max(len(rows), 1)), *tail)
        else:
            step_rows(rows, *tail)
        self.steps[rows] += 1

    def truncated(self) -> np.ndarray:
        """Rows whose episode has reached its length in true anomaly."""
        return self.nu >= self.nu_end - 1e-9

    # ------------------------------------------------------------------ #
    def _derived(self, lo: int, hi: int) -> None:
        """Refresh theta_ref, dtheta_ref and reel_accel of rows lo..hi-1."""
        cfg = self.config
        if lo == 0 and hi == self.num:
            info_batch(self.nu, self.y, self.par, self.deriv_end, cfg.amplitude, cfg.frequency,
                       self._accel_scale, self._theta_ref, self._dtheta_ref, self._reel_accel)
        else:
            info_batch(self.nu[lo:hi], self.y[lo:hi], self.par[lo:hi], self.deriv_end[lo:hi],
                       cfg.amplitude, cfg.frequency, self._accel_scale,
                       self._theta_ref[lo:hi], self._dtheta_ref[lo:hi], self._reel_accel[lo:hi])

    def info(self, b: int) -> dict:
        """The documented ``info`` dict of row b (fresh arrays)."""
        n = self.n
        self._derived(b, b + 1)
        y = self.y[b].copy()
        comp = self.components[b].tolist()
        info = {
            "nu": float(self.nu[b]),
            "theta": y[:n],
            "dtheta": y[n:2 * n],
            "length": y[2 * n:3 * n],
            "dlength": y[3 * n:],
            "ddlength": self.deriv_end[b, 3 * n:].copy(),
            "tension": self.tension_end[b].copy(),
            "tension_min": self.tension_min[b].copy(),
            "theta_ref": float(self._theta_ref[b]),
            "dtheta_ref": float(self._dtheta_ref[b]),
            "reel_accel": self._reel_accel[b].copy(),
            "eccentricity": float(self.par[b, kernels.P_ECC]),
            "failure": _FAILURE_LABELS[self.failure[b]],
        }
        for name, value in zip(COMPONENTS, comp, strict=True):
            info[name] = value
        return info

    def info_arrays(self) -> dict:
        """Every row's :meth:`info` stacked: a dict of fresh (num, ...) arrays.

        Floats become float64 arrays of shape (num,), arrays (num, n), and
        ``"failure"`` an object array of None / labels: the layout of gymnasium's
        vector-env infos (without the ``_key`` masks).
        """
        n = self.n
        self._derived(0, self.num)
        y = self.y
        labels = np.empty(self.num, dtype=object)
        labels[:] = [_FAILURE_LABELS[code] for code in self.failure.tolist()]
        info = {
            "nu": self.nu.copy(),
            "theta": y[:, :n].copy(),
            "dtheta": y[:, n:2 * n].copy(),
            "length": y[:, 2 * n:3 * n].copy(),
            "dlength": y[:, 3 * n:].copy(),
            "ddlength": self.deriv_end[:, 3 * n:].copy(),
            "tension": self.tension_end.copy(),
            "tension_min": self.tension_min.copy(),
            "theta_ref": self._theta_ref.copy(),
            "dtheta_ref": self._dtheta_ref.copy(),
            "reel_accel": self._reel_accel.copy(),
            "eccentricity": self.par[:, kernels.P_ECC].copy(),
            "failure": labels,
        }
        for i, name in enumerate(COMPONENTS):
            info[name] = self.components[:, i].copy()
        return info
