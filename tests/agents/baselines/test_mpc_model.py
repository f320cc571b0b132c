"""The MPC's symbolic model equals the project's physics (tether_gym.physics.transition)."""

from __future__ import annotations

import numpy as np
import pytest

from tether_gym.physics import TetherChain, transition

pytest.importorskip("casadi")
from tether_gym_agents.baselines import mpc_model  # noqa: E402

TOL = 1e-10


def _case(rng, n, full):
    masses = rng.uniform(0.3, 3.0, n)
    ecc = rng.uniform(0.0, 0.6)
    chain = TetherChain(masses, ecc, "full" if full else "gradient",
                        rng.uniform(1e-4, 5e-3) if full else None)
    par = chain.param_row(accel_bound=float(rng.choice([np.inf, 0.775, 0.2])),
                          speed_bound=float(rng.choice([np.inf, 0.4])),
                          time_constant=float(rng.choice([0.0125, 0.05])))
    y = np.concatenate([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.6, 0.6, n),
                        rng.uniform(0.05, 1.2, n), rng.uniform(-0.4, 0.4, n)])
    return par, y, rng.uniform(-0.6, 0.6, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-20, 20)


@pytest.mark.parametrize("full", [False, True], ids=["gradient", "full"])
@pytest.mark.parametrize("n", [1, 2, 3, 5])
@pytest.mark.parametrize("substeps", [1, 2, 3])
def test_step_equals_transition(n, full, substeps):
    """Random states, e, masses, reel limits (saturating or not), disturbances: the
    symbolic step's end state, tensions at the substep boundaries, end tension and
    derivative agree with the compiled step to 1e-10."""
    rng = np.random.default_rng(100 * n + 10 * substeps + full)
    step = mpc_model.step_function(n, substeps, full)
    for _ in range(6):
        par, y, cmd, dist, nu = _case(rng, n, full)
        h = 0.0125
        ref = transition(nu, y, cmd, par, h, substeps, disturbance=dist)
        nu_end, y_end, tensions, deriv = (np.asarray(v) for v in step(nu, y, cmd, dist, par, h))
        assert abs(nu_end.item() - ref.nu) <= TOL
        np.testing.assert_allclose(y_end.ravel(), ref.state, rtol=0, atol=TOL)
        np.testing.assert_allclose(tensions.min(axis=1), ref.tension_min, rtol=0, atol=TOL)
        np.testing.assert_allclose(tensions[:, -1], ref.tension, rtol=0, atol=TOL)
        np.testing.assert_allclose(deriv.ravel(), ref.derivative, rtol=0, atol=TOL)


def test_step_equals_the_env_step_of_the_default_config():
    """With the env's own parameter row, steps and reel limits, chained over 40 steps."""
    import gymnasium as gym

    import tether_gym

    env = gym.make(tether_gym.ENV_ID, action_mode="rate", eccentricity=0.3)
    cfg = env.unwrapped.config
    par = cfg.param_rows(cfg.eccentricity, cfg.masses)
    step = mpc_model.step_function(cfg.n_tethers, cfg.n_substeps, False)
    _, info = env.reset(seed=3)
    nu = float(info["nu"])
    y = np.concatenate([info["theta"], info["dtheta"], info["length"], info["dlength"]])
    rng = np.random.default_rng(0)
    for _ in range(40):
        u = rng.uniform(-1, 1, cfg.n_tethers)
        _, _, _, _, info = env.step(u.astype(np.float32))
        out = step(nu, y, u.astype(np.float32).astype(float) * cfg.max_reel_rate,
                   np.zeros(cfg.n_tethers), par, cfg.physics_step)
        nu, y = np.asarray(out[0]).item(), np.asarray(out[1]).ravel()
        env_y = np.concatenate([info["theta"], info["dtheta"], info["length"],
                                info["dlength"]])
        np.testing.assert_allclose(y, env_y, rtol=0, atol=TOL)
        np.testing.assert_allclose(np.asarray(out[2]).min(axis=1), info["tension_min"],
                                   rtol=0, atol=TOL)


def test_missing_casadi_names_the_pip_command(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "casadi", None)
    with pytest.raises(ModuleNotFoundError, match=r'pip install -e "\.\[mpc\]"'):
        mpc_model.casadi()
