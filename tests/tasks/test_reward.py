"""The v1 reward: bounds, components, each term's formula against hand values, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tether_gym.tasks.reward import (
    COMPONENTS,
    MARGINS,
    PENALTIES,
    TERMS,
    RewardWeights,
    reward_terms,
    term_sums,
)


def _reward(theta=(0.2, 0.2), dtheta=(0.3, 0.3), length=(0.5, 0.5), ref=0.2, dref=0.3,
            command=(0.0, 0.0), accel=(0.0, 0.0), tension=(2.0, 2.0), nominal=(0.5, 0.5),
            weights=None):
    out = np.empty(len(COMPONENTS))
    params = (weights or RewardWeights()).record()
    y = np.concatenate([theta, dtheta, length, np.zeros(len(theta))]).astype(float)
    n = len(theta)
    raw = np.empty(len(TERMS))
    term_sums(y, n, *(np.asarray(x, dtype=float) for x in (command, accel, tension, nominal)),
              params, raw)
    r = reward_terms(y, n, ref, dref, params, raw, out)
    return r, dict(zip(COMPONENTS, out, strict=True))


def test_declaration():
    assert PENALTIES == ("effort", "accel") and MARGINS == ("slack", "length")
    assert COMPONENTS == ("reward_tracking", "reward_effort", "reward_accel", "reward_slack",
                          "reward_length")


def test_perfect_tracking_without_penalties_scores_one():
    r, comp = _reward()
    assert r == 1.0
    assert comp == {"reward_tracking": 0.6, "reward_effort": 0.0, "reward_accel": 0.0,
                    "reward_slack": 0.2, "reward_length": 0.2}


@pytest.mark.parametrize("rms", [1e-1, 1e-2, 1e-3, 3e-4])
def test_tracking_formula_by_hand(rms):
    """r_track = 0.5 / (1 + rms^2 / 0.05^2) + 0.5 ln(rms) / ln(1e-4), times 1 - W = 0.6."""
    r, comp = _reward(theta=(0.2 + rms, 0.2 - rms))  # c = rms^2 (no rate error)
    expected = 0.5 / (1 + (rms / 0.05) ** 2) + 0.5 * math.log(rms) / math.log(1e-4)
    assert comp["reward_tracking"] == pytest.approx(0.6 * expected, rel=1e-13)
    assert r == pytest.approx(0.6 * expected + 0.4, rel=1e-13)


def test_tracking_keeps_paying_down_to_the_floor():
    """Each decade of precision from 1e-2 to 1e-4 rad is worth at least 0.07 per step."""
    values = [_reward(theta=(0.2 + e, 0.2 - e))[0] for e in (1e-2, 1e-3, 1e-4, 1e-5)]
    assert values[1] - values[0] > 0.07 and values[2] - values[1] > 0.07
    assert values[3] - values[2] < 2e-6  # below the floor only the Lorentzian part moves


def test_rate_error_weight_and_pure_lorentzian():
    w = RewardWeights(log_share=0.0)
    _, comp = _reward(theta=(0.25, 0.15), weights=w)  # rms = sigma
    assert comp["reward_tracking"] == pytest.approx(0.6 * 0.5, abs=1e-15)
    de = 0.05 / math.sqrt(0.1)
    _, comp = _reward(dtheta=(0.3 + de, 0.3 - de), weights=w)
    assert comp["reward_tracking"] == pytest.approx(0.6 * 0.5, abs=1e-12)


def test_large_errors_give_zero_log_part():
    _, comp = _reward(theta=(1.4, -1.0), weights=RewardWeights(log_share=1.0))
    assert comp["reward_tracking"] == 0.0


@pytest.mark.parametrize(("kwargs", "key", "value"), [
    # penalties scale with the tracking part (0.6 at perfect tracking)
    ({"command": (1.0, 0.0)}, "reward_effort", -0.6 * 0.05 * 0.5),
    # margin terms: w (1 - q), q = mean(clip(1 - T/0.5, 0, 1)^2) = (0.25 + 1) / 2
    ({"tension": (0.25, -1.0)}, "reward_slack", 0.2 * (1 - (0.25 + 1.0) / 2)),
    # q_len = mean(min(1, h(ln(l/l0)) / h(ln 10))), h(x) = sqrt(1 + (x/0.2)^2) - 1
    ({"length": (1.0, 0.05)}, "reward_length",
     0.2 * (1 - ((math.sqrt(1 + (math.log(2) / 0.2) ** 2) - 1)
                 / (math.sqrt(1 + (math.log(10) / 0.2) ** 2) - 1) + 1.0) / 2)),
])
def test_each_term(kwargs, key, value):
    r, comp = _reward(**kwargs)
    assert comp[key] == pytest.approx(value, abs=1e-15)
    assert r == pytest.approx(sum(comp.values()), abs=1e-15)


def test_accel_term_when_weighted():
    w = RewardWeights(accel=0.05)
    _, comp = _reward(accel=(3.0, 0.5), weights=w)
    assert comp["reward_accel"] == pytest.approx(-0.6 * 0.05 * (1.0 + 0.25) / 2, abs=1e-15)
    assert _reward(accel=(3.0, 0.5))[1]["reward_accel"] == 0.0  # default weight 0


def test_length_term_has_a_gradient_inside_the_bounds():
    qs = [_reward(length=(l, 0.5))[1]["reward_length"] for l in np.linspace(0.06, 1.49, 50)]
    i0 = int(np.argmax(qs))
    assert np.all(np.diff(qs[:i0 + 1]) > 0) and np.all(np.diff(qs[i0:]) < 0)


def test_bounds_at_the_extremes():
    rng = np.random.default_rng(0)
    w = RewardWeights(accel=0.05)
    for _ in range(2000):
        r, comp = _reward(theta=rng.normal(0, 1, 2), dtheta=rng.normal(0, 3, 2),
                          length=rng.uniform(1e-3, 3, 2), command=rng.uniform(-1, 1, 2),
                          accel=rng.normal(0, 5, 2), tension=rng.normal(0, 2, 2), weights=w)
        assert 0.0 <= r <= 1.0
        assert r == pytest.approx(sum(comp.values()), abs=1e-14)
    worst, _ = _reward(theta=(1.7, -1.3), command=(1, 1), tension=(-1, -1), length=(50, 50))
    assert worst == pytest.approx(0.6 * 0.5 / (1 + (1.5 / 0.05) ** 2) * (1 - 0.05), rel=1e-12)


def test_weights_validated():
    with pytest.raises(ValueError, match="margin weights"):
        RewardWeights(slack=0.6, length=0.5)
    with pytest.raises(ValueError, match="penalty weights"):
        RewardWeights(effort=0.6, accel=0.5)
    with pytest.raises(ValueError, match="sigma"):
        RewardWeights(sigma=0.0)
    with pytest.raises(ValueError, match="log_floor"):
        RewardWeights(log_floor=1.0)
    with pytest.raises(ValueError, match="log_share"):
        RewardWeights(log_share=1.5)
    with pytest.raises(ValueError, match="unknown reward_weights keys.*'slak'"):
        RewardWeights.from_dict({"slak": 0.1})
    assert RewardWeights.from_dict({"length": 0.0}).length == 0.0
