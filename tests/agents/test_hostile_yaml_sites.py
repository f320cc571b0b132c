"""Hostile YAML files given to evaluate.py --suite, train.py --sweep and train.py gpu --config:
one error line naming the file, exit code 2, no hang, before any work."""

from __future__ import annotations

import os
import time

import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main

BOMB = ("scenarios:\n- name: a\n  description: &a [x, x, x, x, x, x, x, x, x]\n"
        + "".join(f"  d{k}: &{chr(98 + k)} [" + ", ".join([f"*{chr(97 + k)}"] * 9) + "]\n"
                  for k in range(8)))


def _hostile(tmp_path, kind: str):
    path = tmp_path / f"{kind}.yml"
    if kind == "bomb":
        path.write_text(BOMB)
    elif kind == "deep":
        path.write_text("[" * 50_000)
    elif kind == "binary":
        path.write_bytes(b"\xff\xfe\x00\x81binary")
    elif kind == "big":
        path.write_text("# padding\n" * 950_000)  # 9.5 MB
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "zero":
        path.symlink_to("/dev/zero")
    return path


KINDS = {"bomb": "anchors and aliases", "deep": "deeper than 50", "binary": "not UTF-8",
         "big": "larger than", "fifo": "not a regular file (a FIFO)",
         "zero": "not a regular file (a device)"}


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_evaluate_suite_file(tmp_path, capsys, kind):
    path = _hostile(tmp_path, kind)
    start = time.perf_counter()
    code = evaluate_main(["smc", "--suite", str(path), "--seeds", "1", "--no-plots",
                          "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert time.perf_counter() - start < 5
    assert code == 2 and KINDS[kind] in err and f"suite file {path}" in err, err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_train_sweep_file(tmp_path, capsys, kind):
    path = _hostile(tmp_path, kind)
    start = time.perf_counter()
    code = train_main(["--sweep", str(path), "--timesteps", "64",
                       "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert time.perf_counter() - start < 5
    assert code == 2 and KINDS[kind] in err and f"--sweep file {path}" in err, err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("kind", ["bomb", "deep", "fifo", "zero"])
def test_train_gpu_config(tmp_path, capsys, kind):
    pytest.importorskip("torch")
    path = _hostile(tmp_path, kind)
    code = train_main(["gpu", "--config", str(path), "--device", "cpu",
                       "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and KINDS[kind] in err and str(path) in err, err
    assert len(err.strip().splitlines()) == 1


def test_suite_nominal_values_are_checked_when_read(tmp_path, capsys):
    suite = tmp_path / "nom.yml"
    for nominal, message in [("{masses: abc}", "nominal masses='abc' must be a sequence"),
                             ("{masses: [1.0, -2.0]}", "must all be > 0"),
                             ("{eccentricity: 1.5}", "eccentricity=1.5 is outside"),
                             ("{accel_limit: .nan}", "accel_limit"),
                             ("{reel_time_constant: x}", "reel_time_constant")]:
        suite.write_text(f"scenarios:\n- name: a\n  nominal: {nominal}\n")
        code = evaluate_main(["smc", "--suite", str(suite), "--seeds", "1", "--no-plots",
                              "--out", str(tmp_path / "out")])
        err = capsys.readouterr().err
        assert code == 2 and f"suite file {suite}, scenario 0 (a): nominal" in err, err
        assert message in err and len(err.strip().splitlines()) == 1
    suite.write_text("scenarios:\n- name: a\n  description: [1, 2]\n")
    assert evaluate_main(["smc", "--suite", str(suite), "--out", str(tmp_path / "o")]) == 2
    assert "'description' must be a string" in capsys.readouterr().err


def test_scenario_of_user_code_checks_its_nominal_model():
    from tether_gym_agents.evaluation.scenarios import Scenario

    with pytest.raises(ValueError, match="scenario 's': nominal masses='abc' must be"):
        Scenario("s", "", {}, {"masses": "abc"})
    with pytest.raises(ValueError, match="scenario 's': nominal must be a mapping"):
        Scenario("s", "", {}, {"mass": (1.0, 2.0)})
    assert Scenario("s", "", {}, {"masses": (1.0, 2.0)}).for_bodies(4).nominal == {
        "masses": (1.0, 1.0, 1.0)}
