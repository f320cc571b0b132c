"""The paper reproduction command (tether_gym_agents.paper) and its metric helpers."""

from __future__ import annotations

import ast
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from tether_gym_agents import paper
from tether_gym_agents.paper import cli as paper_cli
from tether_gym_agents.paper import figures, table

REPO = Path(__file__).resolve().parents[3]
PAPER_DIR = Path(paper.__file__).resolve().parent
SHIPPED = REPO / "docs" / "paper"

FIGURES = (
    "fig2_zero_state_angles.png",
    "fig3_zero_state_lengths.png",
    "fig4_zero_state_tensions.png",
    "fig5_periodic_lengths.png",
    "fig6_length_change_e07.png",
    "fig7_smc_angles.png",
    "fig8_smc_lengths.png",
    "fig9_smc_tensions.png",
)
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    code = paper_cli.main(["--out", str(out), "--orbits", "0.2", "--quick"])
    return code, out


def test_main_writes_figures_and_table(short_run):
    code, out = short_run
    assert code == 0
    for name in FIGURES:
        path = out / name
        assert path.is_file(), name
        data = path.read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 5000, name
    table = (out / "paper_vs_tether_gym.md").read_text()
    header = "| # | Quantity | Paper | tether_gym | tether_gym (h_c = 0.025) | Verdict | Note |"
    assert header in table
    rows = [line for line in table.splitlines() if line.startswith("| ") and "---" not in line]
    assert len(rows) >= 25  # header + every stated number
    for key in ("0.75", "24 %", "A = e = 0.2", "about 0.9", "by the end of orbit 1"):
        assert key in table, key
    result = json.loads((out / "paper_vs_tether_gym.json").read_text())
    assert result["orbits"] == 0.2 and result["quick"] is True
    assert set(FIGURES) <= set(result["figures"])
    assert len(result["table"]) == len(rows) - 1
    # the shortened runs really are short, and the metrics that need more say so
    assert result["smc_paper"]["duration_orbits"] <= 0.2 + 1e-3
    assert result["smc_paper"]["settings"]["control_step"] == 0.001
    assert result["smc_default"]["settings"]["control_step"] == 0.025
    verdicts = {r["quantity"]: r["verdict"] for r in result["table"]}
    assert verdicts["SMC: mean l_1 + l_2 after orbit 1"] == "n/a (run too short)"
    # the repository's own model notes are cited, never a path outside the repository
    assert "docs/model.md" in table and "shared/" not in table and "NOTES.md" not in table
    # the header quotes the env's real defaults
    from tether_gym.envs.config import EnvConfig

    cfg = EnvConfig()
    assert (f"RK4 step {cfg.physics_step:g}, reel lag {cfg.reel_time_constant:g}"
            in table.splitlines()[4])
    # strict JSON
    json.loads((out / "paper_vs_tether_gym.json").read_text(),
               parse_constant=lambda token: pytest.fail(f"bare {token} in the JSON"))


def test_paper_trajectories_come_from_the_benchmark_rollout():
    """The paper's sliding-mode run is the benchmark's rollout, metrics included."""
    from tether_gym_agents.baselines.smc import SlidingModeController
    from tether_gym_agents.evaluation.metrics import episode_metrics
    from tether_gym_agents.evaluation.rollout import make_vector_env, rollout
    from tether_gym_agents.paper.measures import smc_metrics
    from tether_gym_agents.paper.runs import run_smc

    traj = run_smc(0.3, {})
    venv = make_vector_env(1, {"orbits_per_episode": 0.3, "action_mode": "rate"})
    same = rollout(SlidingModeController.for_env(venv), [0], env=venv)[0]
    venv.close()
    np.testing.assert_array_equal(traj.theta, same.theta)
    np.testing.assert_array_equal(traj.command, traj.action.clip(-1, 1) * 0.5)
    m, bench = smc_metrics(traj), episode_metrics(traj)
    assert m["min_tension"] == bench["min_tension"]
    assert m["convergence_orbits"] is None and math.isnan(bench["converge_orbits"])


@pytest.mark.parametrize("argv", [[], ["--out"], ["--out", "x", "--orbits", "0"],
                                  ["--out", "x", "--orbits", "nan"],
                                  ["--out", "x", "--orbits", "abc"], ["--out", "x", "--bad"]])
