"""Statistics across training runs, against small examples computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from tether_gym_agents.evaluation.stats import (
    bootstrap_iqm,
    iqm,
    probability_of_improvement,
    run_scores,
    stratified_bootstrap_ci,
    success_counts,
    success_rate_ci,
)


def test_iqm_hand_example():
    # 8 values: drop floor(8/4) = 2 at each end -> mean(3, 4, 5, 6) = 4.5
    values = [7, 1, 100, 3, 2, 6, 4, 5]
    assert iqm(values) == 4.5
    assert iqm(values) == pytest.approx(sps.trim_mean(values, 0.25))
    # NaN entries are left out: 7 finite values, drop 1 at each end -> mean(2..6) = 4
    assert iqm([1, 2, 3, 4, 5, 6, 7, math.nan]) == 4.0
    assert iqm(np.array([[1.0, 2.0], [3.0, 4.0]])) == 2.5  # matrices are flattened
    assert math.isnan(iqm([math.nan]))


def test_run_scores_are_means_over_each_runs_episodes():
    eps = [{"run": 0, "scenario": "a", "x": 1.0}, {"run": 0, "scenario": "a", "x": 3.0},
           {"run": 1, "scenario": "a", "x": 5.0}, {"run": 1, "scenario": "a", "x": math.nan},
           {"run": 0, "scenario": "b", "x": math.nan}, {"run": 1, "scenario": "b", "x": 2.0}]
    scores = run_scores(eps, "x", [0, 1], ["a", "b"])
    np.testing.assert_array_equal(scores, [[2.0, np.nan], [5.0, 2.0]])


def test_stratified_bootstrap_hand_example():
    # 2 runs x 2 scenarios; the IQM of 4 values is the mean of the middle two.
    # Stratified resampling keeps two draws from {0, 1} (scenario 1) and two from
    # {10, 11} (scenario 2), so the middle pair is (max of the first, min of the
    # second): IQM = 5 w.p. 1/4 * 3/4, 6 w.p. 3/4 * 1/4 and 5.5 otherwise.
    # (Unstratified resampling of the 4 values could give 0 or 11.)
    scores = np.array([[0.0, 10.0], [1.0, 11.0]])
    boot = bootstrap_iqm(scores, n_boot=20000, seed=1)
    values, counts = np.unique(boot, return_counts=True)
    np.testing.assert_array_equal(values, [5.0, 5.5, 6.0])
    np.testing.assert_allclose(counts / boot.size, [3 / 16, 10 / 16, 3 / 16], atol=0.01)
    assert stratified_bootstrap_ci(scores) == (5.0, 6.0)


def test_bootstrap_interval_of_two_runs_in_one_scenario():
    # resamples (0,0), (0,1), (1,0), (1,1): IQM of 2 values is their mean -> 0, .5, .5, 1
    boot = bootstrap_iqm(np.array([[0.0], [1.0]]), n_boot=8000, seed=2)
    assert set(np.unique(boot)) == {0.0, 0.5, 1.0}
    assert np.mean(boot == 0.5) == pytest.approx(0.5, abs=0.02)
    assert stratified_bootstrap_ci(np.array([[0.0], [1.0]])) == (0.0, 1.0)


def test_interval_undefined_for_one_run_or_no_data():
    assert stratified_bootstrap_ci(np.array([[1.0, 2.0, 3.0]])) is None
    assert stratified_bootstrap_ci(np.full((3, 2), np.nan)) is None


def test_bootstrap_with_undefined_scores():
    scores = np.array([[0.0, np.nan], [1.0, np.nan]])
    lo, hi = stratified_bootstrap_ci(scores)
    assert (lo, hi) == (0.0, 1.0)


def test_probability_of_improvement_hand_example():
    # scenario A: X runs (1, 3) vs Y (2): pairs 1>2 no, 3>2 yes -> 1/2
    # scenario B: X (5, 5) vs Y (5, 4): ties 1/2 twice, wins twice -> 3/4
    x = np.array([[1.0, 5.0], [3.0, 5.0]])
    y = np.array([[2.0, 5.0], [np.nan, 4.0]])
    assert probability_of_improvement(x, y) == pytest.approx((0.5 + 0.75) / 2)
    # lower is better: A: 1 < 2 yes, 3 < 2 no -> 1/2; B: ties 1/2 twice, 5 < 4 never -> 1/4
    assert probability_of_improvement(x, y, higher_is_better=False) == pytest.approx(0.375)
    # the per-scenario term is Mann-Whitney's U / (n_x n_y)
    u = sps.mannwhitneyu([5.0, 5.0], [5.0, 4.0]).statistic
    assert u / 4 == pytest.approx(0.75)
    assert probability_of_improvement(x, x) == pytest.approx(0.5)


def test_probability_of_improvement_without_common_data():
    assert probability_of_improvement(np.array([[np.nan]]), np.array([[1.0]])) is None
    with pytest.raises(ValueError, match="same scenarios"):
        probability_of_improvement(np.ones((2, 3)), np.ones((2, 2)))


def _episodes(survived: dict) -> list[dict]:
    """Episode records from {(run, scenario): [success of each episode]}."""
    return [{"run": r, "scenario": sc, "success": float(v)}
            for (r, sc), values in survived.items() for v in values]


def test_success_is_the_raw_fraction_and_the_hard_scenario_is_never_trimmed():
    # 2 runs x 4 scenarios of 10 episodes; scenario "hard" loses 4 + 5 of 20. Of the 8
    # cells the IQM drops the 2 lowest, both of "hard", and says 1.0; the raw fraction
    # is 71/80 and the worst scenario 11/20.
    cells = {(r, sc): [1] * 10 for r in (0, 1) for sc in "abc"}
    cells[(0, "hard")] = [1] * 6 + [0] * 4
    cells[(1, "hard")] = [1] * 5 + [0] * 5
    eps = _episodes(cells)
    names = ["a", "b", "c", "hard"]
    assert iqm(run_scores(eps, "success", [0, 1], names)) == 1.0
    counts = success_counts(eps, [0, 1], names)
    assert counts.rate == 71 / 80
    assert counts.worst(names) == ("hard", 11 / 20)
    np.testing.assert_array_equal(counts.per_scenario, [1.0, 1.0, 1.0, 0.55])


def test_success_interval_resamples_runs_per_scenario():
    cells = {(0, "a"): [1, 1], (1, "a"): [0, 0], (0, "b"): [1, 0], (1, "b"): [1, 0]}
    counts = success_counts(_episodes(cells), [0, 1], ["a", "b"])
    assert counts.rate == 0.5
    lo, hi = success_rate_ci(counts, n_boot=4000)
    # per scenario a, the 2 drawn runs give 4/4, 2/4 or 0/4 survivors (p 1/4, 1/2,
    # 1/4); b always gives 2/4: the rate is 6/8, 4/8 or 2/8 -> 2.5 % and 97.5 %
    # percentiles 0.25 and 0.75
    assert (lo, hi) == (0.25, 0.75)
    one_run = success_counts(_episodes({(0, "a"): [1, 0]}), [0], ["a"])
    assert success_rate_ci(one_run) is None
    assert one_run.rate == 0.5
