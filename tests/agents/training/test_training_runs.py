"""train.py with tiny budgets: short runs, env kwargs, resume bookkeeping, CLI values."""

from __future__ import annotations

import json
import shutil
import time
from collections import Counter

import numpy as np
import pytest
import yaml

from tether_gym_agents.cli.train import main
from tether_gym_agents.files.trained import TrainedAgent
from tether_gym_agents.training import callbacks
from tether_gym_agents.training.config import ConfigError, resolve_env_kwargs, with_schedules

FAST = ["--n-envs", "2", "--no-progress", "--eval-episodes", "1"]
SHORT = ["--env-kwargs", "orbits_per_episode=0.05"]


def _lines(text):
    return [line for line in text.splitlines() if line.strip()]


def test_run_shorter_than_eval_freq_ends_with_evaluation(tmp_path):
    out = tmp_path / "ppo"
    # the packaged config evaluates every 50,000 steps: this run is far shorter
    assert main(["--out", str(out), "--timesteps", "300", *FAST, *SHORT]) == 0
    for name in ("eval/evaluations.npz", "best_model.zip", "agent.json",
                 "learning_curve.png", "final_agent/agent.json"):
        assert (out / name).is_file(), name
    info = json.loads((out / "train_info.json").read_text())
    steps = np.load(out / "eval" / "evaluations.npz")["timesteps"]
    assert list(steps) == [info["num_timesteps"]] and info["status"] == "finished"
    assert TrainedAgent.load(out).path == out  # the best agent, in the safe format


def test_resolve_env_kwargs_user_value_wins():
    config = {"eccentricity_range": [0.0, 0.35], "mass_range": 0.25, "init_theta_range": 0.15,
              "initial_theta": [0.0, 0.0], "disturbance": 0.1}
    kwargs, notes = resolve_env_kwargs(config, {"eccentricity": 0.3, "masses": (1, 2)}, "c.yml")
    assert kwargs == {"init_theta_range": 0.15, "initial_theta": [0.0, 0.0], "disturbance": 0.1,
                      "eccentricity": 0.3, "masses": [1, 2]}
    assert any("clears c.yml's eccentricity_range" in n for n in notes)
    assert any("clears c.yml's mass_range" in n for n in notes)
    kwargs, _ = resolve_env_kwargs(config, {"initial_theta": (0.1, 0.0)}, "c.yml")
    assert "init_theta_range" not in kwargs and kwargs["initial_theta"] == [0.1, 0.0]
    # a range the user types too is kept
    kwargs, _ = resolve_env_kwargs(config, {"eccentricity": 0.1,
                                            "eccentricity_range": (0.0, 0.2)}, "c.yml")
    assert kwargs["eccentricity_range"] == [0.0, 0.2]
    # a config list with equal entries follows n_bodies; an unequal one names its line
    kwargs, _ = resolve_env_kwargs(config, {"n_bodies": 5}, "c.yml")
    assert kwargs["initial_theta"] == [0.0] * 4
    with pytest.raises(ConfigError, match=r"c.yml: env_kwargs masses: \[1.0, 2.0\] has 2 "
                                          r"entries, but n_bodies=4 needs 3"):
        resolve_env_kwargs({"masses": [1.0, 2.0]}, {"n_bodies": 4}, "c.yml")


def test_user_env_kwargs_reach_the_run(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["--out", str(out), "--timesteps", "64", *FAST, "--env-kwargs",
                 "orbits_per_episode=0.05", "eccentricity=0.3", "n_bodies=4"]) == 0
    printed = capsys.readouterr().out
    assert '"eccentricity": 0.3' in printed and "clears" in printed
    text = (out / "config.yml").read_text()
    assert "&id" not in text and "*id" not in text  # no YAML anchors
    env_kwargs = yaml.safe_load(text)["env_kwargs"]
    assert env_kwargs["eccentricity"] == 0.3 and "eccentricity_range" not in env_kwargs
    assert env_kwargs["initial_theta"] == [0.0, 0.0, 0.0]
    agent = TrainedAgent.load(out)
    import gymnasium as gym

    import tether_gym

    env = gym.make(tether_gym.ENV_ID, **env_kwargs)
    assert agent.env_kwargs == env_kwargs
    assert agent.observation_space.shape == env.observation_space.shape != (12,)
    env.close()
    # the env the run trained on draws no e: every reset has e = 0.3
    from tether_gym_agents.training.vec_env import make_sb3_vec_env

    venv = make_sb3_vec_env(4, seed=0, env_kwargs=env_kwargs)
    assert venv.config.eccentricity == 0.3 and venv.config.eccentricity_range is None
    venv.close()


