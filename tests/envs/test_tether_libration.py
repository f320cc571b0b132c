"""TetherLibrationEnv: API conformance, determinism, physics, episode end, validation."""

from __future__ import annotations

import math
import re
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from scipy.integrate import solve_ivp

import tether_gym
from tether_gym.envs import TetherLibrationEnv
from tether_gym.physics import PARAMS, TetherChain

from .conftest import (
    INFO_KEYS,
    REWARD_COMPONENTS,
    REWARD_HIGH,
    REWARD_LOW,
    assert_info_equal,
    no_unexpected_warnings,
)

RANDOMISED = {
    "eccentricity_range": (0.1, 0.3),
    "mass_range": 0.2,
    "init_theta_range": 0.05,
    "init_dtheta_range": 0.05,
    "init_length_range": 0.05,
    "obs_noise": 0.01,
    "disturbance": 0.01,
}


# --------------------------------------------------------------------------- #
# API conformance
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("kwargs", [
    {},
    {"n_bodies": 4, "eccentricity_range": (0.1, 0.4), "mass_range": 0.3},
    {"action_mode": "rate"},
], ids=["default", "randomised-N4", "rate-mode"])
def test_check_env_gymnasium_and_sb3(make_env, kwargs):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    with no_unexpected_warnings():
        env = make_env(**kwargs)
        check_env(env.unwrapped)
        sb3_check_env(env)


def test_warning_guard_fails_on_unlisted_warning():
    """The allow-list check itself can fail (guards the check_env test)."""
    with pytest.raises(AssertionError, match="unexpected warnings"):
        with no_unexpected_warnings():
            warnings.warn("A Box observation space minimum value is -infinity", UserWarning,
                          stacklevel=1)  # allowed
            warnings.warn("something else", RuntimeWarning, stacklevel=1)  # not allowed


def test_spaces(make_env):
    env = make_env(n_bodies=4)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    space = env.observation_space
    assert space.dtype == np.float32 and space.shape == (8 * 3 + 4,)
    np.testing.assert_array_equal(space.low[:2], [-1, -1])
    np.testing.assert_array_equal(space.high[:2], [1, 1])
    env_r = make_env(n_bodies=4, mass_range=0.1)
    assert env_r.observation_space.shape == (8 * 3 + 4 + 4,)


def test_no_registered_time_limit(make_env):
    """The env truncates itself after orbits_per_episode; a registered limit would cut
    lengthened episodes (tests/envs/test_contract.py)."""
    env = make_env()
    assert env.spec.max_episode_steps is None
    assert env.unwrapped.max_episode_steps == tether_gym.DEFAULT_MAX_EPISODE_STEPS == 754
    assert env.spec.vector_entry_point == "tether_gym.envs.vector:TetherLibrationVectorEnv"


# --------------------------------------------------------------------------- #
# determinism and reset options
# --------------------------------------------------------------------------- #
def _rollout(env, seed, actions, options=None):
    obs, info = env.reset(seed=seed, options=options)
    out = [(obs, None, info)]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs, reward, info))
        if terminated or truncated:
            break
    return out


def test_same_seed_same_actions_bitwise_identical(make_env):
    actions = np.random.default_rng(123).uniform(-0.3, 0.3, (60, 2)).astype(np.float32)
    env_a, env_b = make_env(**RANDOMISED), make_env(**RANDOMISED)
    run_a = _rollout(env_a, 7, actions)
    run_b = _rollout(env_b, 7, actions)
    run_c = _rollout(env_a, 7, actions)  # same env re-seeded
    assert len(run_a) == len(run_b) == len(run_c) == 61
    for (oa, ra, ia), (ob, rb, ib), (oc, rc, ic) in zip(run_a, run_b, run_c, strict=True):
        assert oa.tobytes() == ob.tobytes() == oc.tobytes()
        assert ra == rb == rc
        assert_info_equal(ia, ib)
        assert_info_equal(ia, ic)


