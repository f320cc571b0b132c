"""SafetyFilter: the projection meets the constraints, is the closest safe command and
leaves safe commands alone (checked against a brute-force grid over the command box)."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.physics import STATE, transition
from tether_gym.safety import DEFAULT_MARGIN, SafetyFilter

N = 2
GRID = np.linspace(-1.0, 1.0, 41)
CANDIDATES = np.array([(a, b) for a in GRID for b in GRID])  # (1681, 2), spacing 0.05


@pytest.fixture(scope="module")
def env():
    e = gym.make(tether_gym.ENV_ID)
    yield e
    e.close()


@pytest.fixture(scope="module")
def filt(env):
    return SafetyFilter.for_env(env)


def _states(rng, count):
    """States from calm to near-failure: short tethers reeling in, fast librations."""
    y = np.empty((count, STATE.size(N)))
    sl = STATE.slices(N)
    y[:, sl["theta"]] = rng.uniform(-0.5, 0.5, (count, N))
    y[:, sl["dtheta"]] = rng.uniform(-0.8, 1.2, (count, N))
    y[:, sl["length"]] = rng.uniform(0.07, 1.2, (count, N))
    y[:, sl["dlength"]] = rng.uniform(-0.5, 0.5, (count, N))
    return rng.uniform(0.0, 2.0 * math.pi, count), y


def _constraints(filt, env, nu, y, cmd):
    """Independent check of the constraints: (tension_min (R, n), length slack (R,))."""
    cfg = env.unwrapped.config
    par = cfg.param_rows(cfg.eccentricity, cfg.masses)
    out = transition(nu, y, cmd * cfg.max_reel_rate, par, cfg.physics_step, cfg.n_substeps)
    sl = STATE.slices(N)
    k = 1.0 + cfg.eccentricity * np.cos(out.nu)
    v = k[:, None] ** 2 * out.state[:, sl["dlength"]]
    stop = out.state[:, sl["length"]] + np.sign(v) * v**2 / (2.0 * filt.accel_bound)
    lo = cfg.length_bounds[0] + filt.length_margin
    hi = cfg.length_bounds[1] - filt.length_margin
    return out.tension_min, np.minimum(stop - lo, hi - stop).min(axis=1)


def _grid_truth(filt, env, nu, y):
    """Per state: feasible mask over CANDIDATES (brute force)."""
    c = len(CANDIDATES)
    tmin, lslack = _constraints(filt, env, np.repeat(nu, c), np.repeat(y[None], c, axis=0),
                                CANDIDATES)
    return (tmin.min(axis=1) >= filt.margin) & (lslack >= 0.0)


@pytest.fixture(scope="module")
def cases(filt, env):
    rng = np.random.default_rng(12)
    nu, y = _states(rng, 150)
    desired = rng.uniform(-1.0, 1.0, (150, N))
    res = filt.project(nu, y, desired)
    return nu, y, desired, res


def test_margins_come_from_the_task(env, filt):
    cfg = env.unwrapped.config
    assert filt.margin == cfg.reward_weights.safe_tension == DEFAULT_MARGIN
    assert filt.length_margin == pytest.approx(cfg.max_reel_rate * cfg.control_step)


def test_the_sample_exercises_every_case(cases):
    _, _, _, res = cases
    assert 10 <= res.active.sum() <= 140
    assert (res.active & res.feasible).sum() >= 10


@pytest.mark.parametrize("sample", ["cases", "harsh"])
def test_never_below_the_margin_when_a_safe_command_exists(filt, env, sample, request):
    nu, y, desired, res = request.getfixturevalue(sample)
    for b in range(len(nu)):
        if not _grid_truth(filt, env, nu[b], y[b]).any():
            continue
        assert res.feasible[b], f"state {b}: the grid has a safe command, the filter none"
        tmin, lslack = _constraints(filt, env, nu[b:b + 1], y[b:b + 1], res.command[b:b + 1])
        assert tmin.min() >= filt.margin and lslack[0] >= 0.0
        np.testing.assert_allclose(res.tension_min[b], tmin[0], rtol=0, atol=0)


def test_the_projection_is_the_closest_safe_command(filt, env, cases):
    nu, y, desired, res = cases
    checked = 0
    for b in np.flatnonzero(res.active & res.feasible):
        ok = _grid_truth(filt, env, nu[b], y[b])
        if not ok.any():
            continue
        best = np.sqrt(((CANDIDATES[ok] - desired[b]) ** 2).sum(axis=1)).min()
        # the grid's best is feasible, so the filter's answer is no farther (up to the
        # filter's own resolution, ~1e-4)
        assert res.correction[b] <= best + 1e-3, (b, res.correction[b], best)
        checked += 1
    assert checked >= 10


def test_safe_commands_pass_bit_for_bit(filt, cases):
    nu, y, desired, res = cases
    keep = ~res.active
    assert np.array_equal(res.command[keep], desired[keep])
    assert np.all(res.correction[keep] == 0.0) and np.all(res.feasible[keep])
    again = filt.project(nu[keep], y[keep], desired[keep])
    assert not again.active.any() and np.array_equal(again.command, desired[keep])


def test_correction_and_box(cases):
    _, _, desired, res = cases
    assert np.all(np.abs(res.command) <= 1.0)
    np.testing.assert_allclose(res.correction,
                               np.linalg.norm(res.command - desired, axis=1), rtol=0, atol=0)
    assert np.all(np.isfinite(res.command)) and np.all(np.isfinite(res.correction))


@pytest.fixture(scope="module")
def harsh(filt):
    """Large angles and tethers rotating backwards (theta' < -0.4): low tension."""
    rng = np.random.default_rng(5)
    count = 60
    nu, y = _states(rng, count)
    sl = STATE.slices(N)
    y[:, sl["theta"]] = rng.uniform(-1.0, 1.0, (count, N))
    y[:, sl["dtheta"]] = rng.uniform(-1.6, -0.4, (count, N))
    desired = rng.uniform(-1.0, 1.0, (count, N))
    return nu, y, desired, filt.project(nu, y, desired)


def test_infeasible_rows_are_the_best_effort(filt, env, harsh):
    """No safe command: flagged, and the worst predicted tension is (up to the local
    search's shortfall, < 0.01 here) the largest any grid command in the length box keeps."""
    nu, y, desired, res = harsh
    checked = 0
    for b in np.flatnonzero(~res.feasible):
        assert res.active[b] or not np.any(res.command[b] != desired[b])
        c = len(CANDIDATES)
        tmin, lslack = _constraints(filt, env, np.repeat(nu[b], c),
                                    np.repeat(y[b:b + 1], c, axis=0), CANDIDATES)
        assert not ((tmin.min(axis=1) >= filt.margin) & (lslack >= 0.0)).any()
        inside = lslack >= 0.0
        if inside.any():
            assert res.tension_min[b].min() >= tmin[inside].min(axis=1).max() - 0.01
            checked += 1
    assert checked >= 3


def test_batch_rows_do_not_interact(filt, cases):
    nu, y, desired, res = cases
    for b in (0, 7, 33):
        one = filt.project(nu[b:b + 1], y[b:b + 1], desired[b:b + 1])
        assert np.array_equal(one.command[0], res.command[b])


def test_desired_commands_outside_the_box_are_clipped_first(filt, cases):
    nu, y, desired, res = cases
    b = int(np.flatnonzero(~res.active)[0])
    wide = desired[b:b + 1] * 3.0
    out = filt.project(nu[b:b + 1], y[b:b + 1], wide)
    assert np.all(np.abs(out.command) <= 1.0)


@pytest.mark.parametrize("bad, match", [
    (dict(command=np.full((1, N), np.nan)), "command"),
    (dict(command=np.zeros((1, 3))), "shape"),
    (dict(nu=np.inf), "nu"),
    (dict(state=np.zeros((1, 5))), "shape"),
])
def test_bad_inputs_raise(filt, cases, bad, match):
    nu, y, desired, _ = cases
    kwargs = dict(nu=nu[0], state=y[:1], command=desired[:1]) | bad
    with pytest.raises(ValueError, match=match):
        filt.project(**kwargs)


@pytest.mark.parametrize("kwargs, match", [
    (dict(margin=0.0), "margin"), (dict(margin=math.nan), "margin"),
    (dict(length_margin=-0.1), "length_margin"), (dict(length_margin=1.0), "length_margin"),
])
def test_bad_margins_raise(env, kwargs, match):
    with pytest.raises(ValueError, match=match):
        SafetyFilter.for_env(env, **kwargs)


def test_a_chain_the_search_cannot_afford_is_refused_when_the_filter_is_built():
    """Before: n_bodies = 12 took more than a minute per filtered step, and n_bodies = 20
    built 3^19 search directions (the line alone, under a 4 GB limit: a MemoryError
    after 11 s; about 240 GB of tuples in all)."""
    from tether_gym.safety import MAX_TETHERS
    from tether_gym.wrappers import SafetyFilterWrapper

    assert MAX_TETHERS == 9
    SafetyFilterWrapper(gym.make(tether_gym.ENV_ID, action_mode="rate", n_bodies=10))
    for n_bodies in (11, 20):
        env = gym.make(tether_gym.ENV_ID, action_mode="rate", n_bodies=n_bodies)
        with pytest.raises(ValueError, match=rf"n_tethers={n_bodies - 1} must be at most 9 "
                                             r"\(n_bodies <= 10\)"):
            SafetyFilterWrapper(env)


def test_substeps_beyond_the_envs_are_refused(env):
    """Before: substeps=10**9 made each prediction run 10**9 RK4 steps: about two days per
    filtered step (1.8 s measured at 10,000, growing linearly)."""
    good = SafetyFilter.for_env(env)
    kwargs = dict(params=good.par[0], n_tethers=good.n, max_reel_rate=good.max_reel_rate,
                  physics_step=good.physics_step, length_bounds=good.length_bounds)
    SafetyFilter(substeps=10_000, **kwargs)
    with pytest.raises(ValueError, match=r"substeps=1000000000 must be at most 10000"):
        SafetyFilter(substeps=10**9, **kwargs)


@pytest.mark.parametrize("name, value", [
    ("params", "abc"), ("params", [None] * 3), ("length_bounds", "ab"),
    ("length_bounds", (0.1, "x")), ("length_bounds", 0.5)])
def test_bad_constructor_values_name_the_argument(env, name, value):
    """numpy's "could not convert string to float" named nothing (issue 24)."""
    good = SafetyFilter.for_env(env)
    kwargs = dict(params=good.par[0], n_tethers=good.n, max_reel_rate=good.max_reel_rate,
                  physics_step=good.physics_step, substeps=good.substeps,
                  length_bounds=good.length_bounds) | {name: value}
    with pytest.raises((TypeError, ValueError)) as err:
        SafetyFilter(**kwargs)
    message = str(err.value)
    assert message.startswith(f"{name}={value!r}") and "must" in message, message


@pytest.mark.parametrize("name", ["nu", "state", "command"])
def test_bad_project_values_name_the_argument(filt, cases, name):
    nu, y, desired, _ = cases
    kwargs = dict(nu=nu[0], state=y[:1], command=desired[:1]) | {name: "abc"}
    with pytest.raises(TypeError, match=rf"^{name}='abc' must"):
        filt.project(**kwargs)


# --------------------------------------------------------------------------- #
# the warning of an infeasible command (FilterInTheLoop, tether_gym.wrappers)
def test_an_infeasible_command_is_warned_of_once_per_process_with_the_filter(env, monkeypatch):
    """Two loops of the same filter settings, a library's catch_warnings between them (it
    resets Python's once-per-location registry, as in the main job): one warning, naming
    the filter and what it did."""
    from tether_gym import wrappers

    monkeypatch.setattr(wrappers, "_WARNED", set())
    # theta = 1.4 rad, theta' = -1: T^ < 0 for every command (tests/test_wrappers.py)
    y = np.array([[1.4, 1.4, -1.0, -1.0, 0.5, 0.5, 0.0, 0.0]])
    nu, desired = np.zeros(1), np.zeros((1, N))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")
        first = wrappers.FilterInTheLoop(SafetyFilter.for_env(env), N)
        first((nu, y), desired)
        with warnings.catch_warnings():
            pass
        second = wrappers.FilterInTheLoop(SafetyFilter.for_env(env), N)
        second((nu, y), desired)
    assert (first.infeasible, second.infeasible) == (1, 1)  # both counted
    assert len(caught) == 1, [str(w.message) for w in caught]
    (warning,) = caught
    assert issubclass(warning.category, wrappers.InfeasibleCommandWarning)
    assert issubclass(warning.category, UserWarning)
    text = str(warning.message)
    assert text.startswith(f"tether_gym safety filter {first.safety_filter!r}: 1 of the 1 ")
    assert wrappers.INFEASIBLE_WARNING in text and "filter_feasible" in text
    # other settings are news: warned of again
    with pytest.warns(wrappers.InfeasibleCommandWarning, match="margin=0.7"):
        wrappers.FilterInTheLoop(SafetyFilter.for_env(env, margin=0.7), N)((nu, y), desired)
