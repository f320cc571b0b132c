"""The accel tests' shared helpers: the equality tests run again through another backend,
bench/'s scripts loaded as modules, and a tiny ``train.py gpu`` config."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).parent
ROOT = HERE.parents[2]

TINY = """tether_gym/TetherLibration-v2:
  n_envs: 8
  n_steps: 16
  batch_size: 48
  n_epochs: 3
  n_timesteps: 1000
"""
"""A ``train.py gpu`` config of 8 envs x 16 steps per rollout, 9 minibatch steps, 8
iterations."""


@pytest.fixture(scope="session")
def load_bench():
    """``load_bench(name)``: ``bench/<name>.py`` as a module (bench/ holds scripts, not a
    package)."""

    def load(name: str):
        spec = importlib.util.spec_from_file_location(name, ROOT / "bench" / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """:data:`TINY` in a file."""
    path = tmp_path_factory.mktemp("cfg") / "tiny.yml"
    path.write_text(TINY)
    return path


@pytest.fixture
def equality_tests_pass():
    """Run test_accel_chain's and test_accel_vec_env's equality tests in a subprocess.

    Calling it with environment overrides (``TETHER_TEST_BACKEND`` and the like, read by
    those files at import: hence a subprocess) asserts that they all pass, none skipped.
    """

    def run(**overrides: str) -> None:
        env = {**os.environ, "TETHER_TEST_DEVICE": "cpu", "OMP_NUM_THREADS": "1",
               "NUMBA_NUM_THREADS": "1", **overrides}
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
               str(HERE / "test_accel_chain.py"), str(HERE / "test_accel_vec_env.py"),
               "-k", "equal_numba or equals_numba or autoreset"]
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        tail = (done.stdout + done.stderr)[-3000:]
        assert done.returncode == 0, tail
        assert " passed" in tail and "skipped" not in tail and "deselected" in tail, tail

    return run


@pytest.fixture
def recorded_graphs(monkeypatch):
    """``train.py gpu --cuda-graphs`` on the CPU: its graphs kept by ``RecordingCapture``.

    The trainer's ``CudaCapture`` becomes ``RecordingCapture``, and Adam the CPU's fused
    one (which keeps its step count on the device, as CUDA's capturable Adam does).
    Returns the list of the functions captured, in order.
    """
    import torch

    from tether_gym_agents.accel import graphs
    from tether_gym_agents.accel.graphs import RecordingCapture

    real_adam = torch.optim.Adam
    monkeypatch.setattr(torch.optim, "Adam",
                        lambda params, **kw: real_adam(params, **{**kw, "fused": True}))
    monkeypatch.setattr(graphs, "CudaCapture", RecordingCapture)
    captures = []
    real_capture = RecordingCapture.capture

    def counted_capture(self, fn, generators=()):
        captures.append(fn)
        return real_capture(self, fn, generators)

    monkeypatch.setattr(RecordingCapture, "capture", counted_capture)
    return captures
