"""The reward: bounds, components, each term's formula, weight validation."""

from __future__ import annotations

import numpy as np
import pytest

from tether_gym.tasks.reward import (
    COMPONENTS,
    PENALTIES,
    RewardWeights,
    penalty_terms,
    reward_terms,
)


def _reward(theta=(0.2, 0.2), dtheta=(0.3, 0.3), length=(0.5, 0.5), ref=0.2, dref=0.3,
            action=(0.0, 0.0), accel=(0.0, 0.0), tension=(2.0, 2.0), nominal=(0.5, 0.5),
            weights=None):
    out = np.empty(len(COMPONENTS))
    params = (weights or RewardWeights()).record()
    y = np.concatenate([theta, dtheta, length, np.zeros(len(theta))]).astype(float)
    n = len(theta)
    raw = np.empty(len(PENALTIES))
    penalty_terms(y, n, *(np.asarray(x, dtype=float) for x in (action, accel, tension, nominal)),
                  params, raw)
    r = reward_terms(y, n, ref, dref, params, raw, out)
    return r, dict(zip(COMPONENTS, out, strict=True))


def test_perfect_tracking_without_penalties_scores_one():
    r, comp = _reward()
    assert r == 1.0 and comp["reward_tracking"] == 1.0
    assert all(comp[k] == 0.0 for k in COMPONENTS[1:])


def test_tracking_term_formula():
    """r_track = 1 / (1 + c / sigma^2), c = mean e^2 + 0.1 mean e'^2: an RMS of sigma halves it."""
    r, comp = _reward(theta=(0.25, 0.15))  # errors +-0.05 = sigma
    assert comp["reward_tracking"] == pytest.approx(0.5, abs=1e-15)
    r, comp = _reward(dtheta=(0.3 + 0.05 / np.sqrt(0.1), 0.3 - 0.05 / np.sqrt(0.1)))
    assert comp["reward_tracking"] == pytest.approx(0.5, abs=1e-12)


@pytest.mark.parametrize(("kwargs", "key", "term"), [
    ({"action": (1.0, 0.0)}, "reward_effort", 0.05 * 0.5),
    ({"accel": (3.0, 0.5)}, "reward_accel", 0.05 * (1.0 + 0.25) / 2),
    ({"tension": (0.25, -1.0)}, "reward_slack", 0.2 * (0.25 + 1.0) / 2),
    ({"length": (0.75, 1.5)}, "reward_length", 0.2 * (0.25 + 1.0) / 2),  # saturates at 1
])
def test_each_penalty(kwargs, key, term):
    r, comp = _reward(**kwargs)
    assert comp[key] == pytest.approx(-term, abs=1e-15)
    assert r == pytest.approx(1.0 - term, abs=1e-15)


def test_bounds_at_the_extremes():
    rng = np.random.default_rng(0)
    for _ in range(2000):
        r, comp = _reward(theta=rng.normal(0, 1, 2), dtheta=rng.normal(0, 3, 2),
                          length=rng.uniform(0, 3, 2), action=rng.uniform(-1, 1, 2),
                          accel=rng.normal(0, 5, 2), tension=rng.normal(0, 2, 2))
        assert 0.0 <= r <= 1.0
        assert r == pytest.approx(sum(comp.values()), abs=1e-14)
    worst, _ = _reward(theta=(0.2, 0.2), action=(1, 1), accel=(9, 9), tension=(-1, -1),
                       length=(2, 2))
    assert worst == pytest.approx(1.0 - 0.5, abs=1e-15)  # all penalties saturated


def test_weights_validated():
    with pytest.raises(ValueError, match="must be <= 1"):
        RewardWeights(slack=0.5, length=0.5, effort=0.1)  # 1.2 with accel 0.05
    with pytest.raises(ValueError, match="sigma"):
        RewardWeights(sigma=0.0)
    with pytest.raises(ValueError, match="unknown reward_weights keys.*'slak'"):
        RewardWeights.from_dict({"slak": 0.1})
    assert RewardWeights.from_dict({"length": 0.0}).length == 0.0
