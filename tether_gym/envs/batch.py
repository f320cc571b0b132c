"""State of a batch of libration environments, shared by the single and vector env.

Each row has its own random generator, so row b of a vector env seeded with s_b
draws exactly what a single env seeded with s_b draws, in the same order: at reset
the randomised parameters (e, then the masses), then the initial perturbations
(theta, theta', l), then the observation noise; at each step the disturbance, then
the observation noise.

:meth:`ChainBatch.step` can advance a subset of the rows (the vector env leaves the
rows it is about to auto-reset alone) and can spread the rows over worker threads;
every row runs the same compiled code either way, so the results do not change.
Threads are Python threads that run the compiled step on contiguous chunks of rows
without the GIL, each with its own scratch (:mod:`.workers`).
"""

from __future__ import annotations

import os
import time
import warnings
import weakref
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from ..physics.dispatch import Direct
from ..physics.kernels import Substeps
from ..physics.state import PARAMS, STATE
from ..tasks.cost import COST_NAMES, cost_terms
from ..tasks.reference import (
    desired_libration,
    expand_like,
    periodic_reel_factors,
    periodic_reel_rate,
)
from ..tasks.reward import COMPONENTS
from ..tasks.termination import TUMBLE_ANGLE, Failure
from .config import EnvConfig
from .layout import N_INFO_SCALARS, N_INFO_VECTORS, I, info_dict
from .step_kernel import Rows, StepConfig, new_row_work, step_rows
from .workers import SLOTS, Relay, SpinWorker, yield_function

__all__ = ["ChainBatch", "RESET_OPTION_KEYS", "check_options", "check_startable"]

RESET_OPTION_KEYS = ("nu",) + STATE.names
"""Keys of ``reset(options=...)``: the true anomaly and every state field."""


OPTION_BOUNDS = {"nu": 1.0e4, "dtheta": 10.0, "dlength": 10.0}
"""Largest magnitude of the unbounded reset options [rad, rad/rad, -]."""

LEAD_MARGIN = 2.0
"""Rows by which a threaded step's workers should end before the calling thread [-]."""

GIVE_UP, CAN_THREAD = yield_function()
"""The address of the workers' yield function, and whether it is a real one (else every
step is serial)."""

MAX_RESET_DRAWS = 1000
"""Draws per row and reset before its episode starts failed (:meth:`ChainBatch.reset_rows`).

A row that passes within the first 100 draws (the limit before) draws exactly what it
drew before; only rows that exhausted 100 draws (which raised then) draw more."""


