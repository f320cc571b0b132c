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


def test_numba_backend_refusals():
    with pytest.raises(ValueError, match="dtype=torch.float32 must be torch.float64"):
        TorchTetherVecEnv(2, backend="numba", dtype=torch.float32)
    with pytest.raises(TypeError, match="compile must be True or False"):
        TorchTetherVecEnv(2, backend="numba", compile="yes")


@pytest.mark.parametrize("mode", ["same_step", "next_step"])
def test_compile_fuses_the_torch_parts_bitwise(mode):
    """``compile=True`` with the numba backend (the inputs' copies, the results into the
    rows and the step's outputs, the starts and their writes through torch.compile):
    over 300 steps of random actions, whose ended episodes reset, every output and the
    whole state equal the eager env's bitwise, in both autoreset modes; and the pieces
    ran compiled."""
    from torch._dynamo.utils import counters

    torch._dynamo.reset()
    before = counters["stats"]["unique_graphs"]
    envs = [TorchTetherVecEnv(32, seed=5, backend="numba", autoreset_mode=mode,
                              compile=fused, init_theta_range=0.3, disturbance=0.1,
                              obs_noise=1e-3, eccentricity_range=(0.0, 0.3))
            for fused in (False, True)]
    first = [env.reset() for env in envs]
    assert torch.equal(first[0][0], first[1][0])
    gen = torch.Generator().manual_seed(2)
    ended = 0
    for _ in range(300):
        a = 1.2 * (2.0 * torch.rand((32, envs[0].n), generator=gen, dtype=torch.float64) - 1.0)
        (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) = (env.step(a) for env in envs)
        assert torch.equal(o1, o2) and torch.equal(r1, r2)
        assert torch.equal(te1, te2) and torch.equal(tr1, tr2)
        assert i1.keys() == i2.keys() and all(torch.equal(i1[k], i2[k]) for k in i1)
        ended += int((te1 | tr1).sum())
    for name in ("nu", "y", "u", "par", "noise", "disturbance", "tension", "derivative",
                 "reward", "cost", "failure", "steps", "nu_end", "_start_failed",
                 "_start_code"):
        assert torch.equal(getattr(envs[0], name), getattr(envs[1], name)), name
    assert ended >= 20  # the resets ran, in both envs alike
    # same_step: the load, the step's end, the starts, the reset's end; next_step: the
    # load, the starts and the reset's end (its step ends in _advance, eagerly)
    assert counters["stats"]["unique_graphs"] - before >= (4 if mode == "same_step" else 3)


def test_numba_backend_needs_the_cpu():
    with pytest.raises(ValueError, match="on the CPU, got device='cuda'"):
        check_backend("numba", torch.device("cuda"))


def test_the_final_check_runs_on_the_training_backend():
    """``train.py gpu``'s final check (``deterministic_episodes``) on the numba backend,
    which a numba run now uses, scores what the torch port scores: the same survivals
    and, to 1e-9, the same returns and tracking errors, for a policy that holds the reels
    (every episode survives) and one that swings them in half the episodes (which fail)."""
    from tether_gym_agents.accel.trainer import deterministic_episodes

    env_kwargs = {"increment_gain": 0.5, "orbits_per_episode": 1.5, "mass_range": 0.25,
                  "eccentricity_range": (0.0, 0.35), "init_theta_range": 0.15}

    def hold(raw):
        return torch.zeros(raw.shape[:-1] + (2,), dtype=torch.float64)

    def hold_or_swing(raw):  # the first half of each group's episodes hold, the rest fail
        swing = torch.tanh(3.0 * raw[..., 2:4].double())
        return torch.where(torch.arange(8)[:, None] < 4, hold(raw), swing)

    for act, survivors in ((hold, (1.0, 1.0)), (hold_or_swing, (0.5, 0.5))):
        out = {b: deterministic_episodes(act, 2, env_kwargs, torch.device("cpu"), 8, 3,
                                         backend=b) for b in ("torch", "numba")}
        assert out["torch"]["survived"] == out["numba"]["survived"] == list(survivors)
        np.testing.assert_allclose(out["numba"]["mean_return"], out["torch"]["mean_return"],
                                   rtol=1e-9)
        for r_n, r_t in zip(out["numba"]["tracking_rms"], out["torch"]["tracking_rms"],
                            strict=True):
            assert (r_n is None) == (r_t is None)
            if r_t is not None:
                assert r_n == pytest.approx(r_t, rel=1e-9)


def test_a_numba_run_checks_itself_on_the_numba_backend(tmp_path, monkeypatch):
    from tether_gym_agents.accel import trainer
    from tether_gym_agents.accel.ppo import PPOSettings

    backends = []
    real = trainer.deterministic_episodes

    def recorded(*args, **kwargs):
        backends.append(kwargs["backend"])
        return real(*args, **kwargs)

    monkeypatch.setattr(trainer, "deterministic_episodes", recorded)
    settings = PPOSettings(n_envs=2, n_steps=4, batch_size=8, n_epochs=1, net_arch=(8, 8))
    run = trainer.GpuRun([0], 16, {"increment_gain": 0.5, "orbits_per_episode": 0.05},
                         tmp_path, torch.device("cpu"), checkpoints=1, eval_episodes=2,
                         backend="numba")
    summary = trainer.train_seeds(settings, run, log=None)
    assert backends == ["numba"] and summary["final"]["survived"]
