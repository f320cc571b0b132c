"""The model-predictive controller: constraints on its own predictions, registry, extra."""

from __future__ import annotations

import math
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.tasks.termination import TUMBLE_ANGLE

pytest.importorskip("casadi")
from tether_gym_agents.baselines.mpc import ModelPredictiveController, _step_blocks  # noqa: E402
from tether_gym_agents.evaluation.registry import make_policy  # noqa: E402
from tether_gym_agents.evaluation.scenarios import RANDOM_INIT, Scenario  # noqa: E402


def _env(**kwargs):
    return gym.make(tether_gym.ENV_ID, action_mode="rate", **kwargs)


def _states():
    """(env, observation) pairs: the paper's reset state, random inits, e = 0.3, mid-transient."""
    out = []
    for kwargs, seed in (({}, 0), (dict(RANDOM_INIT), 1), (dict(RANDOM_INIT, eccentricity=0.3), 2),
                         (dict(RANDOM_INIT, eccentricity=0.0), 4)):
        env = _env(**kwargs)
        obs, _ = env.reset(seed=seed)
        out.append((env, obs))
    env = _env(**RANDOM_INIT)
    obs, _ = env.reset(seed=5)
    rng = np.random.default_rng(0)
    for _ in range(20):  # a state with the reels moving
        obs = env.step(rng.uniform(-1, 1, 2).astype(np.float32))[0]
    out.append((env, obs))
    return out


@pytest.mark.parametrize("case", range(5))
def test_constraints_hold_on_its_own_predictions(case):
    """After the planning of one control step (from a cold start, 4 SQP iterations), the
    plan's nominal prediction keeps T^ >= T_safe at every substep boundary of every
    planned step, |theta| below the tumble bound, the lengths (and braking stops) inside
    their bounds and |u| <= 1 (the acceleration: the next test)."""
    env, obs = _states()[case]
    cfg = env.unwrapped.config
    mpc = ModelPredictiveController.for_env(env, iterations=4)
    mpc.predict(obs)
    U = mpc.plans[0]
    assert np.all(np.abs(U) <= 1.0)
    nu, y = mpc.layout.state(obs[None].astype(np.float64))
    plan = mpc.predicted(float(nu[0]), y[0], U)
    assert mpc.last_slack <= 1e-9
    tol = 1e-7  # the QP's linearisation error after the last iteration
    assert plan.tension.min() >= cfg.reward_weights.safe_tension - tol
    assert np.abs(plan.theta).max() <= TUMBLE_ANGLE - mpc.margins["libration"] + tol
    lo, hi = cfg.length_bounds
    for value in (plan.length, plan.stop):
        assert value.min() >= lo - tol and value.max() <= hi + tol
    assert np.all(np.isfinite(plan.ddlength))


@pytest.mark.parametrize("case", range(5))
def test_acceleration_on_the_plan_is_within_the_limit(case):
    """The physical reel acceleration along the predicted plan (l' from the env's own
    step under the plan, l'' from the plan) stays within the limit."""
    env, obs = _states()[case]
    cfg = env.unwrapped.config
    mpc = ModelPredictiveController.for_env(env, iterations=3)
    mpc.predict(obs)
    nu, y = mpc.layout.state(obs[None].astype(np.float64))
    plan = mpc.predicted(float(nu[0]), y[0], mpc.plans[0])
    from tether_gym.physics import transition

    par = cfg.param_rows(cfg.eccentricity, cfg.masses)
    a_bound = cfg.scales.accel_bound(cfg.accel_limit)
    t, state = float(nu[0]), y[0]
    worst = 0.0
    moves = mpc.plans[0][_step_blocks(mpc.blocks)]  # the held command of each planned step
    for i, u in enumerate(moves):
        for s in range(cfg.n_substeps + 1):
            tr = transition(t, state, u * cfg.max_reel_rate, par, cfg.physics_step, s)
            k = 1.0 + cfg.eccentricity * math.cos(tr.nu)
            dl = tr.state[6:8]
            accel = k ** 4 * plan.ddlength[i, s] - 2 * cfg.eccentricity * math.sin(tr.nu) \
                * k ** 3 * dl
            worst = max(worst, np.abs(accel).max())
        tr = transition(t, state, u * cfg.max_reel_rate, par, cfg.physics_step, cfg.n_substeps)
        t, state = float(tr.nu), tr.state
    assert worst <= a_bound * (1 + 1e-9)


def test_runs_by_name_through_the_registry():
    kwargs = dict(RANDOM_INIT, action_mode="rate", orbits_per_episode=0.05)
    env = gym.make(tether_gym.ENV_ID, **kwargs)
    policy = make_policy("mpc", env, Scenario("tiny", "", kwargs))
    obs, _ = env.reset(seed=0)
    while True:
        action, _ = policy.predict(obs)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert truncated and not terminated, info["failure"]
    assert len(policy.policy.solve_times) == env.unwrapped.config.max_episode_steps


def test_tracks_the_nominal_reference_to_the_float32_floor():
    """From the paper's state, in the second orbit the error falls below 1e-6 rad."""
    env = _env(orbits_per_episode=1.25)
    policy = make_policy("mpc", env)
    obs, _ = env.reset(seed=0)
    errors = []
    while True:
        obs, _, terminated, truncated, info = env.step(policy.predict(obs)[0])
        errors.append((info["nu"], np.abs(info["theta"] - info["theta_ref"]).max()))
        if terminated or truncated:
            break
    assert not terminated
    late = [e for nu, e in errors if nu > 2.0 * math.pi * 1.15]
    assert max(late) < 1e-6


def test_package_imports_without_casadi_and_mpc_says_how_to_install():
    code = ("import sys; sys.modules['casadi'] = None\n"
            "import tether_gym_agents\n"
            "from tether_gym_agents.evaluation.registry import make_policy\n"
            "import gymnasium as gym, tether_gym\n"
            "env = gym.make(tether_gym.ENV_ID, action_mode='rate')\n"
            "try:\n"
            "    make_policy('mpc', env)\n"
            "except ModuleNotFoundError as exc:\n"
            "    print('ERR', exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert 'ERR' in out and 'pip install "tether_gym[mpc]"' in out


def test_missing_casadi_error_in_process(monkeypatch):
    monkeypatch.setitem(sys.modules, "casadi", None)
    with pytest.raises(ModuleNotFoundError, match=r'pip install "tether_gym\[mpc\]"'):
        make_policy("mpc", _env())


def test_unknown_weight_is_rejected():
    with pytest.raises(ValueError, match="unknown weights"):
        ModelPredictiveController.for_env(_env(), weights={"efort": 1.0})