def test_main_rejects_bad_arguments(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        paper.main(argv)
    assert exc.value.code == 2
    assert "usage" in capsys.readouterr().err


def test_missing_matplotlib_names_the_pip_command(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    with pytest.raises(ImportError, match=r'pip install "matplotlib>=3.7"'):
        paper.reproduce(tmp_path / "out", orbits=0.01, quick=True, log=None)
    assert not (tmp_path / "out").exists()  # failed before any run or output


def test_reproduce_rejects_bad_orbits(tmp_path):
    with pytest.raises(ValueError, match="orbits=-1"):
        paper.reproduce(tmp_path, orbits=-1, log=None)


# --------------------------------------------------------------------------- #
# metric helpers
# --------------------------------------------------------------------------- #
def test_convergence_orbits():
    t = np.linspace(0.0, 3.0, 301)
    err = np.where(t < 0.8, 0.1, 1e-4)
    err[50] = 1e-4  # a dip before the end of the transient does not count
    assert paper.convergence_orbits(t, err) == pytest.approx(0.8)
    assert paper.convergence_orbits(t, np.full_like(t, 1e-4)) == 0.0
    late = err.copy()
    late[-1] = 2e-3
    assert paper.convergence_orbits(t, late) is None


def test_swing():
    ell = np.array([[0.5, 0.5], [0.6, 0.45], [0.55, 0.5]])
    np.testing.assert_allclose(paper.swing(ell, 0.5), [0.2, 0.1])


def test_chattering_separates_smooth_and_switching_commands():
    h = 0.001 / (2 * math.pi)  # one step of 0.001 rad, in orbits
    t = np.arange(0.0, 2.0, h)
    smooth = 0.01 * np.sin(2 * math.pi * 2 * t)[:, None]  # two humps per orbit
    c = paper.chattering(t, smooth, start=0.0)
    assert c["tv_per_orbit"] == pytest.approx(0.08, rel=1e-3)  # 4 * 2 * amplitude
    assert c["extrema_per_orbit"] == pytest.approx(4.0, abs=0.6)
    assert c["hf_fraction"] < 0.01
    switching = smooth + 0.001 * (-1.0) ** np.arange(t.size)[:, None]
    c = paper.chattering(t, switching, start=0.0)
    assert c["hf_fraction"] > 0.9
    assert c["extrema_per_orbit"] > 0.9 / h
    assert paper.chattering(t, smooth, start=1.9) is None  # too short a window


# --------------------------------------------------------------------------- #
# the table, the figures and the command line as parts
# --------------------------------------------------------------------------- #
def test_shipped_table_is_rebuilt_from_its_own_numbers():
    """docs/paper: every row and the whole page follow from the JSON's numbers alone.

    The full-mode table (34 rows) exercises every row group with the paper's durations;
    a change to a row's text or verdict shows here without a full reproduction.
    """
    result = json.loads((SHIPPED / "paper_vs_tether_gym.json").read_text())
    rows = table.build_rows(result)
    assert rows == result["table"]
    assert table.markdown(result, rows) == (SHIPPED / "paper_vs_tether_gym.md").read_text()


def test_short_run_table_is_rebuilt_from_its_json(short_run):
    """The same for the shortened run, whose rows read 'n/a (run too short)'."""
    _, out = short_run
    result = json.loads((out / "paper_vs_tether_gym.json").read_text())
    rows = table.build_rows(result)
    assert rows == result["table"]
    assert table.markdown(result, rows) == (out / "paper_vs_tether_gym.md").read_text()
    assert sum(r["verdict"] == table.SHORT for r in rows) >= 10


def test_row_groups_are_in_table_order():
    result = json.loads((SHIPPED / "paper_vs_tether_gym.json").read_text())
    sizes = [len(group(result)) for group in table.ROW_GROUPS]
    assert sum(sizes) == len(result["table"]) and all(n > 0 for n in sizes)
    firsts = [group(result)[0]["quantity"] for group in table.ROW_GROUPS]
    positions = [[r["quantity"] for r in result["table"]].index(q) for q in firsts]
    assert positions == sorted(positions) and positions[0] == 0


def test_draw_writes_the_figures_in_order(short_run):
    _, out = short_run
    result = json.loads((out / "paper_vs_tether_gym.json").read_text())
    assert result["figures"] == [*FIGURES, "fig_extra_swing_scan.png"]
    assert list(figures.FigureInputs._fields) == ["zero", "fig5", "fig6", "fig6_quadrature",
                                                  "scans", "smc_paper", "smc_default"]


def test_add_arguments_and_run_are_the_paper_command(tmp_path, monkeypatch):
    """The agents' command line builds ``evaluate.py paper`` from these two functions."""
    import argparse

    calls = []
    monkeypatch.setattr(paper_cli, "reproduce",
                        lambda out, orbits=None, quick=False: calls.append((out, orbits, quick)))
    parser = paper_cli.add_arguments(argparse.ArgumentParser())
    args = parser.parse_args(["--out", str(tmp_path), "--orbits", "0.5", "--quick"])
    assert paper_cli.run(args) == 0
    assert calls == [(str(tmp_path), 0.5, True)]


# --------------------------------------------------------------------------- #
# the package's shape (issue 23)
# --------------------------------------------------------------------------- #
def _modules():
    return sorted(PAPER_DIR.glob("*.py"))


def _tree(path):
    return ast.parse(path.read_text(), filename=str(path))


@pytest.mark.parametrize("path", _modules(), ids=lambda p: p.name)
def test_no_private_name_of_a_sibling_is_imported(path):
    private = [f"from {'.' * node.level}{node.module or ''} import {alias.name}"
               for node in ast.walk(_tree(path)) if isinstance(node, ast.ImportFrom)
               for alias in node.names if alias.name.startswith("_")]
    assert private == []


@pytest.mark.parametrize("path", _modules(), ids=lambda p: p.name)
def test_functions_are_at_most_60_lines(path):
    long = [f"{node.name}: {node.end_lineno - node.lineno + 1} lines"
            for node in ast.walk(_tree(path))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > 60]
    assert long == []


ALLOWED_SUBPACKAGES = {"common", "baselines", "evaluation"}


@pytest.mark.parametrize("path", _modules(), ids=lambda p: p.name)
def test_paper_imports_only_downhill(path):
    """paper uses common, baselines, evaluation and tether_gym; never training, files, cli."""
    bad = []
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom) and node.level >= 2:
            sub = (node.module or "").split(".")[0]
            if node.level > 2 or sub not in ALLOWED_SUBPACKAGES:
                bad.append(f"{'.' * node.level}{node.module or ''}")
        names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                 [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                 else [])
        for name in names:
            parts = name.split(".")
            if parts[0] == "tether_gym_agents" and (
                    len(parts) < 2 or parts[1] not in ALLOWED_SUBPACKAGES | {"paper"}):
                bad.append(name)
    assert bad == []
