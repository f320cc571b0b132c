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
    assert 'ERR' in out and 'pip install -e ".[mpc]"' in out


def test_missing_casadi_error_in_process(monkeypatch):
    monkeypatch.setitem(sys.modules, "casadi", None)
    with pytest.raises(ModuleNotFoundError, match=r'pip install -e "\.\[mpc\]"'):
        make_policy("mpc", _env())


# ---------------------------------------------------------------------------------------
# arguments: each refused with a clear error before any CasADi function is built


@pytest.fixture
def no_build(monkeypatch):
    """Fail loudly if a test's controller gets as far as building its solver functions."""
    from tether_gym_agents.baselines import mpc as mpc_module

    def refuse(*args):
        raise AssertionError("built the solver functions before refusing the argument")

    monkeypatch.setattr(mpc_module, "_solver_functions", refuse)


@pytest.mark.parametrize(("kwargs", "error", "match"), [
    (dict(blocks=5), TypeError, r"blocks must be a sequence of ints >= 1.*got int 5"),
    (dict(blocks="abc"), TypeError, r"blocks must be a sequence.*got str 'abc'"),
    (dict(blocks=()), ValueError, r"blocks holds 0 moves; valid: 1 \.\.\. 40"),
    (dict(blocks=(1,) * 300), ValueError, r"blocks holds 300 moves; valid: 1 \.\.\. 40"),
    (dict(blocks=(100, 30)), ValueError, r"plans 130 control steps; valid: at most 120"),
    (dict(blocks=(1, 0)), ValueError, r"blocks\[1\]=0 is outside the valid range \[1, 120\]"),
    (dict(blocks=(1, 2.0)), TypeError, r"blocks\[1\] must be an int in \[1, 120\], got float"),
    (dict(iterations=0), ValueError, r"iterations=0 is outside the valid range \[1, 20\]"),
    (dict(iterations=10**9), ValueError, r"iterations=1000000000 is outside"),
    (dict(iterations=True), TypeError, r"iterations must be an int in \[1, 20\], got bool"),
    (dict(weights="abc"), TypeError, r"weights must be a dict with keys from .*got str 'abc'"),
    (dict(weights={"efort": 1.0}), ValueError, r"unknown weights \['efort'\]; valid"),
    (dict(weights={"rate": -1.0}), ValueError, r"weights\[.rate.\]=-1.0 is outside"),
    (dict(weights={"slack": 0.0}), ValueError, r"weights\['slack'\]=0.0 is outside the valid "
                                               r"range \(0.0, 1000000000000.0\]"),
    (dict(weights={"move": float("nan")}), ValueError, r"weights\['move'\]=nan must be finite"),
    (dict(weights={"tail": "x"}), TypeError, r"weights\['tail'\] must be a real number"),
    (dict(margins=[1]), TypeError, r"margins must be a dict"),
    (dict(margins={"libration": 10.0}), ValueError,
     r"margins\['libration'\]=10.0 is outside the valid range \[0.0, 1.5707963267948966\)"),
    (dict(margins={"length": -0.1}), ValueError, r"margins\['length'\]=-0.1 is outside"),
    (dict(margins={"tension_floor": 2.0}), ValueError,
     r"margins\['tension_floor'\]=2.0 is outside the valid range \[0.0, 0.5\]"),
])
def test_arguments_are_checked_before_any_work(kwargs, error, match, no_build):
    with pytest.raises(error, match=match):
        ModelPredictiveController.for_env(_env(), **kwargs)


@pytest.mark.parametrize(("nominal", "error", "match"), [
    ({"masses": (0.0, 2.0)}, ValueError, r"nominal masses for 2 tethers: .*must all be > 0"),
    ({"masses": (-1.0, 2.0)}, ValueError, r"must all be > 0"),
    ({"masses": (1.0, 2.0, 3.0)}, ValueError, r"nominal masses for 2 tethers: .*must have 2 "
                                              r"entries, got 3"),
    ({"masses": "ab"}, TypeError, r"nominal masses for 2 tethers"),
    ({"eccentricity": 1.5}, ValueError,
     r"nominal eccentricity=1.5 is outside the valid range \[0.0, 1.0\)"),
    ({"eccentricity": -0.1}, ValueError, r"nominal eccentricity=-0.1 is outside"),
    ({"reel_time_constant": 0.0}, ValueError, r"nominal reel_time_constant=0.0 is outside "
                                              r"the valid range \(0.0, inf\]"),
    ({"accel_limit": float("nan")}, ValueError, r"nominal accel_limit=nan must be finite"),
    ({"mass": (1.0, 2.0)}, ValueError, r"unknown nominal \['mass'\]; valid"),
    ("abc", TypeError, r"nominal must be a dict"),
])
def test_nominal_model_is_checked_before_any_work(nominal, error, match, no_build):
    with pytest.raises(error, match=match):
        ModelPredictiveController.for_env(_env(), nominal)


def test_a_bad_nominal_model_in_a_suite_file_is_refused_before_any_episode(tmp_path, no_build):
    """Through the user's command: a YAML suite whose nominal masses are <= 0 (checked
    when the suite file is read, before any policy is built)."""
    from tether_gym_agents.evaluation.benchmark import evaluate

    suite = tmp_path / "bad.yml"
    suite.write_text("scenarios:\n  - name: bad\n    env_kwargs: {}\n"
                     "    nominal: {masses: [0.0, 2.0]}\n")
    with pytest.raises(ValueError, match=r"bad.yml, scenario 0 \(bad\): nominal "
                                         r"masses=\(0.0, 2.0\) must all be > 0"):
        evaluate(["mpc"], suite=str(suite), n_seeds=1, out=None, log=None)


def test_a_hand_built_step_is_checked(no_build):
    from dataclasses import replace

    from tether_gym.physics import PARAMS
    from tether_gym_agents.baselines.prediction import NominalStep
    from tether_gym_agents.common.obs import ObservationLayout

    env = _env()
    step = NominalStep.for_env(env)
    params = step.params.copy()
    params[PARAMS.slices(2)["eccentricity"]] = 1.5
    with pytest.raises(ValueError, match=r"the nominal model's eccentricity=1.5 is outside"):
        ModelPredictiveController(replace(step, params=params), ObservationLayout.from_env(env))


@pytest.mark.parametrize(("make", "match"), [
    (lambda: ModelPredictiveController.for_env(_env(), {"eccentricity": 0.9}),
     r"nominal eccentricity 0.9 is beyond the 0.4 it was checked on"),
    (lambda: ModelPredictiveController.for_env(_env(n_bodies=6)),
     r"5 tethers \(N = 6 bodies\) is beyond the 2 it was checked on"),
])
def test_beyond_its_reach_it_warns(make, match, no_build):
    with pytest.warns(UserWarning, match=match), pytest.raises(AssertionError, match="built"):
        make()


def test_non_finite_observations_are_refused_before_planning():
    env = _env()
    mpc = ModelPredictiveController.for_env(env)
    obs, _ = env.reset(seed=0)
    bad = np.array(obs, dtype=np.float64)
    bad[3] = np.nan
    with pytest.raises(ValueError, match=r"observation row 0 has non-finite entries at "
                                         r"indices \[3\] \(\[nan\]\)"):
        mpc.predict(bad)
    assert mpc.solve_times == []
    batch = np.stack([obs, obs]).astype(np.float64)
    batch[1, 0] = np.inf
    with pytest.raises(ValueError, match=r"row 1 has non-finite entries at indices \[0\]"):
        mpc.predict(batch)
