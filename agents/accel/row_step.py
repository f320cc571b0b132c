"""The numba env's own row step on the torch env's tensors: on the CPU, and the GPU's base.

:class:`RowStep` is a drop-in for :func:`~.chain.control_step` in
:class:`~.vec_env.TorchTetherVecEnv`: it copies the inputs (nu, y, command, disturbance,
noise, parameters) into the batch's rows (:func:`tether_gym.envs.batch.zero_rows`, torch
tensors), runs :func:`tether_gym.envs.step_kernel.step_row` on every row, and returns the
rows as a :class:`~.chain.TaskStep` (views, overwritten by the next call). How the row
code runs is the subclass's: :class:`NumbaCpuStep` (``backend="numba"``) calls the numba
env's compiled :func:`~tether_gym.envs.step_kernel.step_rows` on numpy views of CPU
tensors (no copy), one thread; :class:`~.numba_cuda.NumbaCudaStep` (``"numba-cuda"``)
launches it as a CUDA kernel. Either way the equations have one source, the numba env's.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from tether_gym.envs.batch import GIVE_UP, step_config, zero_rows
from tether_gym.envs.config import EnvConfig
from tether_gym.envs.step_kernel import Rows, new_row_work, step_rows
from tether_gym.envs.workers import SLOTS, Relay
from tether_gym.physics.dispatch import Direct

from .chain import TaskStep

__all__ = ["RowStep", "NumbaCpuStep", "TORCH_DTYPES", "check_cpu"]

TORCH_DTYPES = {np.dtype(np.float64): torch.float64, np.dtype(np.float32): torch.float32,
                np.dtype(np.int64): torch.int64, np.dtype(np.bool_): torch.bool}
"""The torch dtype of each numpy dtype in :class:`~tether_gym.envs.step_kernel.Rows`."""


def check_cpu(device: torch.device) -> None:
    """A ValueError unless ``device`` is the CPU, where ``backend="numba"`` runs."""
    if device.type != "cpu":
        raise ValueError(f'backend="numba" runs the numba env\'s step on the CPU, got '
                         f"device={str(device)!r} (on a CUDA device use "
                         f'backend="numba-cuda" or "torch")')


class RowStep:
    """One control step of ``num`` rows by the numba env's row code (base class).

    Parameters
    ----------
    config : EnvConfig
        The env's configuration.
    num : int
        Rows.
    device : torch.device
        Where the rows' tensors live.

    Calling it as ``step(nu, y, u, action, disturbance, noise, par)`` (float64 tensors
    on ``device``: (B,), (B, 4n), (B, n), (B, n), (B, n), (B, 4n), (B, P)) does what
    :func:`~.chain.control_step` does and returns a :class:`~.chain.TaskStep`.
    Subclasses set ``rows`` (:class:`Rows` of tensors) and ``action`` ((B, n) tensor)
    and run the row code in :meth:`_launch`.
    """

    rows: Any  # Rows of tensors (Rows declares numpy arrays)
    action: torch.Tensor
    on_torch_stream: bool = False
    """Whether :meth:`_launch` runs on torch's current CUDA stream, where a CUDA graph
    capture records it (a CPU call is no CUDA work: False)."""

    def __init__(self, config: EnvConfig, num: int, device: torch.device):
        self.device = device
        self.num = int(num)

    def zeros(self, shape, dtype) -> torch.Tensor:
        """A zeroed tensor on the device with the torch dtype of numpy's ``dtype``."""
        return torch.zeros(shape, dtype=TORCH_DTYPES[np.dtype(dtype)], device=self.device)

    def _launch(self, reset: bool) -> None:
        raise NotImplementedError

    def __call__(self, nu, y, u, action, disturbance, noise, par) -> TaskStep:
        """One step of every row (the class docstring says what goes in and out)."""
        self.load(nu, y, u, action, disturbance, noise, par)
        self.launch()
        return self.result()

    def load(self, nu, y, u, action, disturbance, noise, par) -> None:
        """Copy a step's inputs into the rows (torch copies: a CUDA graph can hold them)."""
        r = self.rows
        for dst, src in ((r.nu, nu), (r.y, y), (r.command, u), (self.action, action),
                         (r.disturbance, disturbance), (r.noise, noise), (r.par, par)):
            dst.copy_(src)

    def launch(self) -> None:
        """Run the row code's step on the loaded rows."""
        self._launch(False)

    def result(self) -> TaskStep:
        """The rows after :meth:`launch`, as a :class:`~.chain.TaskStep` of views."""
        r = self.rows
        return TaskStep(r.nu, r.y, r.command, r.tension, r.tension_min, r.derivative, r.reward,
                        r.components, r.cost, r.failure, r.obs)

    def evaluate(self, nu, y, noise, par) -> dict[str, torch.Tensor]:
        """The reset's evaluation of every row (``step_row`` with ``reset``), as copies.

        At (nu, y) with the reels holding their rate and no disturbance: the command
        ``u`` = clip(l' / max_reel_rate, -1, 1), ``tension`` and ``tension_min`` (T^),
        ``derivative`` (dy/dnu) and the observation ``obs`` (with ``noise``).
        """
        self.load_reset(nu, y, noise, par)
        self.launch_reset()
        return {key: value.clone() for key, value in self.reset_result().items()}

    def load_reset(self, nu, y, noise, par) -> None:
        """Copy a reset evaluation's inputs into the rows (torch copies)."""
        r = self.rows
        for dst, src in ((r.nu, nu), (r.y, y), (r.noise, noise), (r.par, par)):
            dst.copy_(src)

    def launch_reset(self) -> None:
        """Run the row code's reset evaluation on the loaded rows."""
        self._launch(True)

    def reset_result(self) -> dict[str, torch.Tensor]:
        """:meth:`evaluate`'s results after :meth:`launch_reset`, as views of the rows."""
        r = self.rows
        return {"u": r.command, "tension": r.tension, "tension_min": r.tension_min,
                "derivative": r.derivative, "obs": r.obs}


class NumbaCpuStep(RowStep):
    """:class:`RowStep` on the CPU: the numba env's compiled ``step_rows``, one thread.

    The rows are CPU tensors and the kernel writes them through numpy views (no copy).
    ``nu_end`` is +inf (truncation is the torch env's business, not the kernel's).

    The kernel checks the actions before it steps any row: a NaN or inf action raises
    ValueError (naming the row) whatever the env's ``check_actions`` says, and then no
    row has changed.
    """

    def __init__(self, config: EnvConfig, num: int, device: torch.device):
        check_cpu(device)
        super().__init__(config, num, device)
        self.rows = zero_rows(config, self.num, self.zeros)
        self.rows.nu_end[:] = np.inf
        self.action = self.zeros((self.num, config.n_tethers), np.float64)
        self._args: tuple[Any, ...] = (
            np.arange(self.num, dtype=np.int64), self.action.numpy(),
            Rows(*[t.numpy() for t in self.rows]), step_config(config),
            new_row_work(config.n_tethers))
        self._relay = Relay(np.zeros(SLOTS, dtype=np.int64), GIVE_UP, 0)  # not a worker
        self._step = Direct(step_rows)

    def _launch(self, reset: bool) -> None:
        index, action, rows, cfg, work = self._args
        bad = self._step(index, action, rows, cfg, work, reset, self._relay)
        if bad >= 0:
            raise ValueError(f"actions must be finite (no NaN or inf); row {int(bad)} is "
                             f"not: {action[bad].tolist()}")
