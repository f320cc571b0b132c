"""train.py --sweep: the sweep file, trial expansion, ranking by the median over seeds."""

from __future__ import annotations

import csv
import math
import statistics
import sys

import numpy as np
import pytest
import yaml

from tether_gym_agents.cli.train import main
from tether_gym_agents.training.config import ConfigError
from tether_gym_agents.training.sweep import (
    Search,
    apply_overrides,
    expand_trials,
    final_eval_return,
    load_sweep,
    rank_trials,
    write_table,
)

TINY = ["--n-envs", "2", "--eval-freq", "256", "--checkpoint-freq", "512", "--eval-episodes",
        "1", "--env-kwargs", "orbits_per_episode=0.05"]


def _sweep_file(tmp_path, doc, name="sweep.yml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc) if isinstance(doc, dict) else doc)
    return path


def test_grid_expands_in_file_order(tmp_path):
    spec = load_sweep(_sweep_file(tmp_path, {"params": {
        "learning_rate": [1e-4, 3e-4], "policy_kwargs.net_arch": {"values": [[8], [16, 16]]}}}))
    assert spec.search is Search.GRID and spec.seeds_per_trial == 3
    assert expand_trials(spec) == [
        {"learning_rate": 1e-4, "policy_kwargs.net_arch": [8]},
        {"learning_rate": 1e-4, "policy_kwargs.net_arch": [16, 16]},
        {"learning_rate": 3e-4, "policy_kwargs.net_arch": [8]},
        {"learning_rate": 3e-4, "policy_kwargs.net_arch": [16, 16]}]


def test_random_draws_are_reproducible_and_in_range(tmp_path):
    doc = {"search": "random", "num_samples": 50, "sample_seed": 7, "params": {
        "ent_coef": {"uniform": [0.0, 0.01]}, "clip_range": {"loguniform": [0.05, 0.3]},
        "n_epochs": {"randint": [5, 6]}, "gamma": [0.99, 0.995]}}
    spec = load_sweep(_sweep_file(tmp_path, doc))
    trials = expand_trials(spec)
    assert trials == expand_trials(load_sweep(_sweep_file(tmp_path, doc, "again.yml")))
    assert len(trials) == 50
    assert all(0.0 <= t["ent_coef"] <= 0.01 and 0.05 <= t["clip_range"] <= 0.3 for t in trials)
    assert {t["n_epochs"] for t in trials} == {5, 6}  # randint includes both ends
    assert {t["gamma"] for t in trials} == {0.99, 0.995}
    logs = np.log([t["clip_range"] for t in trials])  # log-uniform: uniform in log space
    assert abs(np.median(logs) - np.log(np.sqrt(0.05 * 0.3))) < 0.4


@pytest.mark.parametrize(("doc", "message"), [
    ({"seeds_per_trial": 1, "params": {"gamma": [0.9]}}, "seeds_per_trial must be >= 2"),
    ({"params": {"gamma": [0.9]}, "seed": 3}, r"unknown key\(s\) \['seed'\]"),
    ({"search": "bayes", "params": {"gamma": [0.9]}}, "search must be one of"),
    ({"params": {"gamma": {"uniform": [0.9, 0.99]}}}, "which a grid cannot enumerate"),
    ({"search": "random", "params": {"lr": {"loguniform": [0.0, 1.0]}}}, "0 < low < high"),
    ({"search": "random", "params": {"n": {"randint": [5.5, 9]}}}, "integers"),
    ({"params": {"gamma": {"normal": [0, 1]}}}, "must be a list of values or one of"),
    ({"params": {}}, "params must map"),
    ({"asha": {"rungs": 3}, "params": {"gamma": [0.9]}}, "asha must be a mapping"),
    ("params: {gamma: !!python/object/apply:os.system [echo hi]}\n", "not valid YAML"),
])
def test_bad_sweep_files(tmp_path, doc, message):
    with pytest.raises(ConfigError, match=message):
        load_sweep(_sweep_file(tmp_path, doc))


def test_overrides_reach_into_mappings():
    base = {"gamma": 0.9, "policy_kwargs": {"net_arch": [64, 64], "log_std_init": -2.0}}
    out = apply_overrides(base, {"policy_kwargs.net_arch": [8], "env_kwargs.disturbance": 0.0})
    assert out == {"gamma": 0.9, "policy_kwargs": {"net_arch": [8], "log_std_init": -2.0},
                   "env_kwargs": {"disturbance": 0.0}}
    assert base["policy_kwargs"]["net_arch"] == [64, 64]  # the base is not changed
    with pytest.raises(ConfigError, match="gamma is 0.9, not a mapping"):
        apply_overrides(base, {"gamma.x": 1})


def test_rank_by_median_not_mean(tmp_path):
    # a: one lucky seed lifts the mean (35) over b's (12), but b's median is higher
    trials = [{"name": "a", "params": {"x": 1}, "returns": [0.0, 100.0, 5.0]},
              {"name": "b", "params": {"x": 2}, "returns": [10.0, 12.0, 14.0]},
              {"name": "c", "params": {"x": 3}, "returns": [50.0, float("nan"), 60.0]}]
    ranked = rank_trials(trials)
    assert [r["name"] for r in ranked] == ["b", "a", "c"]
    assert ranked[0]["median"] == 12.0 and ranked[1]["median"] == 5.0
    assert ranked[1]["mean"] == 35.0 and math.isnan(ranked[2]["median"])
    text = write_table(ranked, tmp_path, ["x"])
    assert text.splitlines()[2].startswith("| rank | trial | x | median return")
    with open(tmp_path / "sweep_results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["rank"], r["trial"], r["x"], r["median return"]) for r in rows] == [
        ("1", "b", "2", "12"), ("2", "a", "1", "5"), ("3", "c", "3", "nan")]


def test_final_eval_return(tmp_path):
    run = tmp_path / "run"
    assert math.isnan(final_eval_return(run))
    (run / "eval").mkdir(parents=True)
    np.savez(run / "eval" / "evaluations.npz", timesteps=np.array([10, 20]),
             results=np.array([[1.0, 3.0], [5.0, 9.0]]), ep_lengths=np.ones((2, 2)))
    assert final_eval_return(run) == 7.0  # the mean of the last evaluation


def test_sweep_cli_errors(tmp_path, capsys, monkeypatch):
    path = _sweep_file(tmp_path, {"params": {"env_kwargs.disturbance": [0.0, 0.1]}})
    assert main(["--sweep", str(path), "--env-kwargs", "disturbance=0.2", "--out",
                 str(tmp_path / "o")]) == 2
    assert "--env-kwargs sets ['env_kwargs.disturbance']" in capsys.readouterr().err
    bad_key = _sweep_file(tmp_path, {"params": {"learning_rat": [0.1, 0.2]}}, "k.yml")
    assert main(["--sweep", str(bad_key), "--out", str(tmp_path / "k")]) == 2
    assert "learning_rat" in capsys.readouterr().err
    assert main(["--sweep", str(path), "--seeds", "1", "--out", str(tmp_path / "s")]) == 2
    assert "seeds per trial must be >= 2" in capsys.readouterr().err
    monkeypatch.setitem(sys.modules, "optuna", None)
    opt = _sweep_file(tmp_path, {"search": "optuna", "params": {"gamma": [0.9, 0.99]}}, "o.yml")
    assert main(["--sweep", str(opt), "--out", str(tmp_path / "opt")]) == 2
    assert "pip install optuna" in capsys.readouterr().err


@pytest.mark.slow
def test_two_configs_two_seeds_ranked_by_median(ray_session, tmp_path, capsys):
    sweep = _sweep_file(tmp_path, {"seeds_per_trial": 2, "timesteps": 1024, "params": {
        "learning_rate": [1.0e-6, 3.0e-3], "n_steps": [128]}})
    out = tmp_path / "sweep"
    argv = ["--algo", "ppo", "--sweep", str(sweep), "--out", str(out), *TINY]
    assert main(argv) == 0
    medians = {}
    for trial, lr in (("trial_000", 1.0e-6), ("trial_001", 3.0e-3)):
        cfg = yaml.safe_load((out / trial / "seed_1" / "config.yml").read_text())
        assert cfg["hyperparams"]["learning_rate"] == lr and cfg["seed"] == 1
        returns = [final_eval_return(out / trial / f"seed_{s}") for s in (0, 1)]
        assert not any(math.isnan(r) for r in returns)
        medians[trial] = statistics.median(returns)
    assert medians["trial_000"] != medians["trial_001"]  # the learning rate made a difference
    with open(out / "sweep_results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["trial"] for r in rows] == sorted(medians, key=medians.get, reverse=True)
    assert [float(r["median return"]) for r in rows] == pytest.approx(
        sorted(medians.values(), reverse=True), rel=1e-3)
    assert (out / "sweep_results.md").read_text().count("| trial_00") == 2
    capsys.readouterr()
    assert main(argv) == 0  # a rerun trains nothing and writes the same table
    assert capsys.readouterr().out.count("already finished") == 4


@pytest.mark.slow
def test_optuna_asha_sweep(ray_session, tmp_path, capsys):
    pytest.importorskip("optuna")
    sweep = _sweep_file(tmp_path, {
        "search": "optuna", "seeds_per_trial": 2, "num_samples": 2, "timesteps": 512,
        "asha": {"chunks": 2}, "params": {"learning_rate": {"loguniform": [1.0e-5, 1.0e-2]},
                                          "n_steps": [128]}})
    out = tmp_path / "opt"
    assert main(["--algo", "ppo", "--sweep", str(sweep), "--out", str(out), *TINY]) == 0
    trials = sorted(out.glob("trial_*"))
    assert len(trials) == 2
    with open(out / "sweep_results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 2
    for row in rows:  # every trial row is the median of its own seeds' final evaluations
        trial = out / row["trial"].split()[0]
        assert (trial / "seed_0" / "train_info.json").is_file()
        returns = [final_eval_return(trial / f"seed_{s}") for s in (0, 1)]
        assert float(row["median return"]) == pytest.approx(statistics.median(returns), rel=1e-3)


def test_trials_are_trained_from_records(tmp_path, capsys, monkeypatch):
    """Each trial's settings are resolved once from its hyperparams.yml; its seeds are
    records derived from them, given to the training function (here a fake)."""
    from tether_gym_agents.files.run_folder import write_evaluations, write_train_info
    from tether_gym_agents.training import fanout, sweep
    from tether_gym_agents.training.settings import TrainSettings

    calls = []

    def fake_train(settings):
        calls.append(settings)
        score = settings.hyperparams["learning_rate"] * 1000 + settings.seed
        write_evaluations(settings.out, {"timesteps": np.array([settings.timesteps]),
                                         "results": np.array([[score]]),
                                         "ep_lengths": np.ones((1, 1))})
        write_train_info(settings.out, {"num_timesteps": settings.timesteps, "wall_time_s": 0.1})

    monkeypatch.setattr(fanout, "train", fake_train)
    real_jobs, real_resolve, resolved = sweep.run_jobs, sweep.resolve_settings, []
    monkeypatch.setattr(sweep, "run_jobs", lambda jobs, **kw: real_jobs(jobs, **{
        **kw, "use_ray": False}))
    monkeypatch.setattr(sweep, "resolve_settings",
                        lambda options: resolved.append(options) or real_resolve(options))
    path = _sweep_file(tmp_path, {"seeds_per_trial": 2, "timesteps": 64,
                                  "params": {"learning_rate": [1.0e-3, 2.0e-3]}})
    out = tmp_path / "sw"
    assert main(["--sweep", str(path), "--out", str(out), "--env-kwargs",
                 "orbits_per_episode=0.05"]) == 0
    assert len(resolved) == 2  # once per trial
    assert [(s.hyperparams["learning_rate"], s.seed) for s in calls] == [
        (1.0e-3, 0), (1.0e-3, 1), (2.0e-3, 0), (2.0e-3, 1)]
    for settings in calls:
        trial = out / f"trial_00{int(settings.hyperparams['learning_rate'] * 1000) - 1}"
        assert isinstance(settings, TrainSettings)
        assert settings.out == trial / f"seed_{settings.seed}" and settings.timesteps == 64
        assert settings.options.config == str(trial / "hyperparams.yml")
        assert settings.env_kwargs["orbits_per_episode"] == 0.05
        config_at = settings.command.index("--config") + 1
        assert settings.command[config_at] == str(trial / "hyperparams.yml")
    with open(out / "sweep_results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["trial"], r["median return"]) for r in rows] == [("trial_001", "2.5"),
                                                                ("trial_000", "1.5")]


@pytest.mark.parametrize("text", ['{"params": {"learning_rate": 0.00', "[" * 100_000])
def test_a_damaged_trial_record_is_one_line(tmp_path, capsys, monkeypatch, text):
    """A trial.json cut short (or forged 100k levels deep) was a JSONDecodeError (or
    RecursionError) traceback before any trial ran; now one line naming the record."""
    from tether_gym_agents.training import fanout, sweep

    monkeypatch.setattr(fanout, "train", lambda settings: pytest.fail("trained"))
    monkeypatch.setattr(sweep, "run_jobs", lambda jobs, **kw: pytest.fail("ran jobs"))
    path = _sweep_file(tmp_path, {"seeds_per_trial": 2, "timesteps": 64,
                                  "params": {"learning_rate": [1.0e-3]}})
    out = tmp_path / "sw"
    (out / "trial_000").mkdir(parents=True)
    record = out / "trial_000" / "trial.json"
    record.write_text(text)
    assert main(["--sweep", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"train.py: error: {record} is not valid JSON"), err
    assert f"the trial record is damaged: remove {out / 'trial_000'}" in err, err


def test_a_damaged_evaluation_file_ranks_as_no_return(tmp_path, capsys):
    """Before: the DamagedFileError ended the ranking of every trial with a traceback."""
    run = tmp_path / "seed_0"
    (run / "eval").mkdir(parents=True)
    (run / "eval" / "evaluations.npz").write_bytes(b"cut short")
    assert math.isnan(final_eval_return(run))
    err = capsys.readouterr().err
    assert f"{run / 'eval' / 'evaluations.npz'}: damaged" in err
    assert err.rstrip().endswith("counted as no return")
