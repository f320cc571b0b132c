"""evaluate.py / train.py refuse bad output folders and non-file policies in one line, and
evaluate.py without --out writes a new folder per call (issue 33)."""

from __future__ import annotations

import json
import os

import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main

TINY = ["--seeds", "1", "--no-plots", "--suite", "paper", "--env-kwargs",
        "orbits_per_episode=0.05"]


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize("argv", [["smc", *TINY, "--out", ""], ["paper", "--out", ""],
                                  ["--paper", "--out", " "],
                                  ["curves", ".", "--out", ""]])
def test_evaluate_empty_out_is_refused(tmp_path, capsys, monkeypatch, argv):
    monkeypatch.chdir(tmp_path)
    assert evaluate_main(argv) == 2
    err = _one_line(capsys)
    assert "--out" in err and "is empty" in err
    assert list(tmp_path.iterdir()) == []  # nothing written into the current folder


def test_train_empty_out_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for extra in ([], ["--seeds", "2"]):
        assert train_main(["--timesteps", "64", "--out", "", *extra]) == 2
        assert "--out ''" in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_paper_out_that_is_a_file(tmp_path, capsys):
    existing = tmp_path / "notes.txt"
    existing.write_text("mine")
    assert evaluate_main(["paper", "--out", str(existing), "--quick"]) == 2
    err = _one_line(capsys)
    assert err.startswith("evaluate.py paper: error: --out") and "is a file" in err
    assert existing.read_text() == "mine"


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
@pytest.mark.parametrize("policy", ["/dev/zero", "handover:/dev/zero", "fifo"])
def test_special_file_as_policy(tmp_path, capsys, monkeypatch, policy):
    monkeypatch.chdir(tmp_path)
    os.mkfifo("fifo")
    assert evaluate_main([policy, *TINY, "--out", str(tmp_path / "o")]) == 2
    err = _one_line(capsys)
    assert "is not a regular file or an agent folder" in err and "does not exist" not in err
    assert not (tmp_path / "o").exists()


def test_default_out_is_a_new_folder_per_call(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert evaluate_main(["smc", *TINY]) == 0
    assert evaluate_main(["smc", *TINY]) == 0
    out = capsys.readouterr().out
    folders = sorted((tmp_path / "runs" / "eval").iterdir())
    assert len(folders) == 2 and all((f / "results.json").is_file() for f in folders)
    for folder in folders:  # each call says where its results went
        assert f"results: {folder.relative_to(tmp_path)}/results.json" in out
    # a failing call leaves no empty folder behind
    assert evaluate_main(["no_such_policy", *TINY]) == 2
    assert len(list((tmp_path / "runs" / "eval").iterdir())) == 2


def test_explicit_out_is_written_over_and_says_so(tmp_path, capsys):
    out = tmp_path / "eval"
    assert evaluate_main(["smc", *TINY, "--out", str(out)]) == 0
    assert "replacing" not in capsys.readouterr().out
    assert evaluate_main(["zero", *TINY, "--out", str(out)]) == 0
    assert f"--out {out}: replacing the results of an earlier evaluation" in \
        capsys.readouterr().out
    assert list(json.loads((out / "results.json").read_text())["policies"]) == ["zero"]


def test_library_evaluate_refuses_an_empty_out(tmp_path, monkeypatch):
    from tether_gym_agents import evaluate

    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match="out '' is empty"):
        evaluate(["smc"], "paper", 1, out="", plots=False, log=None)
    assert list(tmp_path.iterdir()) == []