def test_different_seeds_differ_with_randomisation(make_env):
    env = make_env(**RANDOMISED)
    obs_a, info_a = env.reset(seed=1)
    obs_b, info_b = env.reset(seed=2)
    assert info_a["eccentricity"] != info_b["eccentricity"]
    assert 0.1 <= info_a["eccentricity"] <= 0.3 and 0.1 <= info_b["eccentricity"] <= 0.3
    assert not np.array_equal(info_a["theta"], info_b["theta"])
    assert not np.array_equal(obs_a, obs_b)
    # without randomisation the seed does not matter
    plain = make_env()
    assert plain.reset(seed=1)[0].tobytes() == plain.reset(seed=2)[0].tobytes()


@pytest.mark.parametrize("kwargs", [{}, RANDOMISED], ids=["plain", "randomised"])
def test_reset_options_round_trip(make_env, kwargs):
    options = {"nu": 0.3, "theta": [0.05, -0.02], "dtheta": [0.1, 0.2],
               "length": [0.4, 0.6], "dlength": [0.01, -0.02]}
    env = make_env(**kwargs)
    obs, info = env.reset(seed=3, options=options)
    assert info["nu"] == 0.3
    for key in ("theta", "dtheta", "length", "dlength"):
        np.testing.assert_array_equal(info[key], options[key], err_msg=key)
    if not kwargs:  # no noise: the observation carries the same state
        np.testing.assert_array_equal(obs[2:10], np.float32(np.concatenate(
            [options[k] for k in ("theta", "dtheta", "length", "dlength")])))
    # a partial option set keeps the configured defaults for the rest
    _, info = make_env().reset(options={"length": [0.3, 0.7]})
    np.testing.assert_array_equal(info["theta"], [0.1, 0.0])
    np.testing.assert_array_equal(info["length"], [0.3, 0.7])


# --------------------------------------------------------------------------- #
# physics: the env against an independent fine integration of the core's equations
# --------------------------------------------------------------------------- #
def _env_and_reference(n_bodies, dlength, physics_step):
    """Run one orbit with l' held at ``dlength``; return (env states, reference states).

    ``physics_step`` None keeps the env's default.
    """
    n = n_bodies - 1
    dl = np.asarray(dlength, dtype=float)
    step = {} if physics_step is None else {"physics_step": physics_step}
    env = TetherLibrationEnv(n_bodies=n_bodies, accel_limit=None, max_reel_rate=1.0,
                             orbits_per_episode=1.0, action_mode="rate", **step)
    _, info = env.reset(seed=0, options={"dlength": dl})
    infos = [info]
    while True:
        _, _, terminated, truncated, info = env.step(dl)  # action = l'_cmd / max rate
        assert not terminated, info["failure"]
        infos.append(info)
        if truncated:
            break
    cfg = env.config
    chain = TetherChain(cfg.masses, cfg.eccentricity)
    zero = np.zeros(n)

    def rhs(nu, z):  # z = [theta, theta', l]; l' constant, l'' = 0
        ddtheta = chain.theta_ddot(nu, z[:n], z[n:2 * n], z[2 * n:], dl, zero)
        return np.concatenate([z[n:2 * n], ddtheta, dl])

    nus = np.array([i["nu"] for i in infos])
    z0 = np.concatenate([infos[0]["theta"], infos[0]["dtheta"], infos[0]["length"]])
    sol = solve_ivp(rhs, (nus[0], nus[-1]), z0, method="DOP853", rtol=1e-12, atol=1e-12,
                    t_eval=nus)
    assert sol.success
    states = np.array([np.concatenate([i["theta"], i["dtheta"], i["length"]]) for i in infos])
    # the reel law gives l'' = (cmd - l') / tau = 0 exactly: l' never changes
    assert all(np.array_equal(i["dlength"], dl) for i in infos)
    assert len(infos) == 1 + env.max_episode_steps
    return states, sol.y.T


@pytest.mark.parametrize(("n_bodies", "dlength"),
                         [(3, (0.02, -0.01)), (4, (0.02, -0.01, 0.005))])
