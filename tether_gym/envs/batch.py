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

from ..tasks.reference import desired_libration, periodic_reel_rate
from ..tasks.reward import COMPONENTS
from ..tasks.termination import Failure
from .config import EnvConfig
from .step_kernel import (
    INFO_SCALARS,
    INFO_VECTORS,
    make_row_work,
    start_rows,
    step_rows,
    step_rows_parallel,
)

__all__ = ["ChainBatch", "RESET_OPTION_KEYS", "INFO_KEYS"]

RESET_OPTION_KEYS = ("nu", "theta", "dtheta", "length", "dlength")

INFO_KEYS = ("nu", "theta", "dtheta", "length", "dlength", "ddlength", "tension", "tension_min",
             "theta_ref", "dtheta_ref", "reel_accel", "eccentricity", "failure") + COMPONENTS
"""Keys of the ``info`` dict, in order."""

_FAILURE_LABELS = np.empty(len(Failure), dtype=object)
_FAILURE_LABELS[:] = [Failure(code).label for code in range(len(Failure))]

_SCALAR_KEYS = INFO_SCALARS + COMPONENTS
"""Keys of the rows of ChainBatch.info_s (INFO_VECTORS name those of info_v)."""


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
        # standard uniform / normal variates of each draw, and their rows as views
        # (built once: rng.random(out=...) then costs no view per draw)
        self._unit = np.zeros((num, n))
        self._gauss = np.zeros((num, 4 * n))
        self._unit_rows = list(self._unit)
        self._gauss_rows = list(self._gauss)
        self._all_rows = np.arange(num, dtype=np.int64)
        # info entries of every row, kept up to date by the kernels (see info)
        self.info_s = np.zeros((len(INFO_SCALARS) + len(COMPONENTS), num))
        self.info_v = np.zeros((len(INFO_VECTORS), num, n))
        self._work = make_row_work(n, 1)  # scratch of the kernels, one lane per thread chunk
        self._lanes = 1

    # ------------------------------------------------------------------ #
    def reset_rows(self, rows, rngs, options=None) -> None:
        """Draw the listed rows' parameters and initial states (options override the draw).

        ``rows`` is a sequence of row indices and ``rngs[b]`` row b's generator. Each
        row draws from its own generator in the single env's order (e, the masses,
        then theta, theta', l as one draw of 3n uniforms, then the observation noise);
        everything after the draws is computed for all the rows at once.
        """
        cfg = self.config
        n = self.n
        opts = _check_options(options, n)
        rows = np.asarray(rows, dtype=np.int64)
        count = rows.shape[0]
        ecc = np.full(count, cfg.eccentricity)
        scale = np.ones((count, n)) if cfg.mass_range is not None else None
        unit = np.empty((count, 3 * n))
        for i, b in enumerate(rows.tolist()):
            rng = rngs[b]
            if cfg.eccentricity_range is not None:
                ecc[i] = rng.uniform(*cfg.eccentricity_range)
            if scale is not None:
                scale[i] = rng.uniform(1.0 - cfg.mass_range, 1.0 + cfg.mass_range, n)
            unit[i] = rng.uniform(-1.0, 1.0, 3 * n)
            if cfg.obs_noise > 0.0:
                rng.standard_normal(out=self._gauss_rows[b])
        if cfg.obs_noise > 0.0:
            self._scale_noise(rows)
        if cfg.randomised:
            masses = np.asarray(cfg.masses, dtype=float)
            self.par[rows] = cfg.param_rows(ecc, masses if scale is None else masses * scale)
        else:  # the nominal row, built once in __init__
            self.par[rows] = self._par_nominal
        nu0 = float(opts.get("nu", cfg.initial_nu))
        ref, dref, _ = desired_libration(nu0, cfg.amplitude, cfg.frequency)
        shape = (count, n)
        theta = (np.broadcast_to(opts["theta"], shape) if "theta" in opts else
                 np.asarray(cfg.initial_theta) + unit[:, :n] * cfg.init_theta_range)
        dtheta = (np.broadcast_to(opts["dtheta"], shape) if "dtheta" in opts else
                  dref + unit[:, n:2 * n] * cfg.init_dtheta_range)
        length = (np.broadcast_to(opts["length"], shape) if "length" in opts else
                  np.asarray(cfg.initial_lengths) + unit[:, 2 * n:] * cfg.init_length_range)
        # Reels start at the rate of the open-loop law (paper Eq. 10) on the reference.
        dlength = (np.broadcast_to(opts["dlength"], shape) if "dlength" in opts else
                   periodic_reel_rate(nu0, ref, dref, length, ecc[:, None], cfg.amplitude,
                                      cfg.frequency))
        self.nu[rows] = nu0
        self.nu_end[rows] = nu0 + cfg.episode_length
        self.y[rows] = np.concatenate([theta, dtheta, length, dlength], axis=1)
        self.steps[rows] = 0
        self.failure[rows] = 0
        self.reward[rows] = 0.0
        self.components[rows] = 0.0
        start_rows(rows, self.nu, self.y, self.par, cfg.amplitude, cfg.frequency,
                   self.with_params, self.noise, self.obs, self.components, self.tension_min,
                   self.tension_end, self.deriv_end, self._accel_scale, self.info_s,
                   self.info_v, self._work)

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
            self._draw_step_noise(rngs, rows)
        tail = (self.nu, self.y, action, cfg.max_reel_rate, self.dist, self.par,
                cfg.physics_step, self._n_substeps, cfg.amplitude, cfg.frequency, self.weights,
                self._length_min, self._length_max, self._accel_reference, self._length_nominal,
                self.with_params,
                self.noise, self.obs, self.reward, self.components, self.failure,
                self.tension_min, self.tension_end, self.deriv_end, self._accel_scale,
                self.info_s, self.info_v)
        if rows is None:
            rows = self._all_rows
        if n_chunks > 0:
            n_chunks = min(n_chunks, max(len(rows), 1))
            if n_chunks > self._lanes:
                self._work = make_row_work(self.n, n_chunks)
                self._lanes = n_chunks
            step_rows_parallel(rows, n_chunks, *tail, self._work)
        else:
            step_rows(rows, *tail, self._work)
        self.steps[rows] += 1

    def _draw_step_noise(self, rngs, rows) -> None:
        """This step's disturbance and observation noise of every row (or of ``rows``).

        Row b draws from ``rngs[b]`` exactly what ``uniform(-d, d, n)`` and then
        ``normal(0, sigma, 4n)`` draw: the standard variates go straight into
        preallocated rows (``out=``), and the scaling, numpy's own
        ``low + (high - low) u`` and ``0 + sigma z``, is done for all rows at once.
        """
        cfg = self.config
        d, sigma = cfg.disturbance, cfg.obs_noise
        for b in (range(self.num) if rows is None else rows.tolist()):
            rng = rngs[b]
            if d > 0.0:
                rng.random(out=self._unit_rows[b])
            if sigma > 0.0:
                rng.standard_normal(out=self._gauss_rows[b])
        sel = slice(None) if rows is None else rows
        if d > 0.0:
            self.dist[sel] = -d + (d - -d) * self._unit[sel]
        if sigma > 0.0:
            self._scale_noise(sel)

    def _scale_noise(self, sel) -> None:
        """noise = sigma z for the rows ``sel`` (numpy's ``normal(0, sigma)`` of the
        standard variates z drawn into ``_gauss``)."""
        self.noise[sel] = self.config.obs_noise * self._gauss[sel]

    def truncated(self) -> np.ndarray:
        """Rows whose episode has reached its length in true anomaly."""
        return self.nu >= self.nu_end - 1e-9

    # ------------------------------------------------------------------ #
    def info(self, b: int) -> dict:
        """The documented ``info`` dict of row b (floats and fresh (n,) arrays)."""
        return _info_dict(self.info_s[:, b].tolist(), self.info_v[:, b].copy(),
                          _FAILURE_LABELS[self.failure[b]])

    def info_arrays(self) -> dict:
        """Every row's :meth:`info` stacked: a dict of fresh (num, ...) arrays.

        Floats become float64 arrays of shape (num,), arrays (num, n), and
        ``"failure"`` an object array of None / labels: the layout of gymnasium's
        vector-env infos (without the ``_key`` masks). The entries are views of two
        fresh copies of the info buffers that the kernels keep up to date.
        """
        return _info_dict(self.info_s.copy(), self.info_v.copy(), _FAILURE_LABELS[self.failure])


def _info_dict(scalars, vectors, failure) -> dict:
    """The info dict in INFO_KEYS order from the rows of the two info buffers."""
    values = dict(zip(_SCALAR_KEYS, scalars, strict=True))
    values.update(zip(INFO_VECTORS, vectors, strict=True))
    values["failure"] = failure
    return {key: values[key] for key in INFO_KEYS}