def test_nonuniform_config_list_error_names_the_line(tmp_path, capsys):
    cfg = tmp_path / "c.yml"
    cfg.write_text(yaml.safe_dump({"tether_gym/TetherLibration-v2": {
        "env_kwargs": {"masses": [1.0, 2.0]}}}))
    assert main(["--config", str(cfg), "--out", str(tmp_path / "o"), "--timesteps", "8",
                 "--env-kwargs", "n_bodies=4"]) == 2
    assert f"{cfg}: env_kwargs masses" in capsys.readouterr().err


def test_linear_schedules_in_zoo_notation(tmp_path, capsys):
    """``learning_rate: lin_3e-4`` falls from 3e-4 to 0 over the run; bad ones stop it."""
    schedule = with_schedules({"learning_rate": "lin_3e-4", "gamma": 0.9})
    assert schedule["gamma"] == 0.9
    assert [schedule["learning_rate"](p) for p in (1.0, 0.5, 0.0)] == [3e-4, 1.5e-4, 0.0]
    cfg = tmp_path / "c.yml"
    cfg.write_text(yaml.safe_dump({"tether_gym/TetherLibration-v2": {
        "learning_rate": "lin_1e-3", "clip_range": "lin_0.2", "n_steps": 32,
        "batch_size": 32}}))
    out = tmp_path / "o"
    assert main(["--config", str(cfg), "--out", str(out), "--timesteps", "64", *FAST,
                 *SHORT]) == 0
    saved = yaml.safe_load((out / "config.yml").read_text())["hyperparams"]
    assert saved["learning_rate"] == "lin_1e-3"  # recorded as written
    for bad in ("lin_0", "lin_x", "const_1e-3"):
        cfg.write_text(yaml.safe_dump({"tether_gym/TetherLibration-v2": {"learning_rate": bad}}))
        assert main(["--config", str(cfg), "--out", str(tmp_path / "b"), "--timesteps",
                     "8"]) == 2
        err = capsys.readouterr().err
        assert f"learning_rate: {bad!r} must be a" in err and "'lin_<start>'" in err


@pytest.mark.parametrize("argv, expected", [
    (["--n-envs", "0"], "--n-envs 0: must be an integer >= 1"),
    (["--eval-freq", "-1"], "--eval-freq -1: must be an integer >= 1"),
    (["--checkpoint-freq", "-5"], "--checkpoint-freq -5: must be an integer >= 1"),
    (["--eval-episodes", "0"], "--eval-episodes 0: must be an integer >= 1"),
    (["--timesteps", "0"], "--timesteps 0: must be an integer >= 1"),
    (["--seed", "-1"], "--seed -1: must be an integer in [0, 2147483647]"),
    (["--config", ""], "--config '': must be the path of a YAML file"),
    (["--env-kwargs", "masses=(1,2"], "--env-kwargs 'masses=(1,2': '(1,2' is not a Python "
                                      "literal"),
    (["--env-kwargs", "masses=(1,-2)"], "masses=(1.0, -2.0) must all be > 0"),
    (["--env-kwargs", "n_bodies=x"], "n_bodies must be an int"),
    (["--env-kwargs", "eccentricity"], "each entry must look like key=value"),
])
def test_cli_values_rejected_before_any_work(tmp_path, capsys, argv, expected):
    out = tmp_path / "run"
    t0 = time.perf_counter()
    assert main(["--out", str(out), "--timesteps", "64", *argv]) == 2
    err = capsys.readouterr().err
    assert len(_lines(err)) == 1 and err.startswith("train.py: error: ")
    assert expected in err
    assert not out.exists()  # nothing was written
    assert time.perf_counter() - t0 < 30


def test_out_must_be_a_writable_folder(tmp_path, capsys):
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    assert main(["--out", str(a_file), "--timesteps", "64"]) == 2
    assert f"--out {str(a_file)!r}: is a file" in capsys.readouterr().err
    assert main(["--out", str(a_file / "sub"), "--timesteps", "64"]) == 2
    err = capsys.readouterr().err
    assert f"--out {str(a_file / 'sub')!r}: cannot write there" in err
    assert len(_lines(err)) == 1
    assert main(["--out", "/proc/tether_gym_run", "--timesteps", "64"]) == 2
    assert "cannot write there" in capsys.readouterr().err