def test_matches_independent_integration(n_bodies, dlength):
    """theta, theta', l at every step over one orbit agree with DOP853 to 1e-7.

    The env's RK4 error is h^4-limited. Measured largest deviations over one orbit
    (N=3 / N=4): 3.5e-9 / 1.1e-8 at physics_step 0.0025, 5.6e-8 / 1.7e-7 at 0.005 and
    2.1e-6 / 6.7e-6 at the default 0.0125. The 1e-7 check uses 0.0025; the 16x ratio
    per halving shows the difference is the fourth-order truncation error, not a
    modelling difference; the default step is checked against its own h^4 bound.
    """
    fine, ref = _env_and_reference(n_bodies, dlength, 0.0025)
    dev_fine = np.abs(fine - ref).max()
    assert dev_fine < 1e-7
    assert np.ptp(ref[:, :n_bodies - 1], axis=0).min() > 0.3  # a real libration, not rest
    coarse, _ = _env_and_reference(n_bodies, dlength, 0.005)
    dev_coarse = np.abs(coarse - ref).max()
    assert dev_coarse < 3e-7
    assert 12.0 < dev_coarse / dev_fine < 20.0  # 2^4 = 16
    default, _ = _env_and_reference(n_bodies, dlength, None)
    dev_default = np.abs(default - ref).max()
    assert dev_default < 1e-5
    assert 0.5 < dev_default / (dev_coarse * 2.5**4) < 1.5  # (0.0125 / 0.005)^4


# --------------------------------------------------------------------------- #
# episode end
# --------------------------------------------------------------------------- #
def _run_until_end(env, action, options=None, max_steps=400):
    env.reset(seed=0, options=options)
    for step in range(1, max_steps + 1):
        obs, reward, terminated, truncated, info = env.step(np.asarray(action, np.float32))
        assert np.all(np.isfinite(obs)) and math.isfinite(reward)
        assert REWARD_LOW <= reward <= REWARD_HIGH
        if terminated or truncated:
            return step, obs, reward, terminated, truncated, info
        assert info["failure"] is None
    raise AssertionError(f"no episode end in {max_steps} steps")


def _healthy_lengths(env, info):
    lo, hi = env.unwrapped.config.length_bounds
    return bool(np.all((info["length"] >= lo) & (info["length"] <= hi)))


def test_slack_terminates(make_env):
    # reeling out fast without an acceleration limit: the reels' l'' takes the tension
    env = make_env(accel_limit=None, max_reel_rate=1.0)
    step, _, _, terminated, truncated, info = _run_until_end(env, [1.0, 1.0])
    assert (step, terminated, truncated, info["failure"]) == (1, True, False, "slack")
    assert info["tension_min"].min() <= 0.0
    assert np.abs(info["theta"]).max() < 0.5 * math.pi and _healthy_lengths(env, info)
    with pytest.raises(Exception, match="reset"):  # OrderEnforcing/env: reset needed
        env.step(np.zeros(2, np.float32))


def test_tumble_terminates(make_env):
    env = make_env()
    step, _, _, terminated, truncated, info = _run_until_end(
        env, [0.0, 0.0], options={"theta": [1.4, 1.4], "dtheta": [3.0, 3.0]})
    assert (terminated, truncated, info["failure"]) == (True, False, "tumble")
    assert step <= 5
    assert np.abs(info["theta"]).max() >= 0.5 * math.pi
    assert info["tension_min"].min() > 0.0 and _healthy_lengths(env, info)


@pytest.mark.parametrize(("bounds", "action"), [((0.05, 0.55), 1.0), ((0.45, 1.5), -1.0)],
                         ids=["too-long", "too-short"])
def test_length_bound_terminates(make_env, bounds, action):
    env = make_env(length_bounds=bounds)  # default reel limits
    step, _, _, terminated, truncated, info = _run_until_end(env, [action, action])
    assert (terminated, truncated, info["failure"]) == (True, False, "length")
    assert 5 < step < 60
    assert not _healthy_lengths(env, info)
    assert info["tension_min"].min() > 0.0 and np.abs(info["theta"]).max() < 0.5 * math.pi


