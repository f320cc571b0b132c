"""metrics.png: one panel per table column, in a grid that grows with the columns;
profile.png: the performance profile, where failed episodes never reach tau."""

from __future__ import annotations

import pytest

from tether_gym_agents.evaluation import plots


def _metrics_figure(tmp_path, monkeypatch, columns):
    pytest.importorskip("matplotlib")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    monkeypatch.setattr(plots, "TABLE_COLUMNS", columns)
    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, path, **kw: saved.append(self))
    block = {key: 0.5 for key, _ in columns}
    block["ci95"] = {key: (0.4, 0.6) for key, _ in columns}
    results = {"suite": "x", "policies": {"a": block, "b": dict(block)}}
    plots._intervals(Figure, FigureCanvasAgg, results, tmp_path)
    (fig,) = saved
    return fig


@pytest.mark.parametrize(("n_columns", "grid"), [(8, (2, 4)), (9, (3, 4)), (3, (1, 3))])
def test_one_panel_per_table_column(tmp_path, monkeypatch, n_columns, grid):
    """8 columns (the shipped table) keep metrics.png's 2 x 4 grid; a 9th adds a row."""
    columns = tuple((f"metric_{k}", f"metric {k} [-]") for k in range(n_columns))
    fig = _metrics_figure(tmp_path, monkeypatch, columns)
    assert [ax.get_title() for ax in fig.axes] == [title for _, title in columns]
    assert {ax.get_subplotspec().get_geometry()[:2] for ax in fig.axes} == {grid}


def test_profile_counts_every_episode_and_failures_never_reach_tau():
    import numpy as np

    eps = [{"success": 1, "tracking_rms": 1e-4}, {"success": 1, "tracking_rms": 1e-2},
           {"success": 0, "tracking_rms": 1e-6},  # failed after orbit 1: never counts
           {"success": 0, "tracking_rms": None}]  # failed before orbit 1
    curve = plots.profile_curve(eps, np.array([1e-7, 1e-5, 1e-4, 5e-3, 1e-2, 1.0]))
    np.testing.assert_array_equal(curve, [0.0, 0.0, 0.25, 0.25, 0.5, 0.5])
    assert np.isnan(plots.profile_curve([], np.array([1.0]))).all()


def test_profile_figure_has_one_curve_per_policy(tmp_path):
    pytest.importorskip("matplotlib")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    eps = [{"policy": p, "success": s, "tracking_rms": r}
           for p, s, r in (("a", 1, 1e-3), ("a", 0, None), ("b", 1, 2e-4), ("b", 1, 5e-4))]
    results = {"suite": "x", "policies": {"a": {}, "b": {}}, "episodes": eps}
    path = plots._profile(Figure, FigureCanvasAgg, results, tmp_path)
    assert path == tmp_path / "profile.png" and path.stat().st_size > 0
