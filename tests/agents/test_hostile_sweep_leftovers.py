"""Leftovers of issue 33's hostile-input sweep, each tried through the command a user runs.

Before (sweep rows in brackets): an agent.json with an infinite action box, an unknown
env argument or a NaN eccentricity loaded and was evaluated (``agent.act_space.high_inf``,
``agent.env.*``); ``normalize: {clip_obs: -1}`` or ``{norm_obs: 3}`` trained
(``config.normalize.*``); a config with NUL bytes ended in yaml's ``ReaderError``
traceback (``config.nul_bytes``); a sweep file of 10^12 grid trials, 1e9 seeds per trial
or 1e12 samples ran out of memory or hung (``sweepfile.*_huge``); a suite's nominal masses
``[1]`` for a 2-tether chain were accepted (``suite.nominal.masses_len``); a NaN in a
run's ``vecnormalize.npz`` failed later inside torch (``resume.vecnorm.nan``); exporting
to an existing file or onto the source gave ``FileExistsError``/``SameFileError``
tracebacks (``export.dest_*``). Now each is one line naming the file, before any work.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.files.cli import main as files_main
from tether_gym_agents.files.safe_format import AGENT_FILE, AgentLoadError
from tether_gym_agents.files.trained import TrainedAgent
from tether_gym_agents.training.checkpoint import load_stats_npz

ENV = "tether_gym/TetherLibration-v2"
TINY = ["--timesteps", "64", "--n-envs", "1", "--no-progress", "--eval-episodes", "1",
        "--eval-freq", "64"]


def _one_line(capsys, prefix: str) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(prefix), err
    return err


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A tiny PPO run folder trained by train.py (safe agent, vecnormalize.npz)."""
    out = tmp_path_factory.mktemp("leftovers") / "run"
    assert train_main(["--algo", "ppo", *TINY, "--checkpoint-freq", "64",
                       "--out", str(out)]) == 0
    assert (out / AGENT_FILE).is_file() and (out / "vecnormalize.npz").is_file()
    return out


def _edited_agent(run, tmp_path, edit):
    agent = tmp_path / "agent"
    shutil.copytree(run / "final_agent" if (run / "final_agent").is_dir() else run, agent,
                    ignore=shutil.ignore_patterns("checkpoints", "eval", "tb"))
    meta = json.loads((agent / AGENT_FILE).read_text())
    edit(meta)
    (agent / AGENT_FILE).write_text(json.dumps(meta))
    return agent


def _high_inf(meta):
    meta["action_space"]["high"] = ["inf"] * len(meta["action_space"]["high"])


def _env_kwarg(key, value):
    def edit(meta):
        meta["env"]["kwargs"][key] = value
    return edit


AGENTS = {
    "action high inf": (_high_inf, r"action_space.high\[0\]='inf'; allowed: a finite"),
    "unknown env kwarg": (_env_kwarg("bogus", 1), r"env.kwargs: unknown argument\(s\) 'bogus'"),
    "eccentricity nan": (_env_kwarg("eccentricity", float("nan")),
                         r"env.kwargs: eccentricity=nan must be finite"),
    "masses of another chain": (_env_kwarg("masses", [1.0]),
                                r"env.kwargs: masses=\[1.0\] must have 2 entries"),
}


@pytest.mark.parametrize("case", list(AGENTS))
def test_agent_json_values_are_refused_naming_file_and_key(run, tmp_path, capsys, case):
    edit, message = AGENTS[case]
    agent = _edited_agent(run, tmp_path, edit)
    with pytest.raises(AgentLoadError, match=f"{agent / AGENT_FILE}: {message}"):
        TrainedAgent.load(agent)
    out = tmp_path / "ev"
    assert evaluate_main([str(agent), "--seeds", "1", "--no-plots", "--out", str(out)]) == 2
    assert str(agent / AGENT_FILE) in _one_line(capsys, "evaluate.py: error:")
    assert not out.exists()


def test_the_agent_as_trained_still_loads(run):
    """The env arguments train.py records pass the env's check."""
    agent = TrainedAgent.load(run)
    assert np.isfinite(agent.predict(np.zeros(agent.observation_space.shape))[0]).all()