def test_nonfinite_state_terminates_with_finite_obs(make_env):
    env = make_env()
    obs0, _ = env.reset(seed=0)
    # force a NaN in the dynamics: the episode's eccentricity in the kernel parameters
    env.unwrapped._batch.par[0, PARAMS.slices(2)["eccentricity"]] = np.nan
    obs, reward, terminated, truncated, info = env.step(np.zeros(2, np.float32))
    assert (terminated, truncated, info["failure"]) == (True, False, "nonfinite")
    assert np.all(np.isfinite(obs)) and math.isfinite(reward)
    assert reward == REWARD_LOW  # documented: the reward is its lowest value
    # the last finite state is kept
    np.testing.assert_array_equal(obs[2:10], obs0[2:10])
    for key in ("theta", "dtheta", "length", "dlength", "tension", "tension_min"):
        assert np.all(np.isfinite(info[key])), key
    assert sum(info[k] for k in REWARD_COMPONENTS) == pytest.approx(reward, abs=1e-12)


@pytest.mark.parametrize("raw", [False, True], ids=["gym.make", "unwrapped-class"])
def test_truncates_exactly_at_registered_limit(make_env, raw):
    # through gym.make the TimeLimit (754) applies; the class alone truncates itself
    env = TetherLibrationEnv() if raw else make_env()
    env.reset(seed=0)
    zero = np.zeros(2, np.float32)
    for step in range(1, 754):
        _, _, terminated, truncated, info = env.step(zero)
        assert not terminated and not truncated, (step, info["failure"])
    _, _, terminated, truncated, info = env.step(zero)
    assert truncated and not terminated and info["failure"] is None
    assert info["nu"] == pytest.approx(754 * 0.025, abs=1e-9)


@pytest.mark.parametrize("nu0", [0.0, 1.0])
def test_env_truncates_itself(make_env, nu0):
    expected = math.ceil(0.1 * 2 * math.pi / 0.025)  # 26
    for env in (make_env(orbits_per_episode=0.1), TetherLibrationEnv(orbits_per_episode=0.1)):
        env.reset(seed=0, options={"nu": nu0})
        for step in range(1, expected + 1):
            _, _, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
            assert not terminated
            assert truncated == (step == expected), step
        with pytest.raises(Exception, match="reset"):
            env.step(np.zeros(2, np.float32))


# --------------------------------------------------------------------------- #
# input validation
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize(("options", "exc", "match"), [
    ({"foo": 1.0}, ValueError, r"unknown reset option\(s\) \['foo'\]; valid keys"),
    ({"theta": [0.1]}, ValueError, r"options\['theta'\]=\[0\.1\] must have shape \(2,\)"),
    ({"nu": [0.0, 1.0]}, ValueError, r"options\['nu'\]=\[0\.0, 1\.0\] must be a scalar"),
    ({"length": [np.nan, 0.5]}, ValueError, r"options\['length'\]=\[nan, 0\.5\] must be finite"),
    ({"dtheta": [np.inf, 0.0]}, ValueError, r"options\['dtheta'\]=\[inf, 0\.0\] must be finite"),
    ({"theta": [1.6, 0.0]}, ValueError, r"options\['theta'\]=\[1\.6, 0\.0\] must lie in"),
    ({"length": [0.0, 0.5]}, ValueError,
     r"options\['length'\]=\[0\.0, 0\.5\] must lie inside length_bounds"),
    ([("nu", 0.0)], TypeError, r"options must be a dict or None, got list"),
])
def test_bad_options_raise(make_env, options, exc, match):
    env = make_env().unwrapped
    with pytest.raises(exc, match=match):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize(("action", "match"), [
    ([np.nan, 0.0], r"action=.*nan.* must be finite"),
    ([np.inf, 0.0], r"action=.*inf.* must be finite"),
    ([0.0, 0.0, 0.0], r"action must have shape \(2,\), got \(3,\)"),
    (0.5, r"action must have shape \(2,\), got \(\)"),
])
def test_bad_actions_raise(make_env, action, match):
    env = make_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(action)


def test_step_before_reset_raises():
    env = TetherLibrationEnv()
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        env.step(np.zeros(2, np.float32))


