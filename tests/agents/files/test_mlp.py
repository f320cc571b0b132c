"""The float64 NumPy forward pass: SB3's deterministic action, bitwise batch-invariant."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.files.mlp import NumpyMLP


def _model(algo, **kwargs):
    from stable_baselines3 import PPO, SAC

    env = gym.make(tether_gym.ENV_ID)
    if algo == "ppo":
        return PPO("MlpPolicy", env, seed=0, device="cpu",
                   policy_kwargs={"net_arch": [64, 64]}, **kwargs)
    return SAC("MlpPolicy", env, seed=0, device="cpu", policy_kwargs={"net_arch": [32, 32]},
               **kwargs)


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_matches_sb3_and_is_batch_invariant(algo):
    model = _model(algo)
    mlp = NumpyMLP.from_policy(model.policy)
    assert mlp is not None
    rng = np.random.default_rng(0)
    obs = rng.normal(0.0, 2.0, size=(37, 20)).astype(np.float32)
    expected = model.predict(obs, deterministic=True)[0]
    got = mlp(obs)
    # SB3 runs in float32, NumPy in float64: equal to float32 rounding
    np.testing.assert_allclose(got, expected, rtol=0, atol=2e-6)
    assert np.abs(got).max() > 0.01  # a real output, not all zero or clipped
    # row i is bitwise the same alone, in batches of any size and beside any rows
    alone = np.array([mlp(obs[i:i + 1])[0] for i in range(len(obs))])
    assert np.array_equal(got, alone)
    for size in (2, 5, 16):
        other = rng.normal(size=(size - 1, 20)).astype(np.float32)
        batch = mlp(np.concatenate([obs[3:4], other]))
        assert np.array_equal(batch[0], alone[3])


def test_unsupported_networks_fall_back():
    model = _model("ppo", use_sde=True)
    assert NumpyMLP.from_policy(model.policy) is None


def _pairwise(terms: list[float]) -> float:
    """The module docstring's summation order: NumPy's pairwise sum, in plain Python."""
    n = len(terms)
    if n < 8:
        total = -0.0
        for t in terms:
            total += t
        return total
    if n <= 128:
        r = terms[:8]
        i = 8
        while i < n - n % 8:
            r = [r[k] + terms[i + k] for k in range(8)]
            i += 8
        total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for t in terms[i:]:
            total += t
        return total
    half = n // 2
    half -= half % 8
    return _pairwise(terms[:half]) + _pairwise(terms[half:])


@pytest.mark.parametrize("n_in", [1, 3, 7, 8, 9, 20, 24, 64, 127, 128, 129, 136, 256, 257,
                                  300, 512, 1000])
def test_compiled_dot_products_sum_in_numpys_pairwise_order(n_in):
    """pairwise_linear is bitwise NumPy's ``(h[:, None, :] * W).sum(-1)`` (the order the
    shipped results were made in), over widths around every branch of the pairwise
    sum: below 8, up to the 128-term block, split in halves above it."""
    from tether_gym_agents.files.mlp import pairwise_linear

    rng = np.random.default_rng(n_in)
    for scale in (1e-3, 1.0, 1e3):
        h = rng.standard_normal((int(rng.integers(1, 9)), n_in)) * scale
        w = rng.standard_normal((int(rng.integers(1, 70)), n_in))
        expected = (h[:, None, :] * w[None, :, :]).sum(axis=-1)
        got = pairwise_linear(h, w)
        assert got.dtype == np.float64 and got.shape == expected.shape
        assert np.array_equal(got, expected)
        # the documented order written out in Python, independently of NumPy's version
        reference = np.array([[0.0 + _pairwise(list(row * col)) for col in w] for row in h])
        assert np.array_equal(got, reference)
        # a plain matrix product sums in another order: the test can tell them apart
        if n_in >= 20 and scale == 1.0:
            assert not np.array_equal(h @ w.T, expected)


def test_pairwise_linear_refuses_shapes_that_do_not_fit():
    from tether_gym_agents.files.mlp import pairwise_linear

    with pytest.raises(ValueError, match=r"\(2, 3\).*\(4, 5\)"):
        pairwise_linear(np.zeros((2, 3)), np.zeros((4, 5)))
