"""The accel tests' shared helper: the equality tests run again through another backend."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).parent


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