# --------------------------------------------------------------------------- #
# info, reward, observation
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("kwargs", [{}, {**RANDOMISED, "n_bodies": 4}], ids=["default", "rand-N4"])
def test_info_keys_and_reward_components(make_env, kwargs):
    env = make_env(**kwargs)
    env.action_space.seed(5)
    _, info = env.reset(seed=5)
    assert set(INFO_KEYS) <= info.keys()
    assert info["failure"] is None
    rewards = []
    for _ in range(200):
        _, reward, terminated, truncated, info = env.step(0.3 * env.action_space.sample())
        assert set(INFO_KEYS) <= info.keys()
        assert REWARD_LOW <= reward <= REWARD_HIGH
        assert reward == pytest.approx(sum(info[k] for k in REWARD_COMPONENTS), abs=1e-12)
        assert info["reward_tracking"] >= 0.0
        assert info["reward_effort"] <= 0.0 and info["reward_accel"] <= 0.0
        assert 0.0 <= info["reward_slack"] <= 0.2 and 0.0 <= info["reward_length"] <= 0.2
        assert (info["failure"] is None) == (not terminated)
        rewards.append(reward)
        if terminated or truncated:
            break
    assert np.ptp(rewards) > 0.01  # the reward actually responds


def test_tracking_reward_prefers_the_reference(make_env):
    """On the reference (theta = theta_d, theta' = theta_d') tracking is perfect."""
    env = make_env()
    _, info = env.reset(seed=0, options={"theta": [0.0, 0.0], "dtheta": [0.2, 0.2]})
    _, reward_on, _, _, info_on = env.step(np.zeros(2, np.float32))
    _, info = env.reset(seed=0, options={"theta": [0.3, -0.3], "dtheta": [0.2, 0.2]})
    _, reward_off, _, _, info_off = env.step(np.zeros(2, np.float32))
    # (1 - W) r_track with W = 0.4: 0.6 at perfect tracking
    assert info_on["reward_tracking"] > 0.9 * 0.6 > 0.2 * 0.6 > info_off["reward_tracking"]
    assert reward_on > reward_off


def _documented_layout(n: int, obs_dim: int) -> list[tuple[str, range]]:
    """Parse the Observation Space table of the env docstring into (label, indices)."""
    doc = TetherLibrationEnv.__doc__
    table = doc[doc.index("## Observation Space"):doc.index("## Rewards")]

    def value(expr):  # "4n+5", "n+1", "2"
        m = re.fullmatch(r"(?:(\d*)n)?\+?(\d*)", expr.replace(" ", ""))
        coef = (int(m.group(1)) if m.group(1) else 1) if "n" in expr else 0
        return coef * n + (int(m.group(2)) if m.group(2) else 0)

    rows = []
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] in ("Index", "") or set(cells[0]) <= {"-"}:
            continue
        spec = re.sub(r"\(.*?\)", "", cells[0]).strip()
        if "," in spec:
            idx = [value(s) for s in spec.split(",")]
        elif ".." in spec:
            lo, hi = (s.strip() for s in spec.split(".."))
            idx = list(range(value(lo), (value(hi) if hi else obs_dim - 1) + 1))
        else:
            idx = [value(spec)]
        rows.append((cells[1], idx))
    return rows


