"""Issue 33 follow-ups on ``evaluate.py`` (its ``main(argv)``) and the paper command: a
refused agent leaves no output folder behind, ``--out`` of the paper command is checked
before any study, ``--seeds`` says what it counts, a device is named as such."""

from __future__ import annotations

import json

import pytest

from tether_gym_agents.cli.evaluate import main
from tether_gym_agents.evaluation import registry
from tether_gym_agents.paper import cli as paper_cli


def _refused_agent(tmp_path):
    """An agent folder whose ``agent.json`` is refused when it is loaded."""
    bad = tmp_path / "bad_agent"
    bad.mkdir()
    (bad / "agent.json").write_text(json.dumps({"algo": "ppo"}))
    (bad / "policy.safetensors").write_bytes(b"x")
    return bad


def test_a_refused_agent_leaves_no_out_folder(tmp_path, capsys):
    """Before: exit 2, but ``--out`` had been made first and stayed behind, empty."""
    out = tmp_path / "new_results"
    assert main([str(_refused_agent(tmp_path)), "--out", str(out), "--seeds", "1",
                 "--no-plots"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("evaluate.py: error:") and "agent.json" in err
    assert len(err.splitlines()) == 1
    assert not out.exists()


def test_a_refused_agent_leaves_no_default_folder(tmp_path, monkeypatch):
    """Without --out: no new runs/eval/<stamp>/ folder is left behind either."""
    monkeypatch.chdir(tmp_path)
    assert main([str(_refused_agent(tmp_path)), "--seeds", "1", "--no-plots"]) == 2
    assert not (tmp_path / "runs" / "eval").exists() \
        or not any((tmp_path / "runs" / "eval").iterdir())


def test_a_device_as_policy_is_named(capsys):
    """``/dev/zero`` as a policy: one line saying it is not a regular file or a folder."""
    assert main(["/dev/zero", "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert "/dev/zero is not a regular file or an agent folder" in err


@pytest.mark.parametrize("command", [["bench"], ["curves"]])
def test_seeds_help_says_what_it_counts(command, capsys):
    """Before: "episodes per scenario and run", nothing against train.py's --seeds."""
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "episodes per scenario and policy (env seeds --seed ... --seed+K-1" in text
    assert "not train.py's --seeds (training runs)" in text


def _no_study(*args, **kwargs):
    raise AssertionError("the paper's studies ran although --out is refused")


@pytest.mark.parametrize("how", ["a file", "empty"])
def test_paper_out_checked_before_any_study(tmp_path, monkeypatch, capsys, how):
    """Before: ``python -m tether_gym_agents.paper.cli --out FILE`` ended in a
    FileExistsError traceback; ``--out ""`` ran the studies to write into the current
    folder."""
    monkeypatch.setattr(paper_cli, "reproduce", _no_study)
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "results.txt"
    out.write_text("not a folder")
    value = str(out) if how == "a file" else ""
    assert paper_cli.main(["--out", value, "--quick"]) == 2
    assert main(["paper", "--out", value, "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("evaluate.py paper: error: --out") for e in err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.txt"]


def test_registered_policies_is_gone():
    """It had no caller (issue 33); the registry is read through resolve_policy."""
    assert not hasattr(registry, "registered_policies")
    assert "registered_policies" not in registry.__all__


@pytest.mark.parametrize("prefix", ["", "handover:"])
def test_a_name_too_long_for_a_path_is_one_short_line(prefix, capsys):
    """Before (sweep row eval.policy.long): ``OSError: [Errno 36] File name too long``
    traceback from ``Path(name).exists()`` in the registry."""
    name = prefix + "p" * 5000
    assert main([name, "--seeds", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("evaluate.py: error: policy") and "5000 characters" in err
    assert len(err.splitlines()) == 1 and len(err) < 400
    with pytest.raises(ValueError, match="unknown policy .*5000 characters"):
        registry.resolve_policy("q" * 5000)  # the library call: no OSError either


def test_each_agent_is_loaded_once(tmp_path, monkeypatch):
    """Loading every agent before --out is made does not load it a second time for the
    evaluation (the specs evaluate.py loaded are passed to ``benchmark.evaluate`` as
    they are): one ``TrainedAgent.load`` per run folder."""
    from tether_gym_agents.files.trained import TrainedAgent

    calls = []
    real = TrainedAgent.load.__func__

    def counted(cls, path, *args, **kwargs):
        calls.append(path)
        return real(cls, path, *args, **kwargs)

    monkeypatch.setattr(TrainedAgent, "load", classmethod(counted))
    runs = registry.resolve_policy("ppo_fast").n_runs
    assert main(["smc", "ppo_fast", "--suite", "paper", "--seeds", "1", "--no-plots",
                 "--env-kwargs", "orbits_per_episode=0.2", "--out",
                 str(tmp_path / "out")]) == 0
    assert len(calls) == runs


def test_curves_error_leaves_no_out_folder(tmp_path, capsys):
    """Before: ``evaluate.py curves`` made --out first; a folder without checkpoint agents
    ended in exit 2 with the new --out left behind, empty. An --out that was there stays."""
    runs = _refused_agent(tmp_path)
    out = tmp_path / "curves_out"
    assert main(["curves", str(runs), "--seeds", "1", "--out", str(out)]) == 2
    assert "no checkpoint agents" in capsys.readouterr().err
    assert not out.exists()
    out.mkdir()
    assert main(["curves", str(runs), "--seeds", "1", "--out", str(out)]) == 2
    assert out.is_dir()