@pytest.fixture
def no_training(monkeypatch):
    def refuse(settings):
        raise AssertionError("a hostile input reached training")
    monkeypatch.setattr("tether_gym_agents.cli.train.train", refuse)


@pytest.mark.parametrize("line, message", [
    ("clip_obs: -1.0", "normalize.clip_obs: -1.0 must be a finite number > 0"),
    ("norm_obs: 3", "normalize.norm_obs: 3 must be true or false"),
    ("epsilon: 0", "normalize.epsilon: 0 must be a finite number > 0 and <= 1"),
    ("gamma: 2", "normalize.gamma: 2 must be a number in [0, 1]"),
])
def test_normalize_values_are_checked(tmp_path, capsys, no_training, line, message):
    config = tmp_path / "ppo.yml"
    config.write_text(f"{ENV}:\n  normalize:\n    {line}\n")
    out = tmp_path / "run"
    assert train_main(["--config", str(config), "--out", str(out), *TINY]) == 2
    assert _one_line(capsys, f"train.py: error: {config}: {message}")
    assert not out.exists()


def test_a_config_with_nul_bytes_is_one_line_naming_the_file(tmp_path, capsys, no_training):
    config = tmp_path / "ppo.yml"
    config.write_text(f"{ENV}:\n  n_envs: 1\n\x00\x00")
    assert train_main(["--config", str(config), "--out", str(tmp_path / "run"), *TINY]) == 2
    err = _one_line(capsys, f"train.py: error: config file {config}: not valid YAML:")
    assert "#x0000 is not allowed" in err


SWEEPS = {
    "seeds": ("search: grid\nseeds_per_trial: 1000000000\nparams:\n  gamma: [0.9, 0.99]\n",
              "seeds_per_trial must be an integer in [2, 100], got 1000000000"),
    "grid": ("search: grid\nparams:\n" + "".join(
        f"  policy_kwargs.k{i}: [{', '.join(str(j) for j in range(10))}]\n" for i in range(12)),
        "the grid has 10 x 10 x 10 x 10 x 10 x 10 x 10 x 10 x 10 x 10 x 10 x 10 = "
        "1000000000000 trials; allowed: at most 10000"),
    "samples": ("search: random\nnum_samples: 1000000000000\n"
                "params:\n  gamma: {uniform: [0.9, 0.99]}\n",
                "num_samples must be an integer in [1, 10000], got 1000000000000"),
}


@pytest.mark.parametrize("case", list(SWEEPS))
def test_huge_sweeps_are_refused_before_expanding(tmp_path, capsys, case):
    text, message = SWEEPS[case]
    sweep = tmp_path / "sweep.yml"
    sweep.write_text(text)
    out = tmp_path / "sweep"
    assert train_main(["--algo", "ppo", "--sweep", str(sweep), "--out", str(out),
                       *TINY]) == 2
    assert _one_line(capsys, f"train.py: error: {sweep}: {message}")
    assert not out.exists()


def test_sweep_seeds_option_is_bounded(tmp_path, capsys):
    sweep = tmp_path / "sweep.yml"
    sweep.write_text("search: grid\nparams:\n  gamma: [0.9, 0.99]\n")
    for seeds in ("500", "1000000000"):  # the latter is refused by train.py's own bound
        assert train_main(["--algo", "ppo", "--sweep", str(sweep), "--seeds", seeds,
                           "--out", str(tmp_path / "s"), *TINY[:2]]) == 2
        assert seeds in _one_line(capsys, "train.py: error: --seeds")
    assert not (tmp_path / "s").exists()
    assert train_main(["--algo", "ppo", "--sweep", str(sweep), "--seeds", "500",
                       "--out", str(tmp_path / "s"), *TINY[:2]]) == 2
    assert "seeds per trial must be >= 2 and <= 100" in _one_line(capsys, "train.py: error:")


