"""metrics.png: one panel per table column, in a grid that grows with the columns."""

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
