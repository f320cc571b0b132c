"""Statistics across training runs: IQM, stratified bootstrap, probability of improvement.

After Agarwal et al. 2021, "Deep RL at the Edge of the Statistical Precipice" (NeurIPS).

Scores are matrices ``(n_runs, n_scenarios)``: entry (r, m) is run r's mean of a metric
over its episodes on scenario m (:func:`run_scores`). A run is one trained agent (one
training seed); a deterministic baseline is one run.

* :func:`iqm`: the mean of the middle 50 % of all entries (``scipy.stats.trim_mean``
  with 25 % cut at each end, over runs and scenarios together, as rliable's
  ``aggregate_iqm``).
* :func:`stratified_bootstrap_ci`: percentile interval of the IQM over resamples that
  draw ``n_runs`` runs with replacement *within each scenario* (rliable's
  ``StratifiedBootstrap``).
* :func:`probability_of_improvement`: per scenario P(X > Y) over all pairs of runs
  (the Mann-Whitney U statistic over n_X n_Y, ties counting 1/2), averaged over the
  scenarios; for metrics where lower is better, improvement means X < Y.

The IQM is for continuous metrics. **Success is never trimmed**: a failed episode is a
lost mission, and the 25 % cut of an IQM drops the hardest scenario's cells.
:func:`success_counts` gives the raw fraction of all episodes that survive and the
worst scenario's; :func:`success_rate_ci` its interval over training runs (the same
stratified resampling of runs). The fraction of episodes over the cost limit
(``over_limit``) is counted and resampled the same way.

NaN entries (a metric undefined for every episode of a run, such as the convergence
time of a policy that never converges) are left out.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy import stats

__all__ = ["iqm", "run_scores", "bootstrap_iqm", "stratified_bootstrap_ci",
           "probability_of_improvement", "success_counts", "success_rate_ci",
           "SuccessCounts", "N_BOOTSTRAP", "BOOTSTRAP_SEED"]

N_BOOTSTRAP = 2000
"""Bootstrap resamples of every interval."""
BOOTSTRAP_SEED = 0
"""Seed of the resampling generator (results.json is reproducible)."""


def iqm(values) -> float:
    """Interquartile mean of the finite entries of ``values`` (any shape); NaN if none.

    ``scipy.stats.trim_mean(finite, 0.25)``: sort, drop ``floor(n / 4)`` values at each
    end, average the rest.
    """
    finite = np.asarray(values, dtype=float).ravel()
    finite = finite[np.isfinite(finite)]
    if finite.size == 0:
        return math.nan
    return float(stats.trim_mean(finite, 0.25))


def run_scores(episodes: list[dict], metric: str, runs: list, scenarios: list) -> np.ndarray:
    """``(len(runs), len(scenarios))`` matrix of each run's mean over its episodes.

    ``episodes`` are records with keys ``run``, ``scenario`` and ``metric``; NaN values
    are left out of a mean, and a cell with no finite value is NaN.
    """
    row = {r: i for i, r in enumerate(runs)}
    col = {s: j for j, s in enumerate(scenarios)}
    sums = np.zeros((len(runs), len(scenarios)))
    counts = np.zeros((len(runs), len(scenarios)))
    for ep in episodes:
        value = ep[metric]
        if value is None or not math.isfinite(value):
            continue
        i, j = row[ep["run"]], col[ep["scenario"]]
        sums[i, j] += value
        counts[i, j] += 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def bootstrap_iqm(scores: np.ndarray, n_boot: int = N_BOOTSTRAP,
                  seed: int = BOOTSTRAP_SEED) -> np.ndarray:
    """IQM of ``n_boot`` stratified resamples of ``scores`` (n_runs, n_scenarios).

    Each resample draws, independently for every scenario (column), ``n_runs`` rows
    with replacement; returns the ``n_boot`` IQMs (NaN where a resample has no finite
    entry).
    """
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 2 or scores.shape[0] < 1 or scores.shape[1] < 1:
        raise ValueError(f"scores must be a non-empty (n_runs, n_scenarios) matrix, got "
                         f"shape {scores.shape}")
    n_runs, n_scen = scores.shape
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n_runs, size=(n_boot, n_runs, n_scen))
    samples = scores[idx, np.arange(n_scen)].reshape(n_boot, -1)
    if np.isfinite(samples).all():
        return stats.trim_mean(samples, 0.25, axis=1)
    return np.array([iqm(row) for row in samples])


def stratified_bootstrap_ci(scores: np.ndarray, level: float = 0.95,
                            n_boot: int = N_BOOTSTRAP,
                            seed: int = BOOTSTRAP_SEED) -> tuple[float, float] | None:
    """Percentile ``level`` interval of the IQM under stratified bootstrap.

    None when there are fewer than two runs (no spread over training runs to measure)
    or no finite score.
    """
    scores = np.asarray(scores, dtype=float)
    if scores.shape[0] < 2 or not np.isfinite(scores).any():
        return None
    boot = bootstrap_iqm(scores, n_boot, seed)
    boot = boot[np.isfinite(boot)]
    if boot.size == 0:
        return None
    tail = 50.0 * (1.0 - level)
    lo, hi = np.percentile(boot, [tail, 100.0 - tail])
    return float(lo), float(hi)


def probability_of_improvement(x: np.ndarray, y: np.ndarray,
                               higher_is_better: bool = True) -> float | None:
    """P(X improves on Y), averaged over scenarios (columns).

    Parameters
    ----------
    x, y : ndarray
        Scores ``(n_runs_x, n_scenarios)`` and ``(n_runs_y, n_scenarios)``.
    higher_is_better : bool
        False for metrics where the smaller value is the better one.

    Returns
    -------
    float or None
        (1 / M) sum_m (1 / (n_x n_y)) sum_ij S(x_im, y_jm) with S = 1 for an
        improvement, 1/2 for a tie, 0 otherwise, over the M scenarios where both have a
        finite score; None if there is no such scenario.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 2 or y.ndim != 2 or x.shape[1] != y.shape[1]:
        raise ValueError(f"x {x.shape} and y {y.shape} must be (n_runs, n_scenarios) with "
                         "the same scenarios")
    per_scenario = []
    for m in range(x.shape[1]):
        a = x[np.isfinite(x[:, m]), m]
        b = y[np.isfinite(y[:, m]), m]
        if a.size == 0 or b.size == 0:
            continue
        if not higher_is_better:
            a, b = -a, -b
        diff = a[:, None] - b[None, :]
        per_scenario.append(float(((diff > 0) + 0.5 * (diff == 0)).mean()))
    return float(np.mean(per_scenario)) if per_scenario else None


