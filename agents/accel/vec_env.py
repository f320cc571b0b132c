"""``TorchTetherVecEnv``: thousands of libration envs stepped as torch tensors, on any device.

The batched twin of ``gym.make_vec("tether_gym/TetherLibration-v2", num_envs=B)`` for
learners that live on an accelerator: the state, the parameters, the observations and
every per-step quantity stay on ``device`` (a CUDA GPU, or the CPU), so a rollout needs
no host round trip per step. The step is :mod:`tether_gym_agents.accel.chain`, a
line-by-line port of the numba step tested equal to it (tests/agents/accel/).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
import torch

from tether_gym.envs.batch import MAX_RESET_DRAWS, StartPlan, check_startable, step_config
from tether_gym.envs.config import EnvConfig
from tether_gym.envs.layout import INFO_KEYS
from tether_gym.envs.tether_libration import action_space, observation_space
from tether_gym.envs.vector import check_num_envs
from tether_gym.physics.state import PARAMS, STATE
from tether_gym.tasks.cost import COST_NAMES
from tether_gym.tasks.reward import COMPONENTS
from tether_gym.tasks.termination import TUMBLE_ANGLE, Failure

from . import chain
from .row_step import NumbaCpuStep, check_cpu

__all__ = ["TorchTetherVecEnv", "StepOutputs", "chain_consts", "resolve_device",
           "AUTORESET_MODES", "BACKENDS", "check_backend"]

BACKENDS = ("torch", "numba", "numba-cuda")
"""``torch``: the step as torch operations (:mod:`.chain`), on any device; ``numba``: the
numba env's own compiled row step on CPU tensors (:class:`.row_step.NumbaCpuStep`);
``numba-cuda``: that row step compiled for a CUDA GPU (:mod:`.numba_cuda`)."""

AUTORESET_MODES = ("next_step", "same_step", "same_step_sync_free")
"""``next_step``: gymnasium's default, as the native vector env; ``same_step``: an ended
sub-env is reset within the step that ended it, its last observation in
``info["final_obs"]`` (stable-baselines3's convention, what the GPU learner uses)."""

CUDA_HINT = ("no CUDA device is available to torch (torch.cuda.is_available() is False): "
             "use device='cpu', or install a CUDA build of torch on a machine with an NVIDIA "
             "GPU (pip install -e \".[gpu]\" there)")


class StepOutputs(NamedTuple):
    """What a same-step autoreset step returns besides the observation, in fixed tensors.

    Filled by :meth:`TorchTetherVecEnv.step_end` before the autoreset, overwritten by
    the next step: the step's ``reward`` (num_envs,) and ``cost`` (num_envs,
    COST_NAMES), the flags ``terminated``, ``truncated`` and ``ended`` (either)
    (num_envs,) bool, and the ended episodes' last observation ``final_obs``
    (num_envs, obs_dim) float32 and failure code ``final_failure`` (num_envs,) int64.
    """

    reward: torch.Tensor
    cost: torch.Tensor
    terminated: torch.Tensor
    truncated: torch.Tensor
    ended: torch.Tensor
    final_obs: torch.Tensor
    final_failure: torch.Tensor


def _cost_entries(cost: torch.Tensor) -> dict[str, torch.Tensor]:
    """The ``info`` entries of the cost and its parts: columns of ``cost`` (B, COST_NAMES)."""
    return {name: cost[:, c] for c, name in enumerate(COST_NAMES)}


def resolve_device(device) -> torch.device:
    """``device`` as a torch.device; "cuda" without a CUDA device is a clear error.

    Raises
    ------
    ValueError
        For an unknown device string, or a CUDA device when torch sees none.
    """
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise ValueError(f"device={device!r} is not a torch device ('cpu', 'cuda', 'cuda:0' "
                         f"or 'auto'): {exc}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={device!r}: {CUDA_HINT}")
    if dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device={device!r}: only 'cpu' and 'cuda' devices are supported")
    return dev


def check_backend(backend: str, device: torch.device, dtype=torch.float64,
                  compile: bool = False) -> None:
    """A ValueError unless ``backend`` (:data:`BACKENDS`) can run with these settings.

    ``numba`` (CPU) and ``numba-cuda`` (a CUDA device) run the numba kernel in float64;
    ``compile`` then fuses the torch arithmetic around it (any backend, any device).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r} must be one of {BACKENDS}")
    if not isinstance(compile, bool):
        raise TypeError(f"compile must be True or False, got {compile!r}")
    if backend == "torch":
        return
    if dtype != torch.float64:
        raise ValueError(f"backend={backend!r} runs the numba kernel in float64: "
                         f"dtype={dtype!r} must be torch.float64")
    if backend == "numba":
        check_cpu(device)
        return
    from .numba_cuda import check_device

    check_device(device)


def chain_consts(config: EnvConfig, device, dtype=torch.float64) -> chain.ChainConsts:
    """The step's constants (:class:`~.chain.ChainConsts`) of a configuration."""
    cfg = step_config(config)
    n = config.n_tethers
    idx = np.maximum.outer(np.arange(n), np.arange(n))
    return chain.ChainConsts(
        n=n, full_gravity=config.chain.gravity.value == "full",
        max_reel_rate=cfg.max_reel_rate, incremental=cfg.incremental,
        increment_gain=cfg.increment_gain, h=cfg.substeps.h, substeps=cfg.substeps.number,
        amplitude=cfg.amplitude, frequency=cfg.frequency, length_min=cfg.length_min,
        length_max=cfg.length_max, accel_ref=cfg.accel_ref, accel_scale=cfg.accel_scale,
        with_eccentricity=cfg.with_eccentricity, with_masses=cfg.with_masses,
        reward=cfg.reward, cost=cfg.cost,
        length_nominal=torch.as_tensor(cfg.length_nominal, dtype=dtype, device=device),
        mt_index=torch.as_tensor(idx, dtype=torch.int64, device=device))


SEED_MAX = 2**63 - 1
"""Largest seed of the batch's generator (``torch.Generator.manual_seed`` takes 64 bits)."""


def _checked_seed(seed) -> int:
    """``seed`` as an int in [0, SEED_MAX] (gymnasium's rule: a non-negative integer)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) \
            or not 0 <= seed <= SEED_MAX:
        raise ValueError(f"seed={seed!r} must be None or an integer in [0, {SEED_MAX}]")
    return int(seed)


class TorchTetherVecEnv:
    r"""``num_envs`` libration environments of ``TetherLibration-v2`` as torch tensors.

    ## Description

    The task, physics, reward, termination, observation and ``info`` of
    ``tether_gym/TetherLibration-v2`` (its docstring is the spec; every keyword argument
    of ``gym.make`` is accepted here), for a batch of chains held on one torch device.
    ``device="cuda"`` steps them on the GPU, ``device="cpu"`` on the CPU through the
    same code. The state is float64 by default (``dtype``), as in the numba env; the
    observation is float32.

    Equal to the numba env (tests/agents/accel/test_accel_vec_env.py, on CPU): one step from the
    same state, parameters, command, disturbance and noise gives the same state, reward,
    failure code and ``info`` to 1e-12 (relative, float64) and the same observation to
    float32 rounding; whole episodes to 1e-9, with the same failure codes and step
    counts. The random draws are torch's (``torch.Generator``), not numpy's, so a seed
    gives other episodes than the numba env's seed: the same distributions, drawn by
    the same formulas.

    ## Spaces

    ``single_observation_space``, ``single_action_space``: the single env's. ``step``
    takes a (num_envs, N-1) tensor (or array) of actions in [-1, 1] (clipped).

    ## Step and autoreset

    ``step(actions) -> (obs, reward, terminated, truncated, info)``, all tensors on the
    device: obs (num_envs, obs_dim) float32, reward (num_envs,) in ``dtype``,
    terminated/truncated (num_envs,) bool. ``info``: a dict of tensors with every key
    of the single env's ``info`` (floats (num_envs,), per-tether entries
    (num_envs, N-1)); ``"failure"`` holds the :class:`~tether_gym.tasks.termination.Failure`
    codes (int64, 0 while healthy) instead of their labels. The constraint cost
    ``"cost"`` and its parts ``"cost_slack"``, ``"cost_length"``, ``"cost_tumble"``
    (num_envs,) are v2's (:mod:`tether_gym.tasks.cost`, thresholds from
    ``cost_thresholds``), 0 at a reset.

    ``autoreset_mode="next_step"`` (default, gymnasium's and the native vector env's):
    the step after an episode ended ignores that sub-env's action, resets it and
    returns its reset observation with reward 0 and both flags False.
    ``"same_step"``: an ended sub-env is reset in the step that ended it; the step
    returns its reset observation, and ``info["final_obs"]`` (num_envs, obs_dim) and
    ``info["final_failure"]`` hold the last observation and the failure code of the
    episode for the ended rows (stable-baselines3's ``terminal_observation``). The
    returned reward and the cost entries of ``info`` are the step's, as in
    ``next_step`` (a failure's last step costs >= 1), not the reset's zeros; the other
    ``info`` entries are the reset's. ``"same_step_sync_free"``: the same, with an
    autoreset that reads nothing back to the host (below).

    ## The step's parts (for CUDA graphs)

    With a same-step mode, ``step`` is :meth:`step_in_place` and copies of its outputs;
    :meth:`step_in_place` is :meth:`step_begin` (the draws; the torch
    backend's whole step), :meth:`step_kernel` (a numba backend's launch),
    :meth:`step_end` (its results into the state) and :meth:`step_autoreset` (a host
    sync, then reset attempts of :meth:`reset_begin`, :meth:`reset_kernel`,
    :meth:`reset_end` and a sync each; without syncs, one attempt), reading the actions
    from ``action_in`` and leaving the step's outputs in ``outputs``
    (:class:`StepOutputs`) and ``obs``. Every tensor of the env stays in the storage it
    was made in, updated in place, so that a learner can capture the parts without a
    host sync or a numba launch as CUDA graphs and replay them
    (:class:`~.graphs.RolloutStep`); ``step`` itself returns copies. Where
    :attr:`whole_step_graph` is True, one graph can hold a whole step.

    ## Starting state

    As the single env's, drawn by torch: e, the masses, (theta, theta', l) from
    uniforms, theta' around theta_d'(nu0), l' from the periodic law (paper Eq. 10);
    a failed draw is drawn again, up to 1000 times; a row whose every draw failed starts
    failed and terminates at its first step with reward 0. Reset options are not
    supported (the native env has them).

    ## Without host syncs (``autoreset_mode="same_step_sync_free"``)

    With ``"same_step"``, the autoreset asks the device whether any row ended (a host
    sync per step) and whether any start failed (one per attempt).
    ``"same_step_sync_free"`` is ``"same_step"`` that asks nothing (``sync_free`` True):
    every step makes one reset attempt, whether or not a row ended (a start drawn for
    every row, written into the rows that ended, nothing written where none did), so the
    host can queue step after step. Two things differ from ``"same_step"``: the generator
    draws the starts every step (other numbers for the same seed, the same
    distributions), and a failed start is not drawn again in its step: the row starts
    failed, as a row whose every draw failed (it terminates at its first step with
    reward 0 and the start's failure code), and is reset with a new draw in that step.
    On the training distribution of ``configs/gpu_ppo.yml`` no start of 10^6 drawn
    failed.

    ## Arguments

    ``num_envs`` (1 ... 4,194,304, :data:`tether_gym.envs.vector.MAX_NUM_ENVS`),
    ``device`` ("cpu", "cuda", "cuda:K" or "auto"), ``dtype`` (torch.float64 or
    torch.float32), ``seed`` (None or an int in [0, 2**63 - 1]), ``autoreset_mode``,
    ``check_actions`` (True: NaN/inf actions raise ValueError, a device sync per step;
    False: a NaN action turns its row's state non-finite, which terminates it as
    ``"nonfinite"``), ``compile`` (True: the torch backend's arithmetic runs through
    ``torch.compile``, fused into few kernels: the step (:func:`~.chain.control_step`
    with the step's disturbance and noise and its results into the rows), the step's
    outputs, and a reset attempt (the starts, their evaluation and their writes), to
    float64 rounding of the eager arithmetic (Inductor reorders it);
    with a numba backend, the torch arithmetic around its kernel does: the step's
    disturbance and noise and the starts made of their draws, the inputs' copies, the
    results into the rows and the step's outputs, the starts' writes, bitwise what it
    computes eagerly on the CPU; the draws themselves stay eager; the first steps
    compile, seconds to tens of seconds), ``backend`` (``"torch"``, default: the step as
    torch operations; ``"numba"``: the step and the reset's evaluation by the numba
    env's own row code, :func:`tether_gym.envs.step_kernel.step_row`, compiled by numba,
    on CPU tensors, one thread; a NaN or inf action then raises ValueError whatever
    ``check_actions`` says; ``"numba-cuda"``: that row code compiled for the GPU by
    numba-cuda, one kernel launch per step, CUDA devices only; both float64; the draws
    and the autoreset stay torch's), ``full_info`` (True, default: ``info`` as above;
    False: only the cost entries and, with ``"same_step"``, ``final_obs`` and
    ``final_failure``, which is what a learner reads: 22 torch operations fewer per
    step), and every keyword argument of ``gym.make``.
    """

    def __init__(self, num_envs: int, device="cpu", dtype=torch.float64, seed: int | None = None,
                 autoreset_mode: str = "next_step", check_actions: bool = True,
                 compile: bool = False, backend: str = "torch", full_info: bool = True,
                 **env_kwargs):
        num_envs = check_num_envs(num_envs)
        if dtype not in (torch.float64, torch.float32):
            raise ValueError(f"dtype={dtype!r} must be torch.float64 or torch.float32")
        if autoreset_mode not in AUTORESET_MODES:
            raise ValueError(f"autoreset_mode={autoreset_mode!r} must be one of "
                             f"{AUTORESET_MODES}")
        if not isinstance(full_info, bool):
            raise TypeError(f"full_info must be True or False, got {full_info!r}")
        if STATE.names != ("theta", "dtheta", "length", "dlength"):
            raise RuntimeError(f"the torch step assumes the state order theta, dtheta, "
                               f"length, dlength, not {STATE.names}")
        self.config = EnvConfig.from_kwargs(**env_kwargs)
        check_startable(self.config)
        self.device = resolve_device(device)
        check_backend(backend, self.device, dtype, compile)
        self.dtype = dtype
        self.num_envs = int(num_envs)
        self.autoreset_mode = autoreset_mode
        if not isinstance(check_actions, bool):
            raise TypeError(f"check_actions must be True or False, got {check_actions!r}")
        self.check_actions = check_actions
        self.full_info = full_info
        # same-step autoreset, and without host syncs (the class docstring)
        self.same_step = autoreset_mode != "next_step"
        self.sync_free = autoreset_mode == "same_step_sync_free"
        self.single_observation_space = observation_space(self.config)
        self.single_action_space = action_space(self.config)
        self.cc = chain_consts(self.config, self.device, dtype)
        self.backend = backend
        self._kernel: Any = None  # the numba row step, with backend "numba" or "numba-cuda"
        if backend == "numba":
            self._kernel = NumbaCpuStep(self.config, self.num_envs, self.device)
        elif backend == "numba-cuda":
            from .numba_cuda import NumbaCudaStep

            self._kernel = NumbaCudaStep(self.config, self.num_envs, self.device)
        # a numba backend's torch arithmetic around its kernel: the step's inputs (its
        # rows, its disturbance and noise from the draws, the copies into the kernel's
        # rows), the results into the rows and the step's outputs, the starts and their
        # writes; with compile, each through torch.compile (the draws stay eager)
        self._load_step: Callable[..., None] = self._load_rows
        self._kernel_step_end: Callable[[], None] = self._step_end_rows
        self._start_loaded: Callable[..., dict[str, torch.Tensor]] = self._load_starts
        self._kernel_reset_end: Callable[[], None] = self._reset_end_rows
        # the torch backend's step of the live rows, its outputs, and its reset attempt
        # (the starts, their evaluation and their writes); with compile, each through
        # torch.compile (the draws stay eager)
        self._torch_advance: Callable[..., None] = self._advance_rows
        self._step_outputs: Callable[[], None] = self._same_step_outputs
        self._torch_attempt: Callable[..., None] = self._attempt_rows
        if compile and self._kernel is not None:
            pieces: tuple[Any, ...] = (self._load_rows, self._step_end_rows,
                                       self._load_starts, self._reset_end_rows)
            (self._load_step, self._kernel_step_end, self._start_loaded,
             self._kernel_reset_end) = (torch.compile(f, fullgraph=True, dynamic=False)
                                        for f in pieces)
        elif compile:
            torch_pieces: tuple[Any, ...] = (self._advance_rows, self._same_step_outputs,
                                             self._attempt_rows)
            (self._torch_advance, self._step_outputs, self._torch_attempt) = (
                torch.compile(f, fullgraph=True, dynamic=False) for f in torch_pieces)
        self._plan = StartPlan.of(self.config)
        # Python floats for the compiled pieces, which guard on numpy scalars by reading
        # them (a host read per call): the step's disturbance bound and observation noise
        # (_step_draws), theta_d and theta_d' at the start (_start_inputs; plan's are numpy's)
        self._draw_scales = (float(self.config.disturbance), float(self.config.obs_noise))
        self._reference_start = (float(self._plan.ref), float(self._plan.dref))
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(int(np.random.SeedSequence(seed).generate_state(1)[0])
                                   if seed is None else _checked_seed(seed))
        n, num = self.config.n_tethers, self.num_envs
        self.n = n
        m = STATE.size(n)
        def z(*shape):
            return (torch.zeros(shape, dtype=dtype, device=self.device))
        def tensor(a):
            return (torch.as_tensor(np.asarray(a, dtype=float), dtype=dtype,
                                                    device=self.device))
        self._par_nominal = tensor(self.config.param_rows(self.config.eccentricity,
                                                          self.config.masses))
        self._masses = tensor(self.config.masses)
        bias = np.zeros(m)
        bias[STATE.slices(n)["theta"]] = self.config.obs_bias
        self._bias = tensor(bias)
        plan = self._plan
        self._start_base = tensor(plan.start_base)
        self._start_spread = tensor(plan.start_spread)
        self._state_low = tensor(plan.state_low)
        self._state_high = tensor(plan.state_high)
        # the batch's rows (Rows of the numba env)
        self.nu = z(num)
        self.y = z(num, m)
        self.par = self._par_nominal.expand(num, -1).clone()
        self.u = z(num, n)                      # normalised command in force [-]
        self.disturbance = z(num, n)
        self.noise = self._bias.expand(num, -1).clone()
        self.tension = z(num, n)
        self.tension_min = z(num, n)
        self.derivative = z(num, m)
        self.reward = z(num)
        self.components = z(num, len(COMPONENTS))
        self.cost = z(num, len(COST_NAMES))     # the cost and its parts (COST_NAMES)
        self.failure = torch.zeros(num, dtype=torch.int64, device=self.device)
        self.steps = torch.zeros(num, dtype=torch.int64, device=self.device)
        self.nu_end = z(num)
        self.obs = torch.zeros((num, self.config.obs_dim), dtype=torch.float32,
                               device=self.device)
        self._autoreset = torch.zeros(num, dtype=torch.bool, device=self.device)
        self._start_failed = torch.zeros(num, dtype=torch.bool, device=self.device)
        self._start_code = torch.zeros(num, dtype=torch.int64, device=self.device)
        self._was_reset = False
        # the step's input and its rows, and the same-step outputs (see the step's parts)
        self.action_in = z(num, n)
        self._rows = torch.ones(num, dtype=torch.bool, device=self.device)
        self._pending = torch.zeros(num, dtype=torch.bool, device=self.device)  # to reset
        # whether any row ended / any start is pending: reduced in the graphed parts, so
        # that the host's branch costs it a read and no launch
        self._any_ended = torch.zeros((), dtype=torch.bool, device=self.device)
        self._any_pending = torch.zeros((), dtype=torch.bool, device=self.device)
        self._attempt: dict[str, torch.Tensor] = {}  # a numba reset attempt's starts, for reset_end
        self.outputs = StepOutputs(
            reward=z(num), cost=z(num, len(COST_NAMES)),
            terminated=torch.zeros(num, dtype=torch.bool, device=self.device),
            truncated=torch.zeros(num, dtype=torch.bool, device=self.device),
            ended=torch.zeros(num, dtype=torch.bool, device=self.device),
            final_obs=torch.zeros_like(self.obs), final_failure=torch.zeros_like(self.failure))

    # ------------------------------------------------------------------ #
    @property
    def whole_step_graph(self) -> bool:
        """Whether one CUDA graph can hold a whole step, its autoreset included.

        True with ``"same_step_sync_free"`` (no host sync) on the torch backend (torch
        operations only) or on numba-cuda on a GPU (its kernel launched on torch's
        stream, where a capture records it); False on the CPU's numba backend, whose
        kernel is a host call, and with the other modes.
        """
        return self.sync_free and (self._kernel is None or self._kernel.on_torch_stream)

    @property
    def observation_dim(self) -> int:
        """Length of one observation."""
        return int(self.config.obs_dim)

    def seed(self, seed: int) -> None:
        """Seed the batch's generator (an int in [0, 2**63 - 1])."""
        self.generator.manual_seed(_checked_seed(seed))

    def reset(self, seed: int | None = None):
        """Reset every sub-env; returns (obs, info). ``seed`` reseeds the generator."""
        if seed is not None:
            self.seed(seed)
        every = torch.ones(self.num_envs, dtype=torch.bool, device=self.device)
        self._reset_rows(every)
        self._autoreset.zero_()
        self._was_reset = True
        return self.obs.clone(), self.info()

    # ------------------------------------------------------------------ #
    def draws(self, count: int) -> dict[str, torch.Tensor]:
        """One draw of ``count`` starts: e, mass scales, 3n uniforms, 4n normals.

        The same quantities the numba env draws from numpy (``ChainBatch._draw_rows``),
        by the same formulas (``low + (high - low) u``); absent ones are None.
        """
        return self._scale_draws(self._unit_draws(count))

    def _unit_draws(self, count: int) -> dict[str, torch.Tensor | None]:
        """:meth:`draws` before its scaling: uniforms in [0, 1) and standard normals."""
        plan, n, g = self._plan, self.n, self.generator
        def rand(*shape):
            return (torch.rand(shape, generator=g, dtype=self.dtype,
                                                  device=self.device))
        out: dict[str, Any] = {"ecc": None, "scale": None, "gauss": None}
        if plan.eccentricity_range is not None:
            out["ecc"] = rand(count)
        if plan.mass_range is not None:
            out["scale"] = rand(count, n)
        out["unit"] = rand(count, 3 * n)
        if plan.obs_noise > 0.0:
            out["gauss"] = torch.randn((count, 4 * n), generator=g, dtype=self.dtype,
                                       device=self.device)
        return out

    def _scale_draws(self, u: dict[str, torch.Tensor | None]) -> dict[str, torch.Tensor]:
        """:meth:`draws` from its uniforms and normals ``u`` (:meth:`_unit_draws`)."""
        plan = self._plan
        out: dict[str, Any] = {"ecc": None, "scale": None, "gauss": u["gauss"]}
        ecc, scale, unit = u["ecc"], u["scale"], u["unit"]
        if ecc is not None and plan.eccentricity_range is not None:
            lo, hi = (float(x) for x in plan.eccentricity_range)  # Python floats
            out["ecc"] = lo + (hi - lo) * ecc
        if scale is not None and plan.mass_range is not None:
            r = float(plan.mass_range)
            out["scale"] = (1.0 - r) + ((1.0 + r) - (1.0 - r)) * scale
        assert unit is not None  # always drawn
        out["unit"] = -1.0 + (1.0 - -1.0) * unit
        return out

    def start(self, draws: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The start of every row of ``draws`` (:meth:`draws`): state, parameters, outputs.

        The numba env's ``_draw_rows`` for the same draws: parameter rows, (theta,
        theta', l) = base + unit * spread, l' from Eq. 10 at nu0 on the reference, then
        the reset's evaluation (dy/dnu and T^ with the reels holding their rate), the
        observation and the command u = clip(l' / max_reel_rate, -1, 1).
        """
        inp = self._start_inputs(draws)
        if self._kernel is None:
            out = self._evaluate(inp)
        else:
            out = self._kernel.evaluate(inp["nu"], inp["y"], inp["noise"], inp["par"])
        return self._start_result(inp, out)

    def _start_inputs(self, draws: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """:meth:`start` before the evaluation: nu0, y, parameter and noise rows, l'."""
        plan, n = self._plan, self.n
        unit = draws["unit"]
        count = unit.shape[0]
        if plan.randomised:
            ecc = (draws["ecc"] if draws["ecc"] is not None
                   else torch.full((count,), plan.eccentricity, dtype=self.dtype,
                                   device=self.device))
            masses = self._masses.expand(count, -1)
            if draws["scale"] is not None:
                masses = masses * draws["scale"]
            par = self._param_rows(ecc, masses)
        else:
            par = self._par_nominal.expand(count, -1)
            ecc = par[:, 0]
        start = self._start_base + unit * self._start_spread
        length = start[:, 2 * n:3 * n]
        nu0 = torch.full((count,), plan.nu0, dtype=self.dtype, device=self.device)
        ref, dref = self._reference_start
        k = 1.0 + ecc * math.cos(plan.nu0)
        # paper Eq. 10 (tasks.reference.periodic_reel_factors) on the reference
        num = (4.0 * ecc * math.sin(plan.nu0) * (1.0 + dref)
               + 2.0 * plan.amplitude * k * plan.frequency**2 * math.sin(plan.frequency
                                                                          * plan.nu0)
               - 3.0 * math.sin(2.0 * ref))
        den = 4.0 * k * (1.0 + dref)
        dlength = length * num[:, None] / den[:, None]
        y = torch.cat([start, dlength], dim=1)
        noise = (self._bias.expand(count, -1) if draws["gauss"] is None
                 else plan.obs_noise * draws["gauss"] + self._bias)
        return {"nu": nu0, "y": y, "par": par, "noise": noise, "dlength": dlength}

    def _evaluate(self, inp: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The torch backend's reset evaluation of the starts ``inp`` (:meth:`_start_inputs`)."""
        cc, nu0, y, par, dlength = self.cc, inp["nu"], inp["y"], inp["par"], inp["dlength"]
        _, res = chain.advance(nu0, y, dlength, torch.zeros_like(dlength), par, cc, 0)
        u = torch.clamp(dlength / cc.max_reel_rate, -1.0, 1.0)
        return {"u": u, "tension": res.tension, "tension_min": res.tension_min,
                "derivative": res.derivative,
                "obs": chain.observation(nu0, y, inp["noise"], par, u, cc)}

    def _start_result(self, inp: dict[str, torch.Tensor],
                      out: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The starts ``inp`` and their evaluation ``out``, with ``nu_end`` and ``ok``."""
        y = inp["y"]
        ok = ((y > self._state_low) & (y < self._state_high)).all(dim=1)
        ok &= ((out["tension"] > 0.0) & (out["tension"] < math.inf)).all(dim=1)
        return {"nu": inp["nu"], "y": y, "par": inp["par"], "noise": inp["noise"],
                "nu_end": inp["nu"] + self._plan.episode_length, "ok": ok, **out}

    def _param_rows(self, ecc: torch.Tensor, masses: torch.Tensor) -> torch.Tensor:
        """Parameter rows for e (B,) and masses (B, n) (``pack_params`` of ``tail_masses``)."""
        total = chain._sum_along(masses)
        tail = chain._cumsum(masses / total[:, None], reverse=True)
        par = self._par_nominal.expand(ecc.shape[0], -1).clone()
        sl = PARAMS.slices(self.n)
        par[:, sl["eccentricity"]] = ecc[:, None]
        par[:, sl["tail_mass"]] = tail
        return par

    def _reset_rows(self, mask: torch.Tensor | None, begin: Callable[[], None] | None = None,
                    end: Callable[[], None] | None = None) -> None:
        """Draw and start the rows of ``mask``, drawing failed starts again (<= 1000 times).

        ``mask`` None: the rows already in ``_pending`` (a step's ended rows, which
        :meth:`step_end` put there). Each attempt is :meth:`reset_begin`,
        :meth:`reset_kernel`, :meth:`reset_end` (``begin`` and ``end``: the same,
        captured as graphs), then one host sync.
        """
        if mask is not None:
            self._pending.copy_(mask)
        for _ in range(MAX_RESET_DRAWS):
            self._reset_attempt(begin, end)
            if not bool(self._any_pending):
                break
        else:
            self._mark_failed_starts()

    def _reset_attempt(self, begin: Callable[[], None] | None = None,
                       end: Callable[[], None] | None = None) -> None:
        """One reset attempt: :meth:`reset_begin`, :meth:`reset_kernel`, :meth:`reset_end`.

        ``begin``, ``end``: the first and last captured as graphs (None: called).
        """
        (self.reset_begin if begin is None else begin)()
        self.reset_kernel()
        (self.reset_end if end is None else end)()

    def _mark_failed_starts(self) -> None:
        """The rows still pending start failed: their code, from their last start drawn."""
        torch.where(self._pending, self._start_failure(), self._start_code,
                    out=self._start_code)

    # A reset attempt's parts, as a step's: reset_begin and reset_end can be captured as
    # graphs (RolloutStep does), reset_kernel is a numba backend's launch.
    def reset_begin(self) -> None:
        """A reset attempt's first part: draw a start for every row.

        With the torch backend, evaluate it and write it into the rows still pending
        (``reset_end``'s work); with a numba backend, copy it into the kernel's rows.
        """
        draws = self._unit_draws(self.num_envs)  # scaled in the (compiled) pieces below
        if self._kernel is None:
            self._torch_attempt(draws)
        else:
            self._attempt = self._start_loaded(draws)

    def _attempt_rows(self, draws: dict[str, torch.Tensor | None]) -> None:
        """The torch backend's reset attempt of ``draws`` (:meth:`_unit_draws`).

        The draws scaled (:meth:`_scale_draws`), the starts (:meth:`_start_inputs`)
        evaluated (:meth:`_evaluate`) and written into the pending rows
        (:meth:`_write_attempt`).
        """
        attempt = self._start_inputs(self._scale_draws(draws))
        self._write_attempt(attempt, self._evaluate(attempt))

    def _load_starts(self, draws: dict[str, torch.Tensor | None]) -> dict[str, torch.Tensor]:
        """The starts of ``draws`` (:meth:`_unit_draws`), copied into a numba backend's rows.

        The draws are scaled here (:meth:`_scale_draws`), then :meth:`_start_inputs`.
        """
        a = self._start_inputs(self._scale_draws(draws))
        self._kernel.load_reset(a["nu"], a["y"], a["noise"], a["par"])
        return a

    def reset_kernel(self) -> None:
        """A reset attempt's numba kernel launch (nothing with the torch backend)."""
        if self._kernel is not None:
            self._kernel.launch_reset()

    def reset_end(self) -> None:
        """A reset attempt's last part with a numba backend: the start into the rows."""
        if self._kernel is not None:
            self._kernel_reset_end()

    def _reset_end_rows(self) -> None:
        """A numba backend's evaluated starts into the pending rows (:meth:`reset_end`)."""
        self._write_attempt(self._attempt, self._kernel.reset_result())

    def _write_attempt(self, attempt: dict[str, torch.Tensor],
                       out: dict[str, torch.Tensor]) -> None:
        """The attempt's start into the pending rows; the rows whose start is good leave.

        ``attempt``: the attempt's starts (:meth:`_start_inputs`), ``out`` their evaluation.
        """
        s = self._start_result(attempt, out)
        self._write_start(self._pending, s)  # a row whose every draw fails keeps its last
        still = self._pending & ~s["ok"]
        # the attempt's rows start failed while their start is: after the last attempt, a
        # reset row is marked failed when every one of its draws failed
        torch.where(self._pending, still, self._start_failed, out=self._start_failed)
        self._pending.copy_(still)
        torch.any(self._pending, out=self._any_pending)
        if self.sync_free:  # no second draw: a failed start starts failed (class docstring)
            self._mark_failed_starts()

    def _write_start(self, rows: torch.Tensor, s: dict[str, torch.Tensor]) -> None:
        """Copy the start ``s`` into the rows of the mask ``rows`` (in place)."""
        col = rows[:, None]
        for name, mask in (("nu", rows), ("nu_end", rows), ("y", col), ("par", col),
                           ("noise", col), ("u", col), ("tension", col), ("tension_min", col),
                           ("derivative", col), ("obs", col)):
            mine = getattr(self, name)
            torch.where(mask, s[name], mine, out=mine)
        for name, mask in (("reward", rows), ("components", col), ("cost", col),
                           ("failure", rows), ("steps", rows)):
            getattr(self, name).masked_fill_(mask, 0)

    def _start_failure(self) -> torch.Tensor:
        """Why each row's start is failed (``ChainBatch._start_code``'s order)."""
        n = self.n
        finite = torch.isfinite(self.y).all(dim=1) & torch.isfinite(self.tension).all(dim=1)
        code = torch.full_like(self.failure, int(Failure.LENGTH))
        tumble = (self.y[:, :n].abs() >= TUMBLE_ANGLE).any(dim=1)
        code = torch.where(tumble, torch.full_like(code, int(Failure.TUMBLE)), code)
        slack = (self.tension <= 0.0).any(dim=1)
        code = torch.where(slack, torch.full_like(code, int(Failure.SLACK)), code)
        return torch.where(finite, code, torch.full_like(code, int(Failure.NONFINITE)))

    # ------------------------------------------------------------------ #
    def step(self, actions):
        """One control step of every sub-env (see the class docstring for autoreset)."""
        if not self._was_reset:
            raise RuntimeError("call reset() before step()")
        try:
            a = torch.as_tensor(actions, device=self.device)
        except (TypeError, ValueError, RuntimeError, NotImplementedError) as exc:
            raise TypeError(f"actions must be an array of real numbers of shape "
                            f"({self.num_envs}, {self.n}), got {type(actions).__name__}: "
                            f"{exc}") from None
        if a.dtype == torch.bool or a.is_complex():
            raise TypeError(f"actions must hold real numbers, got dtype {a.dtype}")
        if a.shape != (self.num_envs, self.n):
            raise ValueError(f"actions must have shape ({self.num_envs}, {self.n}) "
                             f"(num_envs, N-1), got {tuple(a.shape)}")
        if self.check_actions:  # every row, as the native vector env (ended rows too)
            bad = ~torch.isfinite(a).all(dim=1)
            if bool(bad.any()):
                rows = torch.nonzero(bad).flatten().tolist()
                raise ValueError(f"actions must be finite (no NaN or inf); rows {rows} are not")
        self.action_in.copy_(a)  # in the state's dtype
        if self.same_step:
            self.step_in_place()
            o = self.outputs
            info = self.info() if self.full_info else {}
            info["final_obs"] = o.final_obs.clone()
            info["final_failure"] = o.final_failure.clone()
            info.update(_cost_entries(o.cost.clone()))
            return (self.obs.clone(), o.reward.clone(), o.terminated.clone(),
                    o.truncated.clone(), info)
        done = self._autoreset
        self._advance(self.action_in, ~done)
        if bool(done.any()):
            self._reset_rows(done)
        terminated = self.failure != 0
        truncated = self.steps_truncated() & ~terminated
        torch.logical_or(terminated, truncated, out=self._autoreset)
        info = self.info() if self.full_info else _cost_entries(self.cost)
        return self.obs.clone(), self.reward.clone(), terminated, truncated, info

    # The parts of a same-step autoreset step, for a learner that captures them as CUDA
    # graphs (tether_gym_agents.accel.graphs.RolloutStep): step() calls them in turn.
    # Every part reads and writes only this env's tensors, which stay in the same storage
    # from its construction on (updated in place), and only step_kernel (a numba launch)
    # and step_autoreset (a host branch) cannot be captured.
    def step_in_place(self) -> None:
        """A same-step step of ``action_in``, its parts in turn, without ``step``'s copies.

        :meth:`step_begin`, :meth:`step_kernel`, :meth:`step_end`, :meth:`step_autoreset`:
        the outputs are left in :attr:`outputs` and ``obs``. No check of the actions.
        """
        self.step_begin()
        self.step_kernel()
        self.step_end()
        self.step_autoreset()

    def step_begin(self) -> None:
        """First part: draw the step's disturbance and noise, and step ``action_in``.

        The torch backend does the whole step here (and :meth:`step_end`'s work); a
        numba backend copies the inputs into its kernel's rows, for :meth:`step_kernel`.
        Needs a same-step autoreset mode and a prior :meth:`reset`; no host sync.
        """
        if not self.same_step or not self._was_reset:
            raise RuntimeError(f"the step's parts need autoreset_mode='same_step' or "
                               f"'same_step_sync_free' (got {self.autoreset_mode!r}) and "
                               f"a reset() first")
        self._advance_begin(self.action_in, None, draw=True)  # the rows that did not end
        if self._kernel is None:
            self._step_outputs()

    def step_kernel(self) -> None:
        """Second part: the numba backends' kernel launch (nothing with the torch backend)."""
        if self._kernel is not None:
            self._kernel.launch()

    def step_end(self) -> None:
        """Third part: a numba backend's results into the state, and :attr:`outputs`."""
        if self._kernel is not None:
            self._kernel_step_end()

    def _step_end_rows(self) -> None:
        """A numba backend's step results into the live rows, and :attr:`outputs`."""
        self._advance_end(self._kernel.result(), self._rows)
        self._same_step_outputs()

    def step_autoreset(self, begin: Callable[[], None] | None = None,
                       end: Callable[[], None] | None = None) -> None:
        """Last part: reset the rows that ended (a host sync; draws only when one did).

        Reads the flag and the rows that :meth:`step_end` (the torch backend:
        :meth:`step_begin`) left. ``begin``, ``end``: :meth:`reset_begin` and
        :meth:`reset_end` captured as graphs. With ``"same_step_sync_free"``: one reset
        attempt, whether or not a row ended, and no host sync (the class docstring).
        """
        if self.sync_free:
            self._reset_attempt(begin, end)
        elif bool(self._any_ended):
            self._reset_rows(None, begin, end)

    def _same_step_outputs(self) -> None:
        """The step's flags, reward, cost and last observations into :attr:`outputs`."""
        o = self.outputs
        torch.ne(self.failure, 0, out=o.terminated)
        torch.logical_and(self.steps_truncated(), ~o.terminated, out=o.truncated)
        torch.logical_or(o.terminated, o.truncated, out=o.ended)
        torch.any(o.ended, out=self._any_ended)
        self._pending.copy_(o.ended)  # the rows step_autoreset resets
        # the step's reward and cost, before a reset zeroes them
        for dst, src in ((o.reward, self.reward), (o.cost, self.cost),
                         (o.final_obs, self.obs), (o.final_failure, self.failure)):
            dst.copy_(src)

    def steps_truncated(self) -> torch.Tensor:
        """Rows whose episode has reached its length in true anomaly (and that stepped)."""
        return (self.nu >= self.nu_end - 1e-9) & (self.steps > 0)

    def _advance(self, a: torch.Tensor, rows: torch.Tensor, draw: bool = True) -> None:
        """Step the rows of the mask ``rows`` (``step_kernel.step_rows`` with reset False).

        ``draw`` False keeps the disturbance and noise rows as they are (tests set them).
        """
        self._advance_begin(a, rows, draw)
        if self._kernel is not None:
            self._kernel.launch()
            self._advance_end(self._kernel.result(), rows)

    def _advance_begin(self, a: torch.Tensor, rows: torch.Tensor | None, draw: bool) -> None:
        """The draws, then the torch step and its results, or a numba kernel's inputs.

        ``rows`` None: the rows that did not end (``~_autoreset``, into ``_rows``), the
        same-step autoreset's step. The uniform and normal draws are made here, eagerly;
        what is made of them (:meth:`_step_draws`) runs with the torch backend's step
        (:meth:`_advance_rows`) or the numba backends' copies into their rows
        (:meth:`_load_rows`), through torch.compile with ``compile``.
        """
        cfg, g = self.config, self.generator
        unit = gauss = None
        if draw and cfg.disturbance > 0.0:
            unit = torch.rand(self.disturbance.shape, generator=g, dtype=self.dtype,
                              device=self.device)
        if draw and cfg.obs_noise > 0.0:
            gauss = torch.randn(self.noise.shape, generator=g, dtype=self.dtype,
                                device=self.device)
        if self._kernel is None:
            self._torch_advance(a, rows, unit, gauss)
        else:
            self._load_step(a, rows, unit, gauss)

    def _advance_rows(self, a: torch.Tensor, rows: torch.Tensor | None,
                      unit: torch.Tensor | None, gauss: torch.Tensor | None) -> None:
        """The torch backend's step (:meth:`_advance_begin`) after its draws.

        The live rows (:meth:`_live_rows`), their disturbance and noise
        (:meth:`_step_draws`), :func:`~.chain.control_step` and its results into them
        (:meth:`_advance_end`).
        """
        rows = self._live_rows(rows)
        self._step_draws(rows, unit, gauss)
        self._advance_end(chain.control_step(self.nu, self.y, self.u, a, self.disturbance,
                                             self.noise, self.par, self.cc), rows)

    def _live_rows(self, rows: torch.Tensor | None) -> torch.Tensor:
        """``rows``, or with None the rows that did not end, written into ``_rows``."""
        if rows is None:
            return torch.logical_not(self._autoreset, out=self._rows)
        return rows

    def _step_draws(self, rows: torch.Tensor, unit: torch.Tensor | None,
                    gauss: torch.Tensor | None) -> None:
        """The step's disturbance and noise of the rows ``rows``, from its draws.

        ``unit`` (num_envs, n): uniforms in [0, 1), the disturbance -d + 2 d unit;
        ``gauss`` (num_envs, 4n): standard normals, the noise obs_noise gauss + bias.
        None keeps the rows' values (no draw).
        """
        d, sigma = self._draw_scales  # Python floats (torch.compile reads no EnvConfig)
        if unit is not None:
            torch.where(rows[:, None], -d + (d - -d) * unit, self.disturbance,
                        out=self.disturbance)
        if gauss is not None:
            torch.where(rows[:, None], sigma * gauss + self._bias, self.noise,
                        out=self.noise)

    def _load_rows(self, a: torch.Tensor, rows: torch.Tensor | None,
                   unit: torch.Tensor | None, gauss: torch.Tensor | None) -> None:
        """A numba backend's step inputs (:meth:`_advance_begin`), into its kernel's rows."""
        self._step_draws(self._live_rows(rows), unit, gauss)
        self._kernel.load(self.nu, self.y, self.u, a, self.disturbance, self.noise, self.par)

    def _advance_end(self, out, rows: torch.Tensor) -> None:
        """The step's results ``out`` (:class:`~.chain.TaskStep`) into the live rows."""
        ended_start = rows & self._start_failed
        live = rows & ~self._start_failed
        nu, y, u, tension, tension_min, derivative, reward, comps, cost, code, obs = out
        lc = live[:, None]
        for mine, new, mask in ((self.nu, nu, live), (self.y, y, lc), (self.u, u, lc),
                                (self.tension, tension, lc),
                                (self.tension_min, tension_min, lc),
                                (self.derivative, derivative, lc), (self.reward, reward, live),
                                (self.components, comps, lc),
                                (self.cost, cost, lc),  # a failed start's last step keeps 0
                                (self.failure, code, live)):
            torch.where(mask, new, mine, out=mine)
        torch.where(ended_start, self._start_code, self.failure, out=self.failure)
        torch.where(lc, obs, self.obs, out=self.obs)
        self.steps.add_(rows.to(torch.int64))
        self._start_failed &= ~rows

    # ------------------------------------------------------------------ #
    def info(self) -> dict[str, torch.Tensor]:
        """The ``info`` entries of every sub-env (INFO_KEYS; ``failure`` as codes)."""
        n, cc = self.n, self.cc
        y = self.y
        reel, ddl = chain.info_vectors(self.nu, y, self.par,
                                       chain.StepResult(y, self.tension_min, self.derivative,
                                                        self.tension), cc)
        ref = cc.amplitude * torch.sin(cc.frequency * self.nu)
        dref = cc.amplitude * cc.frequency * torch.cos(cc.frequency * self.nu)
        values = {"nu": self.nu, "theta": y[:, :n], "dtheta": y[:, n:2 * n],
                  "length": y[:, 2 * n:3 * n], "dlength": y[:, 3 * n:], "ddlength": ddl,
                  "tension": self.tension, "tension_min": self.tension_min,
                  "theta_ref": ref, "dtheta_ref": dref, "reel_accel": reel,
                  "command": self.u, "eccentricity": self.par[:, 0],
                  # a start whose every draw failed reports why from its reset on
                  "failure": torch.where(self._start_failed, self._start_code, self.failure)}
        for c, name in enumerate(COMPONENTS):
            values[name] = self.components[:, c]
        values.update(_cost_entries(self.cost))
        return {key: values[key] for key in INFO_KEYS}

    def __repr__(self) -> str:
        return (f"TorchTetherVecEnv(num_envs={self.num_envs}, n_bodies={self.config.n_bodies}, "
                f"device={str(self.device)!r}, dtype={self.dtype})")
