"""cost.png, the performance profile's companion (issue 35): success against the mean
cost per step, one labelled point per policy, with interval bars for 2+ runs."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest

from tether_gym.tasks.cost import COST_LIMIT
from tether_gym_agents.cli.evaluate import main
from tether_gym_agents.evaluation import plots


def _cost_axes(figures: list):
    (ax,) = [ax for fig in figures for ax in fig.axes
             if ax.get_title().startswith("Success against cost")]
    return ax


def _points(ax) -> dict:
    """{label: (x, y, xerr segment or None, yerr segment or None)} of the errorbars."""
    out = {}
    for container in ax.containers:
        line, _, bars = container.lines
        x, y = line.get_xdata()[0], line.get_ydata()[0]
        segs = [np.asarray(b.get_segments()[0]) for b in bars]
        xseg = next((s for s in segs if s[0, 1] == s[1, 1]), None) if container.has_xerr \
            else None
        yseg = next((s for s in segs if s[0, 0] == s[1, 0]), None) if container.has_yerr \
            else None
        out[container.get_label()] = (x, y, xseg, yseg)
    return out


def test_evaluate_py_writes_cost_png_next_to_the_profile(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    saved = []
    original = Figure.savefig

    def keep(self, path, **kwargs):
        saved.append(self)
        return original(self, path, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["smc", "zero", "--suite", "paper", "--seeds", "2", "--env-kwargs",
                     "orbits_per_episode=0.3", "--out", str(tmp_path)])
    assert code == 0
    assert (tmp_path / "profile.png").is_file() and (tmp_path / "cost.png").stat().st_size
    res = json.loads((tmp_path / "results.json").read_text())
    ax = _cost_axes(saved)
    points = _points(ax)
    assert set(points) == {"smc", "zero"}
    for name, (x, y, xseg, yseg) in points.items():
        block = res["policies"][name]
        assert (x, y) == (block["cost_per_step"], block["success"])
        assert xseg is None and yseg is None  # one run: no interval
    labelled = [n for t in ax.texts for n in t.get_text().split(", ")]
    assert sorted(labelled) == ["smc", "zero"]  # each policy once
    limit = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert [line.get_xdata()[0] for line in limit] == [COST_LIMIT]


def test_intervals_of_several_runs_are_drawn_as_bars(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, path, **kw: saved.append(self))
    results = {"suite": "x", "cost_limit": 0.01, "episodes": [], "policies": {
        "a": {"cost_per_step": 0.02, "success": 0.9,
              "ci95": {"cost_per_step": (0.015, 0.04), "success": (0.8, 0.95)}},
        "b": {"cost_per_step": 0.0, "success": 1.0,
              "ci95": {"cost_per_step": None, "success": None}},
        "c": {"cost_per_step": float("nan"), "success": 1.0,  # no cost: not drawn
              "ci95": {"cost_per_step": None, "success": None}}}}
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    path = plots._cost(Figure, FigureCanvasAgg, results, tmp_path)
    assert path == tmp_path / "cost.png"
    points = _points(_cost_axes(saved))
    assert set(points) == {"a", "b"}
    x, y, xseg, yseg = points["a"]
    assert (x, y) == (0.02, 0.9)
    np.testing.assert_allclose(sorted(xseg[:, 0]), [0.015, 0.04])
    np.testing.assert_allclose(sorted(yseg[:, 1]), [0.8, 0.95])
    assert points["b"][2] is None and points["b"][3] is None
