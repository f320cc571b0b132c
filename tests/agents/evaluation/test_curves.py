"""evaluate.py curves: every checkpoint of seed runs scored on a suite, with wall times."""

from __future__ import annotations

import json
import math
import re
import shutil

import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.evaluation.curves import (
    Threshold,
    _reached,
    _seed_reached,
    curve_points,
)

TINY = ["--n-envs", "2", "--no-progress", "--eval-freq", "256", "--checkpoint-freq", "256",
        "--eval-episodes", "1", "--timesteps", "512", "--env-kwargs",
        "orbits_per_episode=0.05"]


@pytest.fixture(scope="module")
def two_seeds(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runs") / "ppo"
    for seed in (0, 1):
        assert train_main(["--seed", str(seed), "--out", str(folder / f"seed_{seed}"),
                           *TINY]) == 0
    return folder


@pytest.fixture(scope="module")
def curves_out(two_seeds, tmp_path_factory):
    out = tmp_path_factory.mktemp("curves")
    assert evaluate_main(["curves", str(two_seeds), "--suite", "paper", "--seeds", "2",
                          "--out", str(out)]) == 0
    return out


def test_curves_score_every_common_checkpoint_like_the_benchmark(two_seeds, curves_out):
    out = curves_out
    (curve,) = json.loads((out / "curves.json").read_text())
    steps = [p["steps"] for p in curve["points"]]
    assert steps == sorted(steps) and steps[0] == 256 and len(steps) >= 2
    assert curve["runs"] == 2 and curve["suite"] == "paper"
    for p in curve["points"]:
        assert p["episodes"] == 2 * 2  # 2 runs x 1 scenario x 2 seeds, none trimmed
        assert p["success"] == p["survived"] / p["episodes"]
        assert len(p["wall_time_s"]) == 2 and all(w >= 0 for w in p["wall_time_s"])
        assert len(p["seed_success"]) == len(p["seed_tracking_rms"]) == 2
    for i in (0, 1):  # each seed's wall time grows along its checkpoints
        walls = [p["wall_time_s"][i] for p in curve["points"]]
        assert walls == sorted(walls)
    assert (out / "curves.md").read_text().startswith(str(two_seeds))
    assert (out / "curves.png").is_file()


def test_written_curves_are_read_not_evaluated_again(curves_out, tmp_path, capsys):
    both = tmp_path / "both"
    assert evaluate_main(["curves", str(curves_out), str(curves_out), "--suite", "paper",
                          "--seeds", "2", "--rms", "1e9", "--success", "0",
                          "--out", str(both)]) == 0
    assert "reading its curves.json" in capsys.readouterr().out
    (written,) = json.loads((curves_out / "curves.json").read_text())
    combined = json.loads((both / "curves.json").read_text())
    assert [c["points"] for c in combined] == [written["points"]] * 2
    # the time to threshold is recomputed for the threshold asked now
    # (a tiny run's episodes may all fail: no RMS, never reached)
    first = next((p["steps"] for p in written["points"] if p["tracking_rms"] is not None),
                 None)
    assert (combined[1]["reached"] or {}).get("steps") == first
    assert combined[1]["threshold"] == {"rms": 1e9, "success": 0.0}
    md = (both / "curves.md").read_text()
    assert md.startswith("Time to tracking RMS <= 1e+09 rad at success >= 0")
    assert md.count(f"| ppo | 2 | {written['points'][-1]['steps']} |") == 2
    assert (both / "curves.png").is_file()
    # curves of another suite or number of seeds are not put beside these
    assert evaluate_main(["curves", str(curves_out), "--out", str(tmp_path / "x")]) == 2
    assert "scored on suite 'paper' with 2 seeds" in capsys.readouterr().err


def test_curves_refuse_bad_arguments(tmp_path, capsys):
    for argv, words in ((["curves", str(tmp_path / "none"), "--out", str(tmp_path)],
                         "not a folder of seed runs"),
                        (["curves", str(tmp_path), "--rms", "nan", "--out", str(tmp_path)],
                         "--rms"),
                        (["curves", str(tmp_path), "--success", "2", "--out", str(tmp_path)],
                         "--success")):
        assert evaluate_main(argv) == 2
        assert words in capsys.readouterr().err
    assert evaluate_main(["curves", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "no checkpoint agents" in capsys.readouterr().err


def test_time_to_threshold_is_the_first_point_meeting_both():
    th = Threshold(rms=1e-2, success=0.99)
    points = [{"steps": 1, "tracking_rms": 5e-3, "success": 0.9, "wall_time_s": [10, 20],
               "seed_tracking_rms": [5e-3, 5e-3], "seed_success": [1.0, 0.8]},
              {"steps": 2, "tracking_rms": 2e-2, "success": 1.0, "wall_time_s": [30, 40],
               "seed_tracking_rms": [2e-2, 2e-2], "seed_success": [1.0, 1.0]},
              {"steps": 3, "tracking_rms": 8e-3, "success": 1.0, "wall_time_s": [50, 70],
               "seed_tracking_rms": [8e-3, math.nan], "seed_success": [1.0, 1.0]}]
    assert _reached(points, th) == {"steps": 3, "wall_time_s_median": 60.0,
                                    "wall_time_s_range": [50, 70]}
    assert _seed_reached(points, 0, th) == {"steps": 1, "wall_time_s": 10}
    assert _seed_reached(points, 1, th) is None  # never both, NaN never meets


def test_filtered_curves_score_each_checkpoint_as_filtered_run_does(tmp_path):
    """--filtered: every point is what ``evaluate.py filtered:FOLDER`` gives for that
    checkpoint's seeds as one policy, and the curve is named ``filtered:``."""
    import shutil

    folder = tmp_path / "rate"
    for seed in (0, 1):
        assert train_main(["--seed", str(seed), "--out", str(folder / f"seed_{seed}"), *TINY,
                           "action_mode=rate"]) == 0
    out = tmp_path / "curves"
    assert evaluate_main(["curves", str(folder), "--filtered", "--suite", "paper",
                          "--seeds", "2", "--out", str(out)]) == 0
    (curve,) = json.loads((out / "curves.json").read_text())
    assert curve["policy"] == f"filtered:{folder}"
    assert (out / "curves.md").read_text().startswith(f"filtered:{folder}")
    last = curve["points"][-1]
    step = tmp_path / "last"
    for seed in (0, 1):
        src = folder / f"seed_{seed}" / "checkpoints" / f"agent_{last['steps']}_steps"
        shutil.copytree(src, step / f"seed_{seed}")
    direct = tmp_path / "direct"
    assert evaluate_main([f"filtered:{step}", "--suite", "paper", "--seeds", "2",
                          "--no-plots", "--out", str(direct)]) == 0
    (block,) = json.loads((direct / "results.json").read_text())["policies"].values()
    assert block["kind"] == "hybrid"
    assert last["survived"] == block["survived"] and last["episodes"] == block["n_episodes"]
    if block["tracking_rms"] is None:
        assert last["tracking_rms"] is None
    else:
        assert last["tracking_rms"] == pytest.approx(block["tracking_rms"], rel=1e-12)


def test_filtered_curves_refuse_increment_mode_runs_before_evaluating(two_seeds, tmp_path,
                                                                      capsys):
    out = tmp_path / "curves"
    assert evaluate_main(["curves", str(two_seeds), "--filtered", "--suite", "paper",
                          "--seeds", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(two_seeds) in err and "action_mode='increment'" in err
    assert "tether_curves" not in err  # names the user's folder, not a temporary copy
    assert not out.exists()


def _written_with(curves_out, tmp_path, edit) -> str:
    """A folder holding curves_out's curves.json after ``edit(curves)``."""
    folder = tmp_path / "edited"
    folder.mkdir()
    curves = json.loads((curves_out / "curves.json").read_text())
    edit(curves)
    (folder / "curves.json").write_text(json.dumps(curves))
    return str(folder)


def test_a_curve_without_wall_times_reads_back(curves_out, tmp_path, capsys):
    """A checkpoint that recorded no wall time gives NaN, which curves.json holds as
    null; reading such a file back raised TypeError in the time to threshold."""
    def no_walls(curves):
        for p in curves[0]["points"]:  # each point meets the threshold (a tiny run's
            p["wall_time_s"] = [None, None]  # episodes may all fail: no RMS)
            p.update(tracking_rms=1e-3, success=1.0, seed_tracking_rms=[1e-3, 1e-3],
                     seed_success=[1.0, 1.0])
    folder = _written_with(curves_out, tmp_path, no_walls)
    out = tmp_path / "o"
    assert evaluate_main(["curves", folder, "--suite", "paper", "--seeds", "2", "--rms", "1e9",
                          "--success", "0", "--out", str(out)]) == 0, capsys.readouterr().err
    (curve,) = json.loads((out / "curves.json").read_text())
    assert curve["reached"] == {"steps": 256, "wall_time_s_median": None,
                                "wall_time_s_range": None}
    assert curve["per_seed"] == [{"steps": 256, "wall_time_s": None}] * 2
    assert curve["points"][0]["wall_time_s"] == [None, None]


def _set_point(key, value):
    def edit(curves):
        curves[0]["points"][0][key] = value
    return edit


@pytest.mark.parametrize("edit, message", [
    (lambda c: c[0].pop("runs"), r"curve 0: runs=None; allowed: an integer in \[1, 10000\]"),
    (lambda c: c[0].update(points=[]), r"curve 0: points=\[\]; allowed: a non-empty list"),
    (lambda c: c[0]["points"].append(7), r"curve 0: points\[\d+\]=7; allowed: a mapping"),
    (_set_point("seed_success", [1.0]),
     r"points\[0\].seed_success=\[1.0\]; allowed: a list of 2 numbers or nulls"),
    (_set_point("success", "1"), r"points\[0\].success='1'; allowed: a finite number"),
    (_set_point("steps", -1), r"points\[0\].steps=-1; allowed: an integer >= 0"),
    (_set_point("tracking_rms_ci95", [1.0]), r"points\[0\].tracking_rms_ci95=\[1.0\]"),
])
def test_a_malformed_curves_json_is_one_line_naming_the_key(curves_out, tmp_path, capsys,
                                                            edit, message):
    """Before: KeyError / TypeError tracebacks from the time to threshold."""
    folder = _written_with(curves_out, tmp_path, edit)
    assert evaluate_main(["curves", folder, "--suite", "paper", "--seeds", "2",
                          "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert f"{folder}/curves.json: " in err and re.search(message, err), err


def test_a_deeply_nested_curves_json_is_one_line(tmp_path, capsys):
    """Before: a RecursionError traceback from Python's JSON decoder."""
    (tmp_path / "deep").mkdir()
    (tmp_path / "deep" / "curves.json").write_text("[" * 100_000)
    assert evaluate_main(["curves", str(tmp_path / "deep"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "curves.json is not valid JSON here: nested too deeply" in err, err


@pytest.mark.parametrize("training", [[], {"wall_time_s": [1]}, {"wall_time_s": "x"}, "x"])
def test_a_checkpoint_without_a_usable_wall_time_counts_as_unknown(two_seeds, tmp_path,
                                                                   training):
    """Before: AttributeError or TypeError for a ``training`` entry of another type."""
    run = tmp_path / "ppo"
    shutil.copytree(two_seeds, run)
    agent = run / "seed_0" / "checkpoints" / "agent_256_steps" / "agent.json"
    meta = json.loads(agent.read_text())
    meta["training"] = training
    agent.write_text(json.dumps(meta))
    points = dict(curve_points(run))
    assert math.isnan(points[256][0][1]) and points[256][1][1] >= 0