@pytest.mark.parametrize("n_bodies", [3, 4])
def test_observation_layout_matches_docstring(make_env, n_bodies):
    n = n_bodies - 1
    env = make_env(n_bodies=n_bodies, eccentricity_range=(0.1, 0.3), mass_range=0.2)
    obs, info = env.reset(seed=11, options={"nu": 0.7, "dlength": [0.01] * n})
    for _ in range(3):
        obs, _, _, _, info = env.step(np.full(n, 0.1, np.float32))
    rows = _documented_layout(n, obs.shape[0])
    assert obs.shape[0] == 8 * n + 4 + n_bodies  # "8(N-1) + 4 (+ N when randomised)"
    covered = sorted(i for _, idx in rows for i in idx)
    assert covered == list(range(obs.shape[0]))  # the table covers every entry once
    nu = info["nu"]
    expected = {
        "sin(nu)": [math.sin(nu)], "cos(nu)": [math.cos(nu)],
        "theta_i": info["theta"], "theta_i'": info["dtheta"],
        "l_i": info["length"], "l_i' (actual reel rates)": info["dlength"],
        "theta_d (reference)": [info["theta_ref"]], "theta_d'": [info["dtheta_ref"]],
        "e_i = theta_i - theta_d": info["theta"] - info["theta_ref"],
        "e_i' = theta_i' - theta_d'": info["dtheta"] - info["dtheta_ref"],
        "ln(l_i / l_i,nom)": np.log(info["length"] / np.asarray(
            env.unwrapped.config.initial_lengths)),
        "u_i, the normalised reel-rate command": info["command"],
        "eccentricity e": [info["eccentricity"]],
    }
    labels = []
    for label, idx in rows:
        key = next((k for k in expected if label.startswith(k) and
                    (k != "theta_i" or not label.startswith("theta_i'"))
                    and (k != "l_i" or not label.startswith("l_i'"))), None)
        labels.append(key or label)
        if key is None:
            assert label.startswith("mass fractions M_i"), label
            masses = obs[idx]
            assert masses.sum() == pytest.approx(1.0, abs=1e-6) and np.all(masses > 0)
            continue
        np.testing.assert_allclose(obs[idx], expected[key], rtol=0, atol=1e-6, err_msg=label)
    assert len(labels) == 14 and labels[-1].startswith("mass fractions")
    # the masses are drawn within (1 +- 0.2) m_i: the fractions' ratios are bounded
    nominal = np.asarray(env.unwrapped.config.masses)
    ratio = obs[8 * n + 5:] / (nominal / nominal.sum())
    assert ratio.max() / ratio.min() <= 1.2 / 0.8 + 1e-6
    assert not np.allclose(ratio, 1.0, atol=1e-3)  # drawn, not nominal


def test_observing_the_eccentricity_alone_appends_e_and_changes_nothing_else(make_env):
    """observe_params="eccentricity": the unobserved observation plus the episode's e."""
    kwargs = {"eccentricity_range": (0.0, 0.35), "mass_range": 0.25, "init_theta_range": 0.1}
    blind = make_env(observe_params=False, **kwargs)
    seeing = make_env(observe_params="eccentricity", **kwargs)
    assert seeing.observation_space.shape == (blind.observation_space.shape[0] + 1,)
    obs_b, _ = blind.reset(seed=4)
    obs_s, info = seeing.reset(seed=4)
    for step in range(20):
        np.testing.assert_array_equal(obs_s[:-1], obs_b)
        assert obs_s[-1] == np.float32(info["eccentricity"])
        assert 0.0 <= info["eccentricity"] <= 0.35
        action = np.full(2, 0.3 * math.sin(step), np.float32)
        obs_b, reward_b, *_ = blind.step(action)
        obs_s, reward_s, _, _, info = seeing.step(action)
        assert reward_s == reward_b


@pytest.mark.parametrize("obs_noise", [0.0, 1e-3])
def test_obs_bias_offsets_the_observed_angles_only(make_env, obs_noise):
    """obs_bias b: observed theta_i and e_i are b above the unbiased env's, nothing else
    (info, reward, termination, the other entries) changes."""
    from tether_gym.envs.layout import OBSERVATION

    kwargs = {"init_theta_range": 0.1, "obs_noise": obs_noise}
    plain, biased = make_env(**kwargs), make_env(obs_bias=0.02, **kwargs)
    sl = OBSERVATION.slices(2)
    shifted = np.zeros(plain.observation_space.shape, bool)
    shifted[sl["theta"]] = shifted[sl["error"]] = True
    obs_p, info_p = plain.reset(seed=7)
    obs_b, info_b = biased.reset(seed=7)
    for step in range(30):
        diff = obs_b.astype(float) - obs_p.astype(float)
        np.testing.assert_allclose(diff[shifted], 0.02, atol=1e-6)  # float32 rounding
        np.testing.assert_array_equal(obs_b[~shifted], obs_p[~shifted])
        np.testing.assert_array_equal(info_b["theta"], info_p["theta"])
        action = np.full(2, 0.3 * math.sin(step), np.float32)
        obs_p, r_p, term_p, _, info_p = plain.step(action)
        obs_b, r_b, term_b, _, info_b = biased.step(action)
        assert (r_b, term_b) == (r_p, term_p)
    with pytest.raises(ValueError, match="obs_bias"):
        make_env(obs_bias=0.6)