def test_a_fresh_run_into_an_earlier_run_is_refused(tmp_path, capsys):
    """Without --resume a second run into a run folder would leave its checkpoints beside
    the first run's, and a later --resume would continue the first run's largest one."""
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, *SHORT, "--eval-freq", "512", "--checkpoint-freq", "128"]
    assert main([*argv, "--timesteps", "512"]) == 0
    files = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256"]) == 2
    err = capsys.readouterr().err
    assert len(_lines(err)) == 1 and err.startswith(f"train.py: error: --out {str(out)!r}: "
                                                    "already holds an earlier training run (")
    assert "checkpoints/agent_128_steps" in err and "continue it with --resume" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == files
    assert main([*argv, "--timesteps", "128", "--resume"]) == 0  # what the message says
    assert json.loads((out / "train_info.json").read_text())["num_timesteps"] > 512
    # a call killed before its first checkpoint leaves at most a best agent.json: the
    # same command starts it over
    for name in ("checkpoints", "final_agent"):
        shutil.rmtree(out / name)
    (out / "final_model.zip").unlink()
    assert (out / "agent.json").is_file()
    assert main([*argv, "--timesteps", "256"]) == 0
    assert json.loads((out / "train_info.json").read_text())["num_timesteps"] == 256  # from 0


class _Killed(Exception):
    pass


def _kill_after_eval_at(monkeypatch, step, sleep_at=None, sleep_s=0.0):
    """Make the evaluation callback die (like a kill) right after evaluating at ``step``."""
    original = callbacks.RunEvalCallback._evaluate

    def evaluate(self):
        result = original(self)
        if sleep_at is not None and self.num_timesteps == sleep_at:
            time.sleep(sleep_s)
        if self.num_timesteps >= step and self.evaluations_timesteps \
                and self.evaluations_timesteps[-1] >= step:
            raise _Killed(step)
        return result

    monkeypatch.setattr(callbacks.RunEvalCallback, "_evaluate", evaluate)


def _tb_scalars(tb_dir):
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader

    seen = Counter()
    for path in tb_dir.rglob("events.out.tfevents.*"):
        for event in EventFileLoader(str(path)).Load():
            for value in event.summary.value:
                seen[(value.tag, event.step)] += 1
    return seen


def test_resume_after_kill_has_no_doubled_steps_and_keeps_wall_time(tmp_path, monkeypatch):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, *SHORT, "--eval-freq", "256", "--checkpoint-freq", "512"]
    monkeypatch.setattr(callbacks, "PROGRESS_EVERY_S", 0.0)
    with monkeypatch.context() as m:
        # evaluations at 256, 512 (checkpoint), 768: killed after the last one
        _kill_after_eval_at(m, 768, sleep_at=512, sleep_s=2.0)
        with pytest.raises(_Killed):
            main([*argv, "--timesteps", "2048"])
    killed = json.loads((out / "train_info.json").read_text())
    assert killed["status"] == "running" and killed["wall_time_s"] >= 2.0
    assert list(np.load(out / "eval" / "evaluations.npz")["timesteps"]) == [256, 512, 768]
    assert max(step for _, step in _tb_scalars(out / "tb")) == 768
    assert main([*argv, "--timesteps", "1024", "--resume"]) == 0
    steps = list(np.load(out / "eval" / "evaluations.npz")["timesteps"])
    assert steps == [256, 512, 768, 1024, 1280, 1536]  # 768 once, from the resumed run
    doubled = {key: n for key, n in _tb_scalars(out / "tb").items() if n > 1}
    assert doubled == {}
    info = json.loads((out / "train_info.json").read_text())
    assert info["num_timesteps"] == 1536 and info["status"] == "finished"
    assert info["wall_time_s"] >= killed["wall_time_s"]  # the killed part is counted


def test_truncated_latest_checkpoint_falls_back(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, *SHORT, "--eval-freq", "512", "--checkpoint-freq", "256"]
    assert main([*argv, "--timesteps", "1024"]) == 0
    # killed mid-save: the final model and the newest checkpoint are cut short
    for path in (out / "final_model.zip", out / "checkpoints" / "model_1024_steps.zip"):
        blob = path.read_bytes()
        path.write_bytes(blob[: len(blob) // 3])
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256", "--resume"]) == 0
    captured = capsys.readouterr()
    assert "skipping" in captured.err and "model_1024_steps.zip" in captured.err
    assert "model_768_steps.zip at step 768" in captured.out
    assert json.loads((out / "train_info.json").read_text())["num_timesteps"] >= 768 + 256
