"""The numba backend on the CPU: the equality tests run through it, and its refusals.

``backend="numba"`` steps the torch env's rows with the numba env's own compiled
``step_rows``; the equality tests of test_accel_chain.py and test_accel_vec_env.py run
with it (``TETHER_TEST_BACKEND=numba``, read at their import: a subprocess).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

import torch  # noqa: E402

from tether_gym_agents.accel.vec_env import TorchTetherVecEnv, check_backend  # noqa: E402


@pytest.mark.slow
def test_equality_tests_pass_through_the_numba_backend(equality_tests_pass):
    """One step at 1e-12, whole episodes at 1e-9, starts and both autoresets, via numba."""
    equality_tests_pass(TETHER_TEST_BACKEND="numba")


def test_numba_and_torch_backends_give_the_same_rollout():
    """Same seed, same actions: the two backends' whole outputs agree (different code)."""
    out = {}
    for backend in ("torch", "numba"):
        env = TorchTetherVecEnv(16, seed=3, backend=backend, autoreset_mode="same_step")
        obs, _ = env.reset()
        gen = torch.Generator().manual_seed(1)
        rows = []
        for _ in range(120):
            a = 2.0 * torch.rand((16, env.n), generator=gen, dtype=torch.float64) - 1.0
            obs, reward, term, trunc, info = env.step(a)
            rows.append((obs.clone(), reward.clone(), term.clone(), info["failure"].clone(),
                         info["theta"].clone()))
        out[backend] = rows
    ended = 0
    for (o1, r1, t1, f1, th1), (o2, r2, t2, f2, th2) in zip(out["torch"], out["numba"],
                                                            strict=True):
        np.testing.assert_allclose(r2.numpy(), r1.numpy(), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(th2.numpy(), th1.numpy(), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(o2.numpy(), o1.numpy(), rtol=1e-5, atol=1e-6)
        assert torch.equal(t1, t2) and torch.equal(f1, f2)
        ended += int(t1.sum())
    assert ended > 0  # random actions end some episodes: the autoreset is compared too


def test_a_nan_action_is_refused_and_changes_nothing():
    env = TorchTetherVecEnv(4, seed=0, backend="numba", check_actions=False)
    env.reset()
    y = env.y.clone()
    a = torch.zeros((4, env.n), dtype=torch.float64)
    a[2, 1] = float("nan")
    with pytest.raises(ValueError, match=r"row 2 is not: \[0.0, nan\]"):
        env.step(a)
    assert torch.equal(env.y, y)


@pytest.mark.parametrize("kwargs, message", [
    ({"compile": True}, "compile=True must be False"),
    ({"dtype": torch.float32}, "dtype=torch.float32"),
])
def test_numba_backend_refusals(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TorchTetherVecEnv(2, backend="numba", **kwargs)


def test_numba_backend_needs_the_cpu():
    with pytest.raises(ValueError, match="on the CPU, got device='cuda'"):
        check_backend("numba", torch.device("cuda"))
