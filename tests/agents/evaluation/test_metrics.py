"""Episode metrics on synthetic trajectories with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_gym_agents.evaluation.metrics import (
    HIGHER_IS_BETTER,
    LOWER_IS_BETTER,
    METRICS,
    convergence_orbits,
    episode_metrics,
)
from tether_gym_agents.evaluation.rollout import Trajectory

STEP = 0.025


def _trajectory(error_of_orbit, steps=754, failure=None, dl=0.01, reward=1.0):
    """Reset row (nu = 0) plus ``steps`` step rows, two tethers."""
    k = np.arange(steps + 1)
    nu = k * STEP
    err = np.array([error_of_orbit(x) for x in nu / (2 * math.pi)])
    theta = np.stack([0.1 + err, 0.1 - err], axis=1)
    dlength = np.stack([dl * (-1.0) ** k, np.zeros_like(nu)], axis=1)
    dlength[0] = 0.0
    length = np.stack([0.5 + 1e-3 * k, np.full_like(nu, 0.5)], axis=1)
    tension_min = np.stack([np.ones_like(nu), 0.5 + k * 1e-4], axis=1)
    tension_min[0] = 0.1  # the reset row is not a step: it must not count
    action = np.zeros((steps, 2))
    return Trajectory(nu=nu, theta=theta, dtheta=np.zeros_like(theta), length=length,
                      dlength=dlength, tension=tension_min.copy(), tension_min=tension_min,
                      theta_ref=np.full_like(nu, 0.1), reel_accel=np.zeros_like(theta),
                      action=action, command=action.copy(), reward=np.full(steps, reward),
                      failure=failure, truncated=failure is None,
                      settings={"control_step": STEP})


def test_every_metric_says_which_way_is_better():
    """The probability of improvement reads HIGHER_IS_BETTER: a new metric missing from
    both sets would silently count the worse policy as the better one."""
    assert not HIGHER_IS_BETTER & LOWER_IS_BETTER
    assert HIGHER_IS_BETTER | LOWER_IS_BETTER == set(METRICS)


def test_metrics_of_a_known_episode():
    traj = _trajectory(lambda orbit: 0.1 * math.exp(-10 * orbit))
    m = episode_metrics(traj)
    assert set(m) == set(METRICS)
    nu = traj.nu[1:]
    after = nu > 2 * math.pi
    err = 0.1 * np.exp(-10 * nu[after] / (2 * math.pi))
    assert m["tracking_rms"] == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-12)
    # 0.1 exp(-10 t) < 1e-3 from t = ln(100) / 10 orbits on, at the next sample
    first = nu[np.argmax(0.1 * np.exp(-10 * nu / (2 * math.pi)) < 1e-3)] / (2 * math.pi)
    assert m["converge_orbits"] == pytest.approx(first) and first > math.log(100) / 10
    assert m["reel_effort"] == pytest.approx(0.01 * 754 * STEP)
    assert m["chattering"] == pytest.approx(0.02 * 753)
    assert m["reel_excursion"] == pytest.approx(1e-3 * 753)
    assert m["min_tension"] == pytest.approx(0.5001)
    assert m["success"] == 1.0 and m["slack"] == m["tumble"] == m["length"] == 0.0
    assert m["return"] == 754.0
    # last orbit: nu > nu_K - 2 pi
    last = nu > nu[-1] - 2 * math.pi
    assert m["final_error"] == pytest.approx(0.2 * math.exp(-10 * nu[last][0] / (2 * math.pi))
                                             / 2)


def test_failed_episode():
    m = episode_metrics(_trajectory(lambda orbit: 0.05, steps=100, failure="slack",
                                    reward=0.5))
    assert m["slack"] == 1.0 and m["success"] == 0.0
    assert math.isnan(m["tracking_rms"]) and math.isnan(m["converge_orbits"])
    assert m["return"] == 50.0


def test_convergence_definition():
    t = np.linspace(0, 1, 11)
    assert convergence_orbits(t, [1, 1, 1, 0, 0, 1, 0, 0, 0, 0, 0]) == pytest.approx(0.6)
    assert convergence_orbits(t, np.zeros(11)) == 0.0
    assert convergence_orbits(t, [0] * 10 + [1]) is None
