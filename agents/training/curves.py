"""Learning curves of a run and of a folder of seed runs (matplotlib, optional)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from ..common.atomic_write import save_figure
from ..files.run_folder import (
    LEARNING_CURVE_FILE,
    SEED_CURVES_FILE,
    DamagedFileError,
    evaluations_path,
    read_evaluations,
    seed_runs,
)

__all__ = ["plot_learning_curve", "plot_seed_learning_curves"]


def plot_learning_curve(run_dir: Path) -> Path | None:
    """Write ``learning_curve.png`` from ``eval/evaluations.npz``; None without matplotlib.

    Mean evaluation return (with min-max band) and mean episode length against env
    steps, as recorded by the evaluation callback (rows of different episode counts
    are NaN-padded: the statistics skip the padding).
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    data = read_evaluations(run_dir)
    if data is None:
        raise FileNotFoundError(f"{evaluations_path(run_dir)} does not exist")
    steps, returns, lengths = data["timesteps"], data["results"], data["ep_lengths"]
    fig = Figure(figsize=(7, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax, ax_len = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    ax.plot(steps, np.nanmean(returns, axis=1), label="mean")
    ax.fill_between(steps, np.nanmin(returns, axis=1), np.nanmax(returns, axis=1), alpha=0.3,
                    label="min-max")
    ax.set_ylabel("evaluation return")
    ax.set_title(f"{Path(run_dir).name}: deterministic evaluation episodes")
    ax.legend()
    ax_len.plot(steps, np.nanmean(lengths, axis=1))
    ax_len.set_ylabel("episode length")
    ax_len.set_xlabel("env steps")
    out = Path(run_dir) / LEARNING_CURVE_FILE
    save_figure(fig, out, dpi=100, format="png")
    return out


def plot_seed_learning_curves(folder: Path) -> Path | None:
    """Write ``learning_curves.png`` for a folder of ``seed_K`` runs; None if none plots.

    Each seed's mean evaluation return against env steps (thin lines), and the
    interquartile mean over the seeds with its min-max band on the steps every seed
    has reached (evaluations at the same step counts, as the fan-out's runs have).
    None without matplotlib or without two runs holding ``eval/evaluations.npz``. A run
    whose file is damaged is left out, with a line on stderr naming it.
    """
    from scipy.stats import trim_mean

    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    curves = {}
    for run in seed_runs(folder):
        try:
            data = read_evaluations(run)
        except DamagedFileError as exc:  # one damaged seed does not end the plot
            print(f"learning curves: {run.name} left out: {exc}", file=sys.stderr)
            continue
        if data is not None:
            curves[run.name] = (data["timesteps"], np.nanmean(data["results"], axis=1))
    if len(curves) < 2:
        return None
    common = sorted(set.intersection(*(set(t.tolist()) for t, _ in curves.values())))
    fig = Figure(figsize=(7, 4), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for steps, ret in curves.values():
        ax.plot(steps, ret, lw=0.7, alpha=0.5, label=None)
    if common:
        table = np.array([[ret[steps.tolist().index(t)] for t in common]
                          for steps, ret in curves.values()])
        ax.plot(common, trim_mean(table, 0.25, axis=0), color="k", lw=2,
                label=f"IQM over {len(curves)} seeds")
        ax.fill_between(common, table.min(axis=0), table.max(axis=0), color="k", alpha=0.1,
                        label="min-max over seeds")
        ax.legend()
    ax.set_xlabel("env steps")
    ax.set_ylabel("mean evaluation return")
    ax.set_title(f"{Path(folder).name}: deterministic evaluation episodes, every seed")
    out = Path(folder) / SEED_CURVES_FILE
    save_figure(fig, out, dpi=100, format="png")
    return out
