"""The numba env's own row step, compiled for a CUDA GPU by numba-cuda: one chain per thread.

:class:`NumbaCudaStep` is a drop-in for :func:`~.chain.control_step` in
:class:`~.vec_env.TorchTetherVecEnv` (``backend="numba-cuda"``). Its kernel calls
:func:`tether_gym.envs.step_kernel.step_row`, the very function every step of the numba
env runs (physics, reward, failure code, cost, observation), compiled by numba-cuda for
the GPU instead of by numba for the CPU: the equations have one source. The torch port
(:mod:`.chain`) stays the default backend; on a CPU, ``backend="numba"``
(:class:`~.row_step.NumbaCpuStep`) runs the same row code compiled by numba.

The arrays are torch tensors on the GPU, handed to the kernel without a copy through
``__cuda_array_interface__``. The kernel is launched on torch's current stream (the
default stream, where torch's work runs, or the stream that ``torch.cuda.graph``
captures on), so that a CUDA graph captured around it holds the launch too
(``train.py gpu --cuda-graphs --sync-free``: the whole rollout as one graph). Each call
(:class:`~.row_step.RowStep`) copies the inputs into the batch's rows, launches one
kernel over the rows and returns the rows as a :class:`~.chain.TaskStep`.

On a machine without a GPU the same kernel runs in numba-cuda's simulator
(``NUMBA_ENABLE_CUDASIM=1`` before numba is imported, CPU tensors): the simulator runs
the kernel's Python, row by row, and calls the CPU-compiled ``step_row``, so it tests
this module's wiring (which row reads and writes what), not the GPU's arithmetic.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch

if not hasattr(np, "row_stack"):
    # numpy 2.5 removed np.row_stack (an alias of vstack); numba-cuda 0.30 still declares
    # an overload of it when its CUDA target loads, and fails without it (seen on the GPU
    # machine's numpy 2.5.2)
    setattr(np, "row_stack", np.vstack)  # noqa: B010 - an attribute numpy no longer has

from numba import cuda  # noqa: E402 - numba-cuda's target where installed (load_cuda checks)

from tether_gym.envs.batch import step_config, zero_rows
from tether_gym.envs.config import EnvConfig
from tether_gym.envs.step_kernel import Rows, RowWork, new_row_work, step_row
from tether_gym.physics.kernels import Scratch

from .row_step import RowStep

__all__ = ["NumbaCudaStep", "NUMBA_CUDA_HINT", "simulated", "load_cuda", "kernel_arrays",
           "step_kernel", "check_device"]

NUMBA_CUDA_HINT = ('backend="numba-cuda" needs numba-cuda and the CUDA toolkit libraries: '
                   'pip install "numba-cuda[cu13]" (or pip install -e ".[gpu]")')

THREADS_PER_BLOCK = 128
"""Threads (rows) per block of the step kernel."""

_KERNEL = None


def simulated() -> bool:
    """Whether numba-cuda runs in its CPU simulator (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") == "1"


def load_cuda():
    """``numba.cuda``: numba-cuda's (NVIDIA's target), or its simulator; else an ImportError.

    numba still ships an older built-in CUDA target, which is not used for the GPU.
    """
    if not simulated() and getattr(cuda, "implementation", "") != "NVIDIA":
        raise ImportError(NUMBA_CUDA_HINT)
    return cuda


def check_device(device: torch.device):
    """``numba.cuda`` for ``device`` (:func:`load_cuda`, an ImportError without numba-cuda).

    A ValueError first unless ``device`` is a CUDA device (or numba-cuda's simulator runs).
    """
    if device.type != "cuda" and not simulated():
        raise ValueError(f'backend="numba-cuda" needs a CUDA device, got device='
                         f'{str(device)!r} (on a CPU use backend="torch"; tests run the '
                         "kernel in numba-cuda's simulator, NUMBA_ENABLE_CUDASIM=1)")
    return load_cuda()


def step_kernel(action, rows, cfg, work, reset):
    """Row b = the thread's grid index: :func:`step_row` with its own slice of ``work``.

    ``action`` is a 1-tuple holding the (B, n) actions (inside a tuple, as every other
    array here, so that the simulator hands it to the CPU-compiled ``step_row`` as is).
    """
    b = cuda.grid(1)
    if b < rows.y.shape[0]:
        p = work.physics
        mine = RowWork(Scratch(p.S[b], p.R[b], p.V[b], p.tension[b], p.k1[b], p.k2[b],
                               p.k3[b], p.k4[b], p.tmp[b], p.orbit[b]),
                       work.command[b], work.zero[b], work.accel[b], work.previous[b],
                       work.terms[b])
        step_row(b, action[0], rows, cfg, mine, reset)


def kernel_arrays(config: EnvConfig, num: int, zeros) -> tuple[Any, Any, Any]:
    """The kernel's arrays for ``num`` rows: rows, per-thread scratch and actions.

    ``zeros(shape, dtype)`` allocates one (torch on the device here; numpy in
    ``bench/numba_cuda_ptx.py``, which compiles the kernel without a GPU). The scratch
    is :func:`~tether_gym.envs.step_kernel.new_row_work`'s with a leading row axis;
    ``nu_end`` is +inf (truncation is the env's business, not the kernel's) and the
    cached sin/cos of the anomaly NaN (none cached yet). Returns (:class:`Rows`,
    :class:`RowWork`, actions (num, n)) of whatever arrays ``zeros`` makes.
    """
    rows = zero_rows(config, num, zeros)
    rows.nu_end[:] = np.inf
    template = new_row_work(config.n_tethers)
    work = RowWork(Scratch(*[zeros((num,) + a.shape, a.dtype) for a in template.physics]),
                   *[zeros((num,) + a.shape, a.dtype) for a in template[1:]])
    work.physics.orbit[:] = np.nan
    return rows, work, zeros((num, config.n_tethers), np.dtype(np.float64))


def _kernel():
    """:func:`step_kernel` for the device (compiled at its first launch, cached on disk)."""
    global _KERNEL
    if _KERNEL is None:
        _KERNEL = load_cuda().jit(cache=not simulated())(step_kernel)
    return _KERNEL


class NumbaCudaStep(RowStep):
    """:class:`~.row_step.RowStep` on a CUDA GPU: one kernel launch per step, one row per thread.

    Parameters
    ----------
    config : EnvConfig
        The env's configuration (its :func:`~tether_gym.envs.batch.step_config`).
    num : int
        Rows.
    device : torch.device
        A CUDA device, or the CPU under numba-cuda's simulator (tests).
    """

    def __init__(self, config: EnvConfig, num: int, device: torch.device):
        self._cuda = check_device(device)
        super().__init__(config, num, device)
        self.rows, self.work, self.action = kernel_arrays(config, self.num, self.zeros)
        cfg = step_config(config)
        self._cfg = cfg._replace(length_nominal=self._view(
            torch.as_tensor(cfg.length_nominal, dtype=torch.float64, device=device)))
        self._rows = Rows(*[self._view(t) for t in self.rows])
        self._work = RowWork(Scratch(*[self._view(t) for t in self.work.physics]),
                             *[self._view(t) for t in self.work[1:]])
        self._action = (self._view(self.action),)
        self._blocks = (self.num + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
        self.on_torch_stream = device.type == "cuda"  # the simulator has no streams
        self._streams: dict[int, Any] = {}

    def _view(self, t: torch.Tensor):
        """The kernel's view of a tensor: numba's device array, or numpy's in the simulator."""
        if t.device.type == "cuda":
            return self._cuda.as_cuda_array(t)
        return t.numpy()

    def stream(self):
        """Torch's current CUDA stream as numba's (an external stream; 0 in the simulator).

        Torch's stream is the default stream in eager code and the capture stream
        inside ``torch.cuda.graph``: launched there, the kernel is ordered with torch's
        work and recorded by a capture.
        """
        if not self.on_torch_stream:
            return 0
        ptr = int(torch.cuda.current_stream(self.device).cuda_stream)
        if ptr not in self._streams:
            self._streams[ptr] = self._cuda.external_stream(ptr)
        return self._streams[ptr]

    def _launch(self, reset: bool) -> None:
        _kernel()[self._blocks, THREADS_PER_BLOCK, self.stream()](
            self._action, self._rows, self._cfg, self._work, reset)