def check_options(options, config: EnvConfig) -> dict:
    """Validate reset options; return a dict of float arrays (or a float for nu).

    Raises
    ------
    TypeError
        If ``options`` is not a dict or a value is not real numbers (bools included).
    ValueError
        On an unknown key, a wrong shape, NaN/inf or a value outside its range: theta in
        (-pi/2, pi/2), length inside ``length_bounds``, the others within OPTION_BOUNDS.
    """
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(set(options) - set(RESET_OPTION_KEYS))
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; "
                         f"valid keys: {list(RESET_OPTION_KEYS)}")
    n = config.n_tethers
    out = {}
    for key, value in options.items():
        raw = np.asarray(value)
        if raw.dtype.kind not in "iuf":
            raise TypeError(f"options[{key!r}]={value!r} must be real numbers, got dtype "
                            f"{raw.dtype}")
        arr = raw.astype(float)
        if key == "nu":
            if arr.shape != ():
                raise ValueError(f"options['nu']={value!r} must be a scalar [rad]")
        elif arr.shape != (n,):
            raise ValueError(f"options[{key!r}]={value!r} must have shape ({n},), got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"options[{key!r}]={value!r} must be finite")
        bound = OPTION_BOUNDS.get(key)
        if bound is not None and np.any(np.abs(arr) > bound):
            raise ValueError(f"options[{key!r}]={value!r} must lie in [-{bound:g}, {bound:g}]")
        out[key] = arr
    if "theta" in out and np.any(np.abs(out["theta"]) >= 0.5 * np.pi):
        raise ValueError(f"options['theta']={options['theta']!r} must lie in (-pi/2, pi/2)")
    lo, hi = config.episode.length_bounds
    if "length" in out and not np.all((out["length"] > lo) & (out["length"] < hi)):
        raise ValueError(f"options['length']={options['length']!r} must lie inside "
                         f"length_bounds=({lo:g}, {hi:g})")
    return out


def zero_rows(config: EnvConfig, num: int, zeros: Callable) -> Rows:
    """The per-row arrays of ``num`` rows (:class:`Rows`), zeroed: their one declaration.

    ``zeros(shape, dtype)`` allocates one array (``np.zeros``, or an allocator on
    another device); dtypes are numpy's: float64, float32 (the observation), int64
    (failure codes, step counts) and bool (truncation).
    """
    n = config.n_tethers
    m = STATE.size(n)
    f8 = np.dtype(np.float64)
    return Rows(
        nu=zeros((num,), f8), y=zeros((num, m), f8), par=zeros((num, PARAMS.size(n)), f8),
        disturbance=zeros((num, n), f8), noise=zeros((num, m), f8),
        obs=zeros((num, config.obs_dim), np.dtype(np.float32)),
        reward=zeros((num,), f8), components=zeros((num, len(COMPONENTS)), f8),
        cost=zeros((num, len(COST_NAMES)), f8),
        failure=zeros((num,), np.dtype(np.int64)),
        tension_min=zeros((num, n), f8), tension=zeros((num, n), f8),
        derivative=zeros((num, m), f8),
        info_s=zeros((N_INFO_SCALARS, num), f8), info_v=zeros((N_INFO_VECTORS, num, n), f8),
        steps=zeros((num,), np.dtype(np.int64)), nu_end=zeros((num,), f8),
        truncated=zeros((num,), np.dtype(np.bool_)), command=zeros((num, n), f8))


def step_config(config: EnvConfig) -> StepConfig:
    """The compiled step's constants for a configuration."""
    lo, hi = config.episode.length_bounds
    observed = config.observed
    return StepConfig(
        max_reel_rate=float(config.reels.max_rate),
        incremental=config.action.mode == "increment",
        increment_gain=float(config.action.increment_gain),
        substeps=Substeps(float(config.episode.physics_step), config.n_substeps),
        amplitude=float(config.reference.amplitude),
        frequency=float(config.reference.frequency),
        length_min=lo, length_max=hi,
        accel_ref=float(config.accel_reference),
        accel_scale=float(config.scales.accel),
        with_eccentricity=observed["eccentricity"],
        with_masses=observed["masses"],
        reward=config.reward_weights.record(),
        length_nominal=np.asarray(config.chain.initial_lengths, dtype=float),
        cost=config.cost_thresholds.record((lo, hi)))


def _stop_workers(workers: list[SpinWorker]) -> None:
    """Stop and forget the worker threads of a batch (also when it is garbage collected)."""
    while workers:
        workers.pop().stop()


def _obs_bias(config: EnvConfig) -> np.ndarray:
    """(m,) constant offsets of the observed state entries: ``obs_bias`` on each theta_i.

    The observation noise of a step is drawn on top of it (:meth:`ChainBatch._scale_noise`).
    """
    bias = np.zeros(STATE.size(config.n_tethers))
    bias[STATE.slices(config.n_tethers)["theta"]] = config.obs_bias
    return bias


class StartPlan(NamedTuple):
    """What every reset of one configuration reads, read from the config once.

    The reset of a few rows of a vector env costs mostly Python and NumPy call
    overhead, so the values are kept here instead of being looked up through the
    config's parts, and the parts of the start that do not depend on the draws (the
    reference at the configured nu(0), and Eq. 10's factors when e is fixed) are
    computed once, by the same expressions, so the start is bitwise the same.
    """

    eccentricity: float
    masses: np.ndarray
    randomised: bool
    eccentricity_range: tuple | None
    mass_range: float | None
    obs_noise: float
    init_dtheta_range: float
    amplitude: float
    frequency: float
    nu0: float
    ref: float
    dref: float
    eq10: tuple | None  # (num, den) of Eq. 10 at nu0 and the fixed e; None when e is drawn
    #   (or when a den is 0)
    episode_length: float
    slices: dict  # STATE's slices for n tethers (the first three also index a start)
    start_base: np.ndarray  # (3n,) initial theta, theta_d'(nu0), initial lengths
    start_spread: np.ndarray  # (3n,) their init_*_range
    state_low: np.ndarray  # (4n,) a start state row must lie strictly inside these
    state_high: np.ndarray

    @classmethod
    def of(cls, config: EnvConfig) -> StartPlan:
        """The plan of ``config``."""
        rnd = config.randomisation
        nu0 = float(config.initial_nu)
        amplitude, frequency = config.amplitude, config.frequency
        ref, dref, _ = desired_libration(nu0, amplitude, frequency)
        eq10 = None
        if rnd.eccentricity_range is None:
            like = np.zeros((1, config.n_tethers))
            eq10 = periodic_reel_factors(expand_like(nu0, like), expand_like(ref, like),
                                         expand_like(dref, like),
                                         np.full((1, 1), config.eccentricity),
                                         amplitude, frequency)
            if not np.all(eq10[1] != 0.0):
                eq10 = None  # every start fails: check_startable refuses the config
        if STATE.names != ("theta", "dtheta", "length", "dlength"):
            raise RuntimeError(f"StartPlan assumes the state order theta, dtheta, length, "
                               f"dlength, not {STATE.names}")
        n = config.n_tethers
        theta0 = np.asarray(config.initial_theta, dtype=float)
        lengths0 = np.asarray(config.initial_lengths, dtype=float)
        ones = np.ones(n)
        lo, hi = config.episode.length_bounds
        # theta in (-pi/2, pi/2), l in [lo, hi] (the next floats out make it strict),
        # theta' and l' finite: the start conditions of _failed_at_start, one comparison
        bounds = {"theta": (-0.5 * np.pi, 0.5 * np.pi), "dtheta": (-np.inf, np.inf),
                  "length": (np.nextafter(lo, -np.inf), np.nextafter(hi, np.inf)),
                  "dlength": (-np.inf, np.inf)}
        return cls(
            eccentricity=config.eccentricity,
            masses=np.asarray(config.masses, dtype=float),
            randomised=config.randomised,
            eccentricity_range=rnd.eccentricity_range,
            mass_range=rnd.mass_range,
            obs_noise=rnd.obs_noise,
            init_dtheta_range=rnd.init_dtheta_range,
            amplitude=amplitude,
            frequency=frequency,
            nu0=nu0,
            ref=ref,
            dref=dref,
            eq10=eq10,
            episode_length=config.episode_length,
            slices=STATE.slices(n),
            start_base=np.concatenate([theta0, dref * ones, lengths0]),
            start_spread=np.concatenate([rnd.init_theta_range * ones,
                                         rnd.init_dtheta_range * ones,
                                         rnd.init_length_range * ones]),
            state_low=np.concatenate([bounds[name][0] * ones for name in STATE.names]),
            state_high=np.concatenate([bounds[name][1] * ones for name in STATE.names]))


def check_startable(config: EnvConfig) -> None:
    """Refuse a configuration whose every start is failed, as far as that is certain.

    Two cases are decided from the configuration alone: theta_d'(initial_nu) = -1 (the
    reels' start rate, paper Eq. 10, divides by 1 + theta_d' = 0 whatever is drawn), and
    a start with nothing drawn (the init_*_range arguments 0, e and the masses fixed)
    that fails. Any other configuration has starts that pass with some probability
    (every draw range holds its nominal value, which lies inside the bounds); a row
    whose draws all fail starts failed instead (:meth:`ChainBatch.reset_rows`).

    Raises
    ------
    ValueError
        Naming the arguments that fix the failed start and the bounds it must meet.
    """
    plan = StartPlan.of(config)
    if 1.0 + plan.dref == 0.0:
        raise ValueError(
            f"amplitude={config.amplitude!r}, frequency={config.frequency!r} and "
            f"initial_nu={config.initial_nu!r} give theta_d'(initial_nu) = -1: the reels' "
            "start rate (paper Eq. 10) divides by 1 + theta_d' = 0, so every start is "
            "failed; choose them so that amplitude * frequency * cos(frequency * "
            "initial_nu) != -1")
    rnd = config.randomisation
    if config.randomised or any((rnd.init_theta_range, rnd.init_dtheta_range,
                                 rnd.init_length_range)):
        return
    probe = ChainBatch(config, 1, check_start=False)
    first = np.zeros(1, dtype=np.int64)
    probe._draw_rows(first, [np.random.default_rng(0)], {})
    if probe._failed_at_start(first)[0]:
        lo, hi = config.episode.length_bounds
        raise ValueError(
            f"every start of this configuration is failed ({probe._start_code(0)}: "
            f"{probe._start_failure(0)}) and nothing is drawn (init_theta_range, "
            "init_dtheta_range and init_length_range are 0, eccentricity and masses "
            f"fixed): change initial_theta={config.initial_theta!r}, initial_lengths="
            f"{config.initial_lengths!r}, or amplitude, frequency and initial_nu (theta'(0) "
            f"= theta_d'(initial_nu) = {plan.dref:.4g}), so that the start has every "
            f"|theta_i| < pi/2, every l_i inside length_bounds=({lo:g}, {hi:g}) and every "
            "tension T^_i > 0")


class ChainBatch:
    """Arrays and step logic for ``num`` environments with one :class:`EnvConfig`.

    Building one refuses a configuration whose every start is failed
    (:func:`check_startable`; ``check_start=False`` skips that).
    """

    def __init__(self, config: EnvConfig, num: int, *, check_start: bool = True):
        if check_start:
            check_startable(config)
        self.config = config
        self.num = num
        n = config.n_tethers
        self.n = n
        m = STATE.size(n)
        self._bias = _obs_bias(config)
        self._par_nominal = config.param_rows(config.eccentricity, config.masses)
        self.rows = zero_rows(config, num, np.zeros)
        self.rows.par[:] = self._par_nominal
        self.rows.noise[:] = self._bias
        self.cfg = step_config(config)
        self._plan = StartPlan.of(config)
        self._random_step = config.disturbance > 0.0 or config.obs_noise > 0.0
        # standard uniform / normal variates of each draw, and their rows as views
        # (built once: rng.random(out=...) then costs no view per draw)
        self._unit = np.zeros((num, n))
        self._gauss = np.zeros((num, m))
        self._unit_rows = list(self._unit)
        self._gauss_rows = list(self._gauss)
        self._all_rows = np.arange(num, dtype=np.int64)
        self._no_action = np.zeros((num, n))
        self._step = Direct(step_rows)
        self._once = Relay(np.zeros(SLOTS, dtype=np.int64), GIVE_UP, 0)  # not a worker
        self._work = [new_row_work(n)]  # one scratch per thread
        self._workers: list[SpinWorker] = []  # started by the first threaded step
        self._lead = 0.0  # extra rows of this thread's chunk in a threaded step
        # a threaded step's rows and actions, where the workers read them
        self._index_buf = np.zeros(num, dtype=np.int64)
        self._action_buf = np.zeros((num, n))
        self._finalizer = weakref.finalize(self, _stop_workers, self._workers)
        # rows whose episode starts failed (every draw failed) and their failure codes
        self._start_failed = np.zeros(num, dtype=np.bool_)
        self._start_codes = np.zeros(num, dtype=np.int64)
        self._any_start_failed = False
        self._warned = False

    # views kept for readability (the arrays live in self.rows)
    @property
    def y(self) -> np.ndarray:
        """State rows (STATE layout), (num, 4n)."""
        return self.rows.y

    @property
    def par(self) -> np.ndarray:
        """Parameter rows (PARAMS layout), (num, P)."""
        return self.rows.par

    @property
    def obs(self) -> np.ndarray:
        """Observations (OBSERVATION layout), float32 (num, obs_dim)."""
        return self.rows.obs

    @property
    def reward(self) -> np.ndarray:
        """Reward of each row's last step, (num,)."""
        return self.rows.reward

    @property
    def failure(self) -> np.ndarray:
        """Failure code of each row (0 while healthy), int64 (num,)."""
        return self.rows.failure

    @property
    def steps(self) -> np.ndarray:
        """Control steps since each row's reset, int64 (num,)."""
        return self.rows.steps

    # ------------------------------------------------------------------ #
    def reset_rows(self, rows, rngs, options=None) -> None:
        """Draw the listed rows' parameters and initial states (options override the draw).

        ``rows`` is a sequence of row indices and ``rngs[b]`` row b's generator. Each
        row draws from its own generator in the single env's order (e, the masses,
        then theta, theta', l as one draw of 3n uniforms, then the observation noise);
        everything after the draws is computed for all the rows at once. A row whose
        drawn initial state is already failed (slack, tumbled, a length out of bounds or
        non-finite) draws again from its generator, up to MAX_RESET_DRAWS times. If
        every draw failed, the row's episode starts failed, without an error (this can
        happen inside a vector env's step, at an autoreset): it keeps its last draw,
        ``info["failure"]`` names the reason, and its next :meth:`step` ends it.

        Raises
        ------
        ValueError
            If the options fix a failed initial state, or the draws of a start with
            options keep failing (the options are the caller's; no autoreset has any).
        """
        opts = check_options(options, self.config)
        rows = np.asarray(rows, dtype=np.int64)
        if self._any_start_failed:
            self._start_failed[rows] = False
            self._any_start_failed = bool(self._start_failed.any())
        for _ in range(MAX_RESET_DRAWS):
            self._draw_rows(rows, rngs, opts)
            failed = rows[self._failed_at_start(rows)]
            if failed.size == 0:
                return
            if set(opts) & set(STATE.names):
                b = int(failed[0])
                raise ValueError(f"reset options {options!r} give a failed initial state: "
                                 f"{self._start_failure(b)}")
            rows = failed  # redraw those rows from their generators, within the ranges
        if opts:
            raise ValueError(f"reset options {options!r}: the start is still failed after "
                             f"{MAX_RESET_DRAWS} draws in {len(rows)} row(s), e.g. "
                             f"{self._start_failure(int(rows[0]))}; narrow the init_*_range "
                             "arguments or choose options away from the failure bounds")
        self._begin_failed(rows)

    def _begin_failed(self, rows: np.ndarray) -> None:
        """Let the listed rows' episodes start failed; warn once per batch.

        Their last draw stays, ``info`` reports the failure, and their next :meth:`step`
        ends them (:meth:`_end_failed_starts`).
        """
        for b in rows.tolist():
            code = self._start_code(b)
            self._start_codes[b] = code
            self.rows.info_s[I.failure[0], b] = code
        self._start_failed[rows] = True
        self._any_start_failed = True
        if not self._warned:
            self._warned = True
            warnings.warn(
                f"{MAX_RESET_DRAWS} draws of the start failed in {len(rows)} row(s), e.g. "
                f"{self._start_failure(int(rows[0]))}: such an episode starts failed "
                "(info['failure'] at the reset) and ends at its first step with reward 0; "
                "narrow the init_*_range arguments or move initial_theta / "
                "initial_lengths away from the failure bounds (said once per env)",
                RuntimeWarning, stacklevel=4)

    def _failed_at_start(self, rows: np.ndarray) -> np.ndarray:
        """Mask of the listed rows whose initial state is non-finite or failed.

        Failed: a theta_i outside (-pi/2, pi/2), a length outside ``length_bounds`` or a
        tension T^_i <= 0.

        (Checked here rather than in the compiled reset, where it was tried: it saved
        some Python per reset call but added to the compile time of every cold start.)
        """
        plan = self._plan
        y = self.rows.y[rows]
        tension = self.rows.tension[rows]
        # NaN fails every comparison, +-inf one of each pair
        ok = ((y > plan.state_low) & (y < plan.state_high)).all(axis=1)
        ok &= ((tension > 0.0) & (tension < np.inf)).all(axis=1)
        return ~ok

    def _start_code(self, b: int) -> Failure:
        """Why row b's failed start is failed, as :func:`failure_code` orders the reasons.

        (The start check has no divergence bound, so a failed start is non-finite, slack,
        tumbled or out of length bounds.)
        """
        sl = self._plan.slices
        y, tension = self.rows.y[b], self.rows.tension[b]
        if not (np.isfinite(y).all() and np.isfinite(tension).all()):
            return Failure.NONFINITE
        if (tension <= 0.0).any():
            return Failure.SLACK
        if (np.abs(y[sl["theta"]]) >= TUMBLE_ANGLE).any():
            return Failure.TUMBLE
        return Failure.LENGTH

    def _start_failure(self, b: int) -> str:
        """Why row b's initial state fails, in words."""
        sl = self._plan.slices
        y = self.rows.y[b]
        return (f"theta={y[sl['theta']].round(4).tolist()}, "
                f"l={y[sl['length']].round(4).tolist()}, "
                f"T^={self.rows.tension[b].round(4).tolist()}")

    def _draw_rows(self, rows: np.ndarray, rngs, opts: dict) -> None:
        """One draw of the listed rows' parameters and initial states, then their start."""
        plan = self._plan
        mass_range = 0.0 if plan.mass_range is None else plan.mass_range
        n = self.n
        count = rows.shape[0]
        ecc = np.full(count, plan.eccentricity)
        scale = np.ones((count, n)) if plan.mass_range is not None else None
        unit = np.empty((count, 3 * n))
        noise = plan.obs_noise > 0.0
        for i, b in enumerate(rows.tolist()):
            rng = rngs[b]
            if plan.eccentricity_range is not None:
                ecc[i] = rng.uniform(*plan.eccentricity_range)
            if scale is not None:
                scale[i] = rng.uniform(1.0 - mass_range, 1.0 + mass_range, n)
            unit[i] = rng.uniform(-1.0, 1.0, 3 * n)
            if noise:
                rng.standard_normal(out=self._gauss_rows[b])
        if noise:
            self._scale_noise(rows)
        r = self.rows
        if plan.randomised:
            masses = plan.masses
            r.par[rows] = self.config.param_rows(ecc, masses if scale is None else masses * scale)
        else:  # the nominal row, built once in __init__
            r.par[rows] = self._par_nominal
        nu0 = float(opts["nu"]) if "nu" in opts else plan.nu0
        at_plan = nu0 == plan.nu0
        if at_plan:
            ref, dref = plan.ref, plan.dref
        else:
            ref, dref, _ = desired_libration(nu0, plan.amplitude, plan.frequency)
        # theta, theta', l (STATE's first three fields, in its order: StartPlan.of checks
        # it) from the draws, then what the options fix
        sl = plan.slices
        start = plan.start_base + unit * plan.start_spread
        if "dtheta" not in opts and not at_plan:  # theta_d' at another nu(0)
            start[:, sl["dtheta"]] = dref + unit[:, sl["dtheta"]] * plan.init_dtheta_range
        for name in ("theta", "dtheta", "length"):
            if name in opts:
                start[:, sl[name]] = opts[name]
        length = start[:, sl["length"]]
        # Reels start at the rate of the open-loop law (paper Eq. 10) on the reference
        # (infinite where theta_d' = -1: such a start is refused below)
        if "dlength" in opts:
            dlength = np.broadcast_to(opts["dlength"], (count, n))
        elif at_plan and plan.eq10 is not None:  # periodic_reel_rate's last line
            num, den = plan.eq10  # den != 0 (StartPlan.of)
            dlength = length * num / den
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                dlength = periodic_reel_rate(nu0, ref, dref, length, ecc[:, None],
                                             plan.amplitude, plan.frequency)
        r.nu[rows] = nu0
        r.nu_end[rows] = nu0 + plan.episode_length
        r.y[rows] = np.concatenate((start, dlength), axis=1)
        r.failure[rows] = 0
        r.reward[rows] = 0.0
        r.components[rows] = 0.0
        r.cost[rows] = 0.0
        self._step(rows, self._no_action, r, self.cfg, self._work[0], True, self._once)

    # ------------------------------------------------------------------ #
    def step(self, action: np.ndarray, rngs, rows: np.ndarray | None = None,
             n_chunks: int = 0, *, checked: bool = False,
             meanwhile: Callable[[], object] | None = None) -> None:
        """One control step of every row, or of the rows listed in ``rows``.

        ``action`` is a C-contiguous float64 (num, n) array; ``rngs[b]`` draws row b's
        disturbance and noise. ``rows`` (int64 indices) leaves the other rows
        untouched (no physics, no random draws). ``n_chunks`` > 1 splits the rows into
        that many contiguous chunks run on threads (bitwise the same results).
        ``checked`` says the caller has checked that every action is finite.
        ``meanwhile`` is called on this thread, while the worker threads step their
        chunks (after the step when it is not threaded): work on other rows, such as the
        vector env's autoresets, that then costs no time of its own. It must not touch
        the stepped rows or their generators.

        Raises
        ------
        ValueError
            If a stepped row's action is NaN or inf; then nothing has changed.
        """
        index = self._all_rows if rows is None else rows
        if self._any_start_failed:
            index = rows = self._end_failed_starts(action, index, checked)
            checked = True
        threaded = n_chunks > 1 and len(index) > 1 and CAN_THREAD
        if self._random_step or threaded:
            if not checked:
                bad = self._check_finite(action, index)
                if bad >= 0:
                    self._raise_not_finite(action, bad)
            if self._random_step:
                self._draw_step_noise(rngs, rows)
        if threaded:
            self._step_threaded(action, index, min(n_chunks, len(index)), meanwhile)
            return
        # the kernel checks the actions before it steps any row
        bad = self._step(index, action, self.rows, self.cfg, self._work[0], False, self._once)
        if bad >= 0:
            self._raise_not_finite(action, bad)
        if meanwhile is not None:
            meanwhile()

    def _end_failed_starts(self, action: np.ndarray, index: np.ndarray,
                           checked: bool) -> np.ndarray:
        """End the listed rows whose episode started failed; return the other rows.

        Their step sets the failure code of the start, its cost (of the start's state:
        at least 1, as every failing step's) and counts the step; nothing else changes
        (the reward stays 0, the observation is the start's) and they draw nothing. The
        actions of every listed row are checked first.

        Raises
        ------
        ValueError
            If a listed row's action is NaN or inf; then nothing has changed.
        """
        if not checked:
            bad = self._check_finite(action, index)
            if bad >= 0:
                self._raise_not_finite(action, bad)
        stuck = self._start_failed[index]
        if not stuck.any():
            return index
        ended = index[stuck]
        self.rows.failure[ended] = self._start_codes[ended]
        self.rows.steps[ended] += 1
        r = self.rows
        for b in ended.tolist():  # the ending step costs what the failed start costs
            cost_terms(r.y[b], self.n, r.tension_min[b], self.cfg.cost, r.cost[b])
            r.info_s[I.cost[0]:I.cost[0] + r.cost.shape[1], b] = r.cost[b]
        self._start_failed[ended] = False
        self._any_start_failed = bool(self._start_failed.any())
        return index[~stuck]

    @staticmethod
    def _raise_not_finite(action: np.ndarray, bad: int) -> None:
        raise ValueError(f"actions must be finite (no NaN or inf); row {bad} is not: "
                         f"{action[bad]!r}")

    def _check_finite(self, action: np.ndarray, index: np.ndarray) -> int:
        """-1 if the listed rows' actions are finite, else the first bad row."""
        ok = np.isfinite(action[index]).all(axis=1)
        return -1 if ok.all() else int(index[np.argmin(ok)])

    def _step_threaded(self, action: np.ndarray, rows: np.ndarray, n_chunks: int,
                       meanwhile: Callable[[], object] | None) -> None:
        """Chunks 1.. on the worker threads, then ``meanwhile()`` and chunk 0 on this one.

        This thread's chunk is longer than the workers' by ``self._lead`` rows (shorter
        when negative: ``meanwhile`` took time), adjusted after every step
        (:meth:`_adjust_lead`) so that the workers finish just before this thread does;
        which thread steps a row does not change its result.
        """
        while len(self._work) < n_chunks:
            self._work.append(new_row_work(self.n))
        if self._workers and self._workers[0].pid != os.getpid():
            self._workers.clear()  # inherited through a fork: their threads stayed behind
        while len(self._workers) < n_chunks - 1:
            work = self._work[len(self._workers) + 1]
            self._workers.append(SpinWorker(
                self._step, (self._index_buf, self._action_buf, self.rows, self.cfg, work,
                             False), GIVE_UP))
        count = len(rows)
        self._index_buf[:count] = rows
        self._action_buf[...] = action
        most = count // n_chunks
        lead = min(max(int(self._lead), -most), most)
        share = (count - lead) / n_chunks
        bounds = [0] + [lead + round(c * share) for c in range(1, n_chunks)] + [count]
        jobs = [self._workers[c - 1].start(bounds[c], bounds[c + 1])
                for c in range(1, n_chunks)]
        try:
            if meanwhile is not None:
                meanwhile()
            start = time.perf_counter()
            self._step(self._index_buf[:bounds[1]], self._action_buf, self.rows, self.cfg,
                       self._work[0], False, self._once)
            end = time.perf_counter()
        finally:  # never return (or raise) while a worker is still writing the rows
            polls = sum(self._workers[c - 1].wait(jobs[c - 1]) for c in range(1, n_chunks))
        waited = time.perf_counter() - end
        per_row = (end - start) / max(bounds[1], 1)
        # a worker that was done when this thread looked may have been so by any margin:
        # then the lead shrinks by half a row (LEAD_MARGIN + 1 rows early, as it were)
        late = waited if polls else -(LEAD_MARGIN + 1.0) * per_row
        self._adjust_lead(late, per_row, most)

    def _adjust_lead(self, late: float, per_row: float, most: int) -> None:
        """Move the lead towards workers that end ``LEAD_MARGIN`` rows before this thread.

        ``late`` [s] is how much later than this thread the last worker ended (negative:
        earlier), ``per_row`` [s] this thread's time per row; half the error is corrected
        per step (a damped loop: single steps jitter), within [-``most``, ``most``] rows.
        """
        if per_row > 0.0:
            error = late / per_row + LEAD_MARGIN
            self._lead = min(max(self._lead + 0.5 * error, -float(most)), float(most))

    def close(self) -> None:
        """Stop the worker threads (if any were started)."""
        _stop_workers(self._workers)

    def _draw_step_noise(self, rngs, rows) -> None:
        """Draw this step's disturbance and observation noise of every row (or of ``rows``).

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
            self.rows.disturbance[sel] = -d + (d - -d) * self._unit[sel]
        if sigma > 0.0:
            self._scale_noise(sel)

    def _scale_noise(self, sel) -> None:
        """Set noise = sigma z for the rows ``sel``.

        This is numpy's ``normal(0, sigma)`` of the standard variates z drawn into
        ``_gauss``.
        """
        self.rows.noise[sel] = self.config.obs_noise * self._gauss[sel]
        if self.config.obs_bias:
            self.rows.noise[sel] += self._bias

    def truncated(self) -> np.ndarray:
        """Rows whose episode has reached its length in true anomaly."""
        return self.rows.truncated

    # ------------------------------------------------------------------ #
    def info(self, b: int) -> dict:
        """The documented ``info`` dict of row b (floats and fresh (n,) arrays)."""
        return info_dict(self.rows.info_s[:, b].tolist(), self.rows.info_v[:, b].copy())

    def info_arrays(self) -> dict:
        """Every row's :meth:`info` stacked: a dict of fresh (num, ...) arrays.

        Floats become float64 arrays of shape (num,), arrays (num, n), and
        ``"failure"`` an object array of None / labels: the layout of gymnasium's
        vector-env infos (without the ``_key`` masks). The entries are views of two
        fresh copies of the info buffers that the kernel keeps up to date.
        """
        return info_dict(self.rows.info_s.copy(), self.rows.info_v.copy())