@pytest.mark.parametrize("kwargs", [{}, {"n_bodies": 4, "init_theta_range": 0.1,
                                         "gravity": "full", "speed_limit": 3.0}])
def test_env_step_is_the_public_transition(make_env, kwargs):
    """One env step is tether_gym.physics.transition of the reset state, bit for bit."""
    from tether_gym.physics import STATE, transition

    env = make_env(**kwargs)
    cfg = env.unwrapped.config
    _, info = env.reset(seed=3)
    state = np.concatenate([info[name] for name in STATE.names])
    params = cfg.param_rows(cfg.eccentricity, cfg.masses)
    action = np.linspace(-1.3, 0.7, cfg.n_tethers).astype(np.float32)
    expected = transition(info["nu"], state,
                          np.clip(action.astype(np.float64), -1.0, 1.0) * cfg.max_reel_rate,
                          params, cfg.physics_step, cfg.n_substeps)
    _, _, _, _, info = env.step(action)
    assert info["nu"] == expected.nu
    got = np.concatenate([info[name] for name in STATE.names])
    assert got.tobytes() == expected.state.tobytes()
    assert info["tension"].tobytes() == expected.tension.tobytes()
    assert info["tension_min"].tobytes() == expected.tension_min.tobytes()
    assert info["ddlength"].tobytes() == expected.derivative[STATE.slices(
        cfg.n_tethers)["dlength"]].tobytes()


# --------------------------------------------------------------------------- #
# action modes (v1)
# --------------------------------------------------------------------------- #
def test_increment_mode_integrates_the_command(make_env):
    """u <- clip(u + 0.25 a, -1, 1), starting from the reels' rate l' / max_reel_rate."""
    env = make_env()
    assert env.unwrapped.config.action_mode == "increment"
    _, info = env.reset(seed=0, options={"dlength": [0.1, -0.6]})
    u = np.clip(np.array([0.1, -0.6]) / 0.5, -1, 1)
    np.testing.assert_array_equal(info["command"], u)
    rng = np.random.default_rng(3)
    for _ in range(40):
        a = rng.uniform(-1.5, 1.5, 2).astype(np.float32)  # outside the box: clipped first
        obs, _, terminated, _, info = env.step(a)
        u = np.clip(u + 0.25 * np.clip(a.astype(float), -1, 1), -1, 1)
        np.testing.assert_array_equal(info["command"], u)
        np.testing.assert_array_equal(obs[-2:], u.astype(np.float32))
        assert not terminated


def test_modes_share_the_physics(make_env):
    """The same commands give bit-identical states in both modes."""
    inc = make_env(init_theta_range=0.1)
    rate = make_env(init_theta_range=0.1, action_mode="rate")
    _, i_inc = inc.reset(seed=4)
    _, i_rate = rate.reset(seed=4)
    u = np.array(i_inc["command"])
    rng = np.random.default_rng(0)
    for _ in range(100):
        a = rng.uniform(-0.2, 0.2, 2)
        target = np.clip(u + 0.25 * a, -1, 1)
        _, r_inc, _, _, i_inc = inc.step(a)
        _, r_rate, _, _, i_rate = rate.step(target)
        u = target
        for key in ("theta", "dtheta", "length", "dlength", "tension", "command"):
            np.testing.assert_array_equal(i_inc[key], i_rate[key], err_msg=key)
        assert r_inc == r_rate


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"action_mode": "delta"}, "action_mode='delta' must be one of"),
    ({"action_mode": 1}, "action_mode=1 must be one of"),
    ({"increment_gain": 0.0}, "increment_gain"),
    ({"increment_gain": 3.0}, "increment_gain"),
])
def test_action_arguments_validated(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TetherLibrationEnv(**kwargs)