class SuccessCounts(NamedTuple):
    """Surviving and all episodes per (run, scenario) cell, and what they add up to."""

    survived: np.ndarray
    """(n_runs, n_scenarios) episodes that ran to the time limit without failure."""
    episodes: np.ndarray
    """(n_runs, n_scenarios) episodes."""

    @property
    def rate(self) -> float:
        """Surviving fraction of all episodes [-] (NaN without episodes)."""
        total = self.episodes.sum()
        return float(self.survived.sum() / total) if total else math.nan

    @property
    def per_scenario(self) -> np.ndarray:
        """(n_scenarios,) surviving fraction of each scenario's episodes over all runs."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.survived.sum(axis=0) / self.episodes.sum(axis=0)

    def worst(self, scenarios: list) -> tuple[str | None, float]:
        """(name, surviving fraction) of the scenario with the lowest fraction (first on ties)."""
        rates = self.per_scenario
        if not np.isfinite(rates).any():
            return None, math.nan
        j = int(np.nanargmin(rates))
        return scenarios[j], float(rates[j])


def success_counts(episodes: list[dict], runs: list, scenarios: list,
                   metric: str = "success") -> SuccessCounts:
    """Count surviving episodes (``success`` == 1) per run and scenario.

    With ``metric`` another 0/1 episode metric (such as ``over_limit``): the episodes
    where it is 1 (in the ``survived`` field) among all episodes, counted the same way;
    an episode where it is undefined (NaN) counts among all episodes only.
    """
    row = {r: i for i, r in enumerate(runs)}
    col = {s: j for j, s in enumerate(scenarios)}
    survived = np.zeros((len(runs), len(scenarios)))
    total = np.zeros((len(runs), len(scenarios)))
    for ep in episodes:
        i, j = row[ep["run"]], col[ep["scenario"]]
        total[i, j] += 1
        survived[i, j] += float(ep[metric] == 1)
    return SuccessCounts(survived, total)


def success_rate_ci(counts: SuccessCounts, level: float = 0.95, n_boot: int = N_BOOTSTRAP,
                    seed: int = BOOTSTRAP_SEED) -> tuple[float, float] | None:
    """Percentile interval of the surviving fraction over runs, resampled per scenario.

    Each resample draws, for every scenario, ``n_runs`` runs with replacement (as
    :func:`bootstrap_iqm`) and takes surviving over all episodes of the drawn cells. None
    with fewer than two runs or no episodes.
    """
    n_runs, n_scen = counts.survived.shape
    if n_runs < 2 or not counts.episodes.sum():
        return None
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n_runs, size=(n_boot, n_runs, n_scen))
    cols = np.arange(n_scen)
    survived = counts.survived[idx, cols].sum(axis=(1, 2))
    total = counts.episodes[idx, cols].sum(axis=(1, 2))
    tail = 50.0 * (1.0 - level)
    lo, hi = np.percentile(survived / total, [tail, 100.0 - tail])
    return float(lo), float(hi)
