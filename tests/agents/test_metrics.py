"""Episode metrics and their aggregation, on synthetic episodes with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from tether_gym_agents.metrics import aggregate, convergence_orbits, episode_metrics

STEP = 0.025


def _episode(error_of_orbit, steps=754, failure=None, dl=0.01):
    infos = []
    for k in range(1, steps + 1):
        nu = k * STEP
        err = error_of_orbit(nu / (2 * math.pi))
        infos.append({"nu": nu, "theta": np.array([0.1 + err, 0.1 - err]), "theta_ref": 0.1,
                      "dlength": np.array([dl * (-1) ** k, 0.0]),
                      "length": np.array([0.5 + 1e-3 * k, 0.5]),
                      "tension_min": np.array([1.0, 0.5 + k * 1e-4]),
                      "failure": failure if k == steps else None})
    return infos


def test_metrics_of_a_known_episode():
    infos = _episode(lambda orbit: 0.1 * math.exp(-10 * orbit))
    m = episode_metrics(infos, [1.0] * len(infos), 0.0, STEP, truncated=True)
    nu = np.array([i["nu"] for i in infos])
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


def test_failed_episode():
    infos = _episode(lambda orbit: 0.05, steps=100, failure="slack")
    m = episode_metrics(infos, [0.5] * 100, 0.0, STEP, truncated=False)
    assert m["slack"] == 1.0 and m["success"] == 0.0
    assert math.isnan(m["tracking_rms"]) and math.isnan(m["converge_orbits"])


def test_convergence_definition():
    t = np.linspace(0, 1, 11)
    assert convergence_orbits(t, [1, 1, 1, 0, 0, 1, 0, 0, 0, 0, 0]) == pytest.approx(0.6)
    assert convergence_orbits(t, np.zeros(11)) == 0.0
    assert convergence_orbits(t, [0] * 10 + [1]) is None


def test_aggregate_mean_and_student_t_interval():
    values = [0.1, 0.2, 0.4, math.nan]
    episodes = [{k: 0.0 for k in ("final_error", "converge_orbits", "reel_effort",
                                  "reel_excursion", "min_tension", "slack", "tumble",
                                  "length", "success", "chattering", "return")}
                | {"tracking_rms": v} for v in values]
    agg = aggregate(episodes)
    finite = np.array(values[:3])
    assert agg["tracking_rms"] == pytest.approx(finite.mean())
    assert agg["tracking_rms_n"] == 3
    half = stats.t.ppf(0.975, 2) * finite.std(ddof=1) / math.sqrt(3)
    assert agg["tracking_rms_ci95"] == pytest.approx(half)
    assert agg["success"] == 0.0 and agg["success_ci95"] == 0.0
