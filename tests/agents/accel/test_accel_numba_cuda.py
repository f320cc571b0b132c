"""The numba-cuda backend: the equality tests run through its kernel, and its refusals.

CI has no GPU, so the kernel runs in numba-cuda's simulator (``NUMBA_ENABLE_CUDASIM=1``,
which must be set before numba is imported: a subprocess). The simulator runs the kernel's
Python row by row over the CPU-compiled ``step_row``: these tests check the wiring (each
thread's row and scratch, the arrays handed to the kernel, the reset's evaluation), and a
device session runs the same files with ``TETHER_TEST_DEVICE=cuda`` for the GPU's arithmetic.
"""

from __future__ import annotations

import pytest

pytest.importorskip("torch")

import torch  # noqa: E402

from tether_gym_agents.accel import numba_cuda  # noqa: E402
from tether_gym_agents.accel.vec_env import BACKENDS, TorchTetherVecEnv  # noqa: E402


@pytest.mark.slow
def test_equality_tests_pass_through_the_kernel(equality_tests_pass):
    """test_accel_chain (one step, 1e-12) and the episode/start/autoreset tests, simulated."""
    equality_tests_pass(NUMBA_ENABLE_CUDASIM="1", TETHER_TEST_BACKEND="numba-cuda")


def test_backend_refusals():
    assert BACKENDS == ("torch", "numba", "numba-cuda")
    with pytest.raises(ValueError, match="backend='jax' must be one of"):
        TorchTetherVecEnv(2, backend="jax")
    with pytest.raises(ValueError, match="dtype=torch.float32"):
        TorchTetherVecEnv(2, backend="numba-cuda", dtype=torch.float32)
    if not numba_cuda.simulated():
        with pytest.raises(ValueError, match="needs a CUDA device, got device='cpu'"):
            TorchTetherVecEnv(2, backend="numba-cuda", device="cpu")


def test_load_cuda_names_the_install_without_numba_cuda(monkeypatch):
    """numba's own deprecated CUDA target is not taken for numba-cuda's."""
    monkeypatch.setattr(numba_cuda.cuda, "implementation", "Built-in", raising=False)
    monkeypatch.setattr(numba_cuda, "simulated", lambda: False)
    with pytest.raises(ImportError, match=r'pip install "numba-cuda\[cu13\]"'):
        numba_cuda.load_cuda()


def test_the_kernel_is_launched_on_torchs_current_stream(monkeypatch):
    """On a GPU the kernel goes to torch's current stream (the default stream eagerly,
    the capture stream inside ``torch.cuda.graph``), wrapped once per stream as numba's
    external stream, so that a CUDA graph captured around it records the launch; in the
    simulator (no streams) to stream 0. The wiring only, with stand-ins for CUDA: CI
    has no GPU, and whether a capture records the launch is the device script's check."""
    launches, wrapped = [], []

    class Kernel:
        def __getitem__(self, config):
            def launch(*args):
                launches.append((config, args[-1]))
            return launch

    class Cuda:
        @staticmethod
        def external_stream(ptr):
            wrapped.append(ptr)
            return f"numba stream {ptr}"

    current = {"ptr": 0}

    class Stream:
        @property
        def cuda_stream(self):
            return current["ptr"]

    monkeypatch.setattr(numba_cuda, "_kernel", Kernel)
    monkeypatch.setattr(torch.cuda, "current_stream", lambda device=None: Stream())
    step = object.__new__(numba_cuda.NumbaCudaStep)
    step.device, step._cuda, step._streams = torch.device("cuda"), Cuda(), {}
    step._blocks, step.on_torch_stream = 3, True
    step._action = step._rows = step._cfg = step._work = None
    step.launch()
    current["ptr"] = 1234  # e.g. the stream torch.cuda.graph captures on
    step.launch_reset()
    step.launch()
    current["ptr"] = 0
    step.launch()
    tpb = numba_cuda.THREADS_PER_BLOCK
    assert launches == [((3, tpb, "numba stream 0"), False),
                        ((3, tpb, "numba stream 1234"), True),
                        ((3, tpb, "numba stream 1234"), False),
                        ((3, tpb, "numba stream 0"), False)]
    assert wrapped == [0, 1234]
    step.on_torch_stream = False  # the simulator's
    step.launch()
    assert launches[-1] == ((3, tpb, 0), False)
