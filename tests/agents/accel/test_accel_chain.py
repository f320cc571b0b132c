"""The torch step equals the numba step: one step from 10^4 random states, N = 2..6.

Every combination of tethers (N - 1 = 1..5), gravity model and action mode steps 500
random rows (random e, masses, angles, rates, lengths, commands, actions, disturbances
and observation noise, wild rows included so that every failure code occurs) once
through the numba kernel (``step_kernel.step_rows``) and once through
:class:`TorchTetherVecEnv` on the CPU, from the same rows: the state, true anomaly,
reward and its components, tensions, derivative and every ``info`` entry agree to
1e-12 (relative, float64), the failure codes exactly, and the float32 observation to
float32 rounding.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from tether_gym.envs.batch import ChainBatch  # noqa: E402
from tether_gym.envs.config import EnvConfig  # noqa: E402
from tether_gym.tasks.termination import KEEP_PREVIOUS, Failure  # noqa: E402
from tether_gym_agents.accel.vec_env import TorchTetherVecEnv  # noqa: E402

ROWS = 500
RTOL = 1e-12
DEVICE = os.environ.get("TETHER_TEST_DEVICE", "cpu")
"""Where the torch step runs: CI has no GPU; a device session sets "cuda"."""
BACKEND = os.environ.get("TETHER_TEST_BACKEND", "torch")
"""TorchTetherVecEnv's backend: "numba-cuda" on a GPU, or in numba-cuda's simulator
(test_accel_numba_cuda.py runs this file so)."""


def _random_rows(config: EnvConfig, rng: np.random.Generator, rows: int) -> dict:
    """Random state, parameter, command, disturbance and noise rows (some far out)."""
    n = config.n_tethers
    th = rng.uniform(-1.3, 1.3, (rows, n))
    dth = rng.uniform(-0.5, 0.5, (rows, n))
    ln = rng.uniform(0.3, 1.5, (rows, n)) / n
    dl = rng.uniform(-0.05, 0.05, (rows, n))
    wild = rng.random(rows) < 0.1  # far from any healthy state: slack, diverged, ...
    dth[wild] *= rng.choice([10.0, 1e3, 1e7], (wild.sum(), 1))
    ln[wild] *= rng.choice([1e-3, 1.0, 30.0], (wild.sum(), 1))
    ecc = rng.uniform(0.0, 0.6, rows)
    masses = rng.uniform(0.5, 2.0, (rows, n))
    return {"nu": rng.uniform(-10.0, 30.0, rows),
            "y": np.concatenate([th, dth, ln, dl], axis=1),
            "par": config.param_rows(ecc, masses),
            "command": rng.uniform(-1.0, 1.0, (rows, n)),
            "disturbance": rng.uniform(-0.1, 0.1, (rows, n)),
            "noise": rng.normal(0.0, 1e-3, (rows, 4 * n)),
            "action": rng.uniform(-1.5, 1.5, (rows, n))}


def _numba_step(config: EnvConfig, draw: dict):
    batch = ChainBatch(config, ROWS, check_start=False)
    r = batch.rows
    for key in ("nu", "y", "par", "command", "disturbance", "noise"):
        getattr(r, key)[...] = draw[key]
    r.nu_end[...] = draw["nu"] + 1.0
    index = np.arange(ROWS, dtype=np.int64)
    bad = batch._step(index, np.ascontiguousarray(draw["action"]), r, batch.cfg,
                      batch._work[0], False, batch._once)
    assert bad == -1
    return batch


def _torch_step(config_kwargs: dict, draw: dict) -> TorchTetherVecEnv:
    env = TorchTetherVecEnv(ROWS, device=DEVICE, seed=0, backend=BACKEND, **config_kwargs)
    assert env.backend == BACKEND
    env.reset()
    def as_t(x):
        return (torch.as_tensor(x, dtype=torch.float64, device=env.device))
    env.nu, env.y, env.par = as_t(draw["nu"]), as_t(draw["y"]), as_t(draw["par"])
    env.u, env.disturbance, env.noise = (as_t(draw["command"]), as_t(draw["disturbance"]),
                                         as_t(draw["noise"]))
    env.nu_end = env.nu + 1.0
    env._advance(as_t(draw["action"]), torch.ones(ROWS, dtype=torch.bool, device=env.device),
                 draw=False)
    return env


def close(actual, expected, what):
    actual = np.asarray(actual.cpu() if hasattr(actual, "cpu") else actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=RTOL * 1e-3, err_msg=what)


@pytest.mark.parametrize("action_mode", ["increment", "rate"])
@pytest.mark.parametrize("gravity", ["gradient", "full"])
@pytest.mark.parametrize("n_bodies", [2, 3, 4, 5, 6])
def test_one_step_equals_numba(n_bodies, gravity, action_mode):
    kwargs = {"n_bodies": n_bodies, "gravity": gravity, "action_mode": action_mode,
              "initial_theta": [0.0] * (n_bodies - 1), "observe_params": True}
    config = EnvConfig.from_kwargs(**kwargs)
    draw = _random_rows(config, np.random.default_rng(1000 * n_bodies + len(gravity)), ROWS)
    ref = _numba_step(config, draw)
    env = _torch_step(kwargs, draw)
    r = ref.rows
    codes = env.failure.cpu().numpy()
    np.testing.assert_array_equal(codes, r.failure)
    assert len(set(codes.tolist())) >= 3, "the random rows should reach several failure codes"
    # a diverged or non-finite step keeps its previous state (compared on every row); the
    # tensions and derivative it reached are beyond 1e6 or overflowed (no physics, and
    # their rounding is chaotic): those are compared on the other rows
    sane = ~np.isin(codes, KEEP_PREVIOUS)
    assert (~sane).any() and sane.sum() > ROWS // 2
    for name in ("nu", "y", "reward", "components", "command"):
        got = getattr(env, "u" if name == "command" else name).cpu().numpy()
        close(got, getattr(r, name), name)
    for name in ("tension", "tension_min", "derivative"):
        close(getattr(env, name).cpu().numpy()[sane], getattr(r, name)[sane], name)
    np.testing.assert_allclose(env.obs.cpu().numpy(), r.obs, rtol=2.0**-23, atol=0.0,
                               err_msg="observation")
    info, expected = env.info(), ref.info_arrays()
    for key, value in info.items():
        if key == "failure":
            assert [Failure(int(c)).label for c in value.cpu().numpy()] == list(expected[key])
            continue
        close(value.cpu().numpy()[sane], expected[key][sane], f"info[{key!r}]")