@pytest.mark.parametrize("scenario, message", [
    ({"nominal": {"masses": [1]}}, "nominal masses=[1] must have 2 entries, got 1"),
    ({"env_kwargs": {"n_bodies": 4}, "nominal": {"masses": [1, 2]}},
     "nominal masses=[1, 2] must have 3 entries, got 2"),
])
def test_suite_nominal_masses_fit_the_scenarios_chain(tmp_path, capsys, scenario, message):
    import yaml

    suite = tmp_path / "suite.yml"
    suite.write_text(yaml.safe_dump({"scenarios": [{"name": "s1", **scenario}]}))
    out = tmp_path / "ev"
    assert evaluate_main(["smc", "--suite", str(suite), "--seeds", "1", "--no-plots",
                          "--out", str(out)]) == 2
    err = _one_line(capsys, "evaluate.py: error:")
    assert str(suite) in err and message in err, err
    assert not out.exists()


def test_suite_nominal_masses_of_the_chain_are_accepted(tmp_path):
    from tether_gym_agents.evaluation.scenarios import load_suite_file

    suite = tmp_path / "suite.yml"
    suite.write_text("scenarios:\n  - {name: a, nominal: {masses: [1, 2]}}\n"
                     "  - {name: b, env_kwargs: {n_bodies: 4}, nominal: {masses: [1, 1, 1]}}\n"
                     "  - {name: c, env_kwargs: {masses: [1, 1, 1]}, "
                     "nominal: {masses: [1, 2, 1]}}\n")
    assert [s.nominal["masses"] for s in load_suite_file(suite)] == [
        (1, 2), (1, 1, 1), (1, 2, 1)]


def _poison(path, key, value):
    with np.load(path) as z:
        arrays = {k: np.asarray(z[k]).copy() for k in z.files}
    arrays[key].flat[0] = value
    np.savez(path, **arrays)


@pytest.mark.parametrize("key, value, message", [
    ("obs_mean", np.nan, r"obs_mean\[0\]=nan; allowed: finite numbers with \|mean\| <= 1e\+06"),
    ("obs_var", -1.0, r"obs_var\[0\]=-1.0; allowed: finite numbers >= 0"),
    ("ret_var", np.inf, r"ret_var\[0\]=inf"),
    ("obs_count", np.nan, r"obs_count=.*nan.*; allowed: a finite number >= 0"),
])
def test_non_finite_statistics_are_refused_naming_the_file(run, tmp_path, key, value,
                                                           message):
    path = tmp_path / "vecnormalize.npz"
    shutil.copyfile(run / "vecnormalize.npz", path)
    _poison(path, key, value)
    with pytest.raises(ValueError, match=f"{path}: {message}"):
        load_stats_npz([], path)


def test_resume_does_not_train_on_nan_statistics(run, tmp_path, capsys):
    """train.py --resume refuses the poisoned final statistics (resume.py then goes back to
    the last checkpoint, saying so); the resumed run's statistics are finite."""
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    _poison(copy / "vecnormalize.npz", "obs_mean", np.nan)
    capsys.readouterr()
    train_main(["--algo", "ppo", "--resume", "--out", str(copy), *TINY[2:],
                "--timesteps", "128", "--checkpoint-freq", "64"])
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Expected parameter loc" not in err, err
    assert f"{copy / 'vecnormalize.npz'}: obs_mean[0]=nan" in err, err
    with np.load(copy / "vecnormalize.npz") as z:
        assert all(np.isfinite(z[k]).all() for k in z.files)


def test_export_to_a_file_or_onto_the_source_is_one_line(run, tmp_path, capsys):
    src = tmp_path / "run"
    shutil.copytree(run, src)
    before = {p: p.stat().st_mtime_ns for p in src.rglob("*")}
    dest = tmp_path / "file"
    dest.write_text("mine")
    assert files_main(["export", str(src), str(dest)]) == 2
    assert f"export destination {dest} is a file" in _one_line(capsys, "agent_files: error:")
    assert dest.read_text() == "mine"
    for same in (src, tmp_path / "." / "run"):
        assert files_main(["export", str(src), str(same)]) == 2
        err = _one_line(capsys, "agent_files: error:")
        assert "is the run folder" in err and "itself" in err, err
    assert {p: p.stat().st_mtime_ns for p in src.rglob("*")} == before
    assert files_main(["export", str(src), str(tmp_path / "shared")]) == 0
    assert (tmp_path / "shared" / AGENT_FILE).is_file()
