"""Plots of the benchmark: the performance profile, one trajectory per policy, intervals.

* ``profile.png``: the performance profile of tracking precision, one curve per
  policy: the fraction of *all* its episodes (every run, scenario and seed) that survive
  with a tracking RMS after orbit 1 <= tau, against tau on a log axis. A failed
  episode never reaches any tau (as in Dolan & More's performance profiles, and
  rliable's score distributions): a curve's right end is the policy's success rate.

* ``cost.png``, the profile's companion: success (the surviving fraction of all
  episodes, y) against the mean constraint cost per step (IQM over runs x scenarios of
  ``cost_per_step``, x), one labelled point per policy, with its 95 %
  stratified-bootstrap intervals as bars (2+ runs) and the cost limit as a dashed line
  (policies on one point share its label);
  the x axis is linear up to the limit and logarithmic beyond (``symlog``). Written when
  the results carry a ``cost_limit``.
* ``trajectories.png``: max_i |theta_i - theta_d| and l_1 + ... + l_n over the first
  scenario's first seed (run 0) of every policy; the title names the scenario, and an
  episode that ended in a failure ends with an ``x`` marker labelled with the reason.
* ``metrics.png``: per column of the table (``results.TABLE_COLUMNS``, four panels to a
  row), each policy's IQM (dot; success and over cost limit: fractions of all episodes) with
  its 95 % stratified-bootstrap
  interval (bar), as rliable's ``plot_interval_estimates``; an undefined value (such as
  the convergence time of a policy that never converges) is written "n/a", never drawn.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..common.atomic_write import save_figure
from .results import TABLE_COLUMNS

__all__ = ["plot_results", "profile_curve", "cost_points", "PLOT_PIP"]

PLOT_PIP = 'pip install "matplotlib>=3.7"'
LOG_SCALE = ("tracking_rms", "final_error", "chattering", "reel_effort")
PANELS_PER_ROW = 4
"""Panels per row of ``metrics.png`` (one panel per column of the table)."""


def _finite(x) -> bool:
    return x is not None and math.isfinite(x)


def plot_results(results: dict, trajectories: dict, scenario, out: Path, log=print) -> list:
    """Write ``profile.png``, ``cost.png``, ``trajectories.png`` and ``metrics.png``.

    Returns the paths written (``cost.png`` only when ``results`` has a ``cost_limit``).

    Without matplotlib, logs the pip command and writes nothing.
    """
    log = log or (lambda *a, **k: None)
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        log(f"  (plots skipped: matplotlib is missing; install it with: {PLOT_PIP})")
        return []
    out = Path(out)
    written = [_profile(Figure, FigureCanvasAgg, results, out),
               _trajectories(Figure, FigureCanvasAgg, trajectories, scenario, out),
               _intervals(Figure, FigureCanvasAgg, results, out)]
    if "cost_limit" in results:
        written.insert(1, _cost(Figure, FigureCanvasAgg, results, out))
    log("  wrote " + ", ".join(str(p) for p in written))
    return written


def profile_curve(episodes: list[dict], taus: np.ndarray) -> np.ndarray:
    """Fraction of ``episodes`` that survive with tracking RMS <= tau, for each tau.

    The denominator is every episode; a failed one (``success`` 0) or one without a
    tracking RMS counts as never reaching tau.
    """
    if not episodes:
        return np.full(len(taus), np.nan)
    reached = np.array([e["tracking_rms"] for e in episodes
                        if e["success"] == 1 and _finite(e["tracking_rms"])])
    return np.array([(reached <= t).sum() for t in taus]) / len(episodes)


def _profile(Figure, Canvas, results: dict, out: Path) -> Path:
    fig = Figure(figsize=(8, 5), layout="constrained")
    Canvas(fig)
    ax = fig.subplots()
    eps = results["episodes"]
    rms = [e["tracking_rms"] for e in eps if e["success"] == 1 and _finite(e["tracking_rms"])
           and e["tracking_rms"] > 0]
    lo, hi = (min(rms), max(rms)) if rms else (1e-6, 1.0)
    taus = np.logspace(np.log10(lo) - 0.3, np.log10(hi) + 0.3, 400)
    for k, name in enumerate(results["policies"]):
        curve = profile_curve([e for e in eps if e["policy"] == name], taus)
        ax.step(taus, curve, where="post", label=name, color=f"C{k % 10}",
                ls="-" if k < 10 else "--")
    ax.set_xscale("log")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("tau: tracking RMS after orbit 1 [rad]")
    ax.set_ylabel("fraction of all episodes with RMS <= tau")
    ax.set_title(f"Performance profile, suite {results['suite']!r} (every run, scenario and "
                 "seed; failed episodes never reach tau)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    path = out / "profile.png"
    save_figure(fig, path, dpi=100)  # a link or FIFO there is replaced, not written to
    return path


def cost_points(results: dict) -> dict[str, tuple]:
    """``{policy: (cost, success, cost_ci, success_ci)}`` of :func:`_cost`'s points.

    ``cost`` is the IQM of ``cost_per_step``, ``success`` the surviving fraction; each
    interval is ``(lo, hi)`` or None (fewer than 2 runs). Policies without a finite cost
    or success are left out.
    """
    points = {}
    for name, block in results["policies"].items():
        cost, success = block.get("cost_per_step"), block.get("success")
        if not (_finite(cost) and _finite(success)):
            continue
        ci95 = block.get("ci95", {})
        points[name] = (cost, success, ci95.get("cost_per_step"), ci95.get("success"))
    return points


def _cost(Figure, Canvas, results: dict, out: Path) -> Path:
    fig = Figure(figsize=(8, 5), layout="constrained")
    Canvas(fig)
    ax = fig.subplots()
    limit = float(results["cost_limit"])
    points = cost_points(results)
    labels: dict[tuple, list[str]] = {}  # policies on one point share one label
    right = limit
    for k, (name, (cost, success, cost_ci, success_ci)) in enumerate(points.items()):
        color = f"C{k % 10}"
        xerr = None if cost_ci is None else [[cost - cost_ci[0]], [cost_ci[1] - cost]]
        yerr = None if success_ci is None else [[success - success_ci[0]],
                                                [success_ci[1] - success]]
        ax.errorbar([cost], [success], xerr=xerr, yerr=yerr, fmt="o", color=color,
                    capsize=3, label=name)
        labels.setdefault((cost, success), []).append(name)
        right = max(right, cost, cost_ci[1] if cost_ci is not None else cost)
    for (cost, success), names in labels.items():
        ax.annotate(", ".join(names), (cost, success), textcoords="offset points",
                    xytext=(5, -12 if success > 0.9 else 5), fontsize=8)
    ax.axvline(limit, color="grey", ls="--", lw=1, label=f"cost limit {limit:g}")
    ax.set_xscale("symlog", linthresh=limit)
    ax.set_xlim(0.0, 3.0 * right)
    ax.set_ylim(-0.02, 1.04)
    ax.set_xlabel("mean cost per step [-] (IQM over runs x scenarios; linear up to the "
                  "limit, log beyond)")
    ax.set_ylabel("success: surviving fraction of all episodes")
    ax.set_title(f"Success against cost, suite {results['suite']!r} (bars: 95 % "
                 "stratified-bootstrap intervals over runs, 2+ runs)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    path = out / "cost.png"
    save_figure(fig, path, dpi=100)  # a link or FIFO there is replaced, not written to
    return path


def _trajectories(Figure, Canvas, trajectories: dict, scenario, out: Path) -> Path:
    fig = Figure(figsize=(10, 6.5), layout="constrained")
    Canvas(fig)
    ax_err, ax_len = fig.subplots(2, 1, sharex=True)
    seed = None
    for name, traj in trajectories.items():
        seed = traj.seed
        orbits = traj.orbits[1:]
        err = np.maximum(traj.tracking_error[1:], 1e-7)
        total = traj.length[1:].sum(axis=1)
        line, = ax_err.semilogy(orbits, err, label=name)
        ax_len.plot(orbits, total, color=line.get_color(), label=name)
        if traj.failure is not None:
            for ax, y in ((ax_err, err[-1]), (ax_len, total[-1])):
                ax.plot([orbits[-1]], [y], "x", color=line.get_color(), ms=10, mew=2)
                ax.annotate(traj.failure, (orbits[-1], y), textcoords="offset points",
                            xytext=(4, 4), fontsize=8, color=line.get_color())
    title = f"scenario {scenario.name!r}"
    if scenario.description:
        title += f": {scenario.description}"
    ax_err.set_title(f"{title}; seed {seed}, run 0 (x: episode ended in a failure)",
                     fontsize=9)
    ax_err.set_ylabel("max |theta - theta_d| [rad]")
    ax_err.legend(ncol=3, fontsize=8)
    ax_len.set_ylabel("l1 + ... + l_n [-]")
    ax_len.set_xlabel("true anomaly [orbits]")
    path = out / "trajectories.png"
    save_figure(fig, path, dpi=100)  # a link or FIFO there is replaced, not written to
    return path


def _grid(panels: int) -> tuple[int, int]:
    """(rows, columns) of a grid of ``panels`` panels, :data:`PANELS_PER_ROW` to a row."""
    rows = -(-panels // PANELS_PER_ROW)
    return rows, min(panels, PANELS_PER_ROW)


def _intervals(Figure, Canvas, results: dict, out: Path) -> Path:
    pols = results["policies"]
    names = list(pols)
    rows, cols = _grid(len(TABLE_COLUMNS))
    fig = Figure(figsize=(13, 1.2 + 0.45 * len(names) * rows), layout="constrained")
    Canvas(fig)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[len(TABLE_COLUMNS):]:
        fig.delaxes(ax)  # the last row's empty places
    ys = np.arange(len(names))[::-1]
    for ax, (key, title) in zip(axes[:len(TABLE_COLUMNS)], TABLE_COLUMNS, strict=True):
        values = [pols[p][key] for p in names]
        cis = [pols[p]["ci95"][key] for p in names]
        drawn = [v for v in values if _finite(v)]
        log_scale = key in LOG_SCALE and drawn and min(drawn) > 0
        for y, value, ci in zip(ys, values, cis, strict=True):
            if not _finite(value):
                ax.text(0.5, y, "n/a", transform=ax.get_yaxis_transform(), ha="center",
                        va="center", fontsize=8, color="grey")
                continue
            if ci is not None and _finite(ci[0]) and _finite(ci[1]):
                ax.plot([ci[0], ci[1]], [y, y], "-", lw=5, alpha=0.35, color="C0",
                        solid_capstyle="butt")
            ax.plot([value], [y], "o", color="C0", ms=5)
        if log_scale:
            from matplotlib.ticker import NullFormatter

            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_yticks(ys, names, fontsize=8)
        ax.set_ylim(-0.7, len(names) - 0.3)
        ax.set_title(title, fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    fig.suptitle("IQM over runs x scenarios (success, over cost limit: fractions of all "
                 "episodes) "
                 "with 95 % stratified-bootstrap intervals "
                 f"(suite {results['suite']!r}; intervals need 2+ runs; n/a: undefined)",
                 fontsize=10)
    path = out / "metrics.png"
    save_figure(fig, path, dpi=100)  # a link or FIFO there is replaced, not written to
    return path
