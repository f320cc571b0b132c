"""Faults of a training run (issue 24): resumes that change flags, damaged or cut files,
killed wall time, and the final evaluation after the last update. Tiny budgets, in-process."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import stable_baselines3.common.callbacks as sb3_callbacks
import stable_baselines3.common.evaluation as sb3_evaluation
from stable_baselines3.common.base_class import BaseAlgorithm

from tether_gym_agents.cli.train import main
from tether_gym_agents.files import run_folder as rf
from tether_gym_agents.training import callbacks
from tether_gym_agents.training.run import train
from tether_gym_agents.training.settings import TrainOptions, resolve_settings

FAST = ["--n-envs", "2", "--no-progress", "--env-kwargs", "orbits_per_episode=0.05"]


class _Killed(Exception):
    pass


def _npz(out):
    with np.load(out / "eval" / "evaluations.npz") as data:
        return {k: data[k] for k in data.files}


def test_resume_with_other_eval_episodes_continues_the_history(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, "--eval-freq", "256", "--checkpoint-freq", "256"]
    assert main([*argv, "--timesteps", "512", "--eval-episodes", "1"]) == 0
    # (rollouts of 2 x 256 steps: the evaluation due at the end of each call's last
    # rollout comes after its update)
    assert main([*argv, "--timesteps", "512", "--eval-episodes", "2", "--resume"]) == 0
    data = _npz(out)
    assert list(data["timesteps"]) == [256, 512, 768, 1024]
    assert list(data["episodes"]) == [1, 1, 2, 2]
    assert np.isnan(data["results"][0, 1]) and np.isfinite(data["results"][2]).all()
    # and back to the original flags: the mixed history continues again
    assert main([*argv, "--timesteps", "512", "--eval-episodes", "1", "--resume"]) == 0
    data = _npz(out)
    assert list(data["timesteps"]) == [256, 512, 768, 1024, 1280, 1536]
    assert list(data["episodes"]) == [1, 1, 2, 2, 1, 1]
    assert "Traceback" not in capsys.readouterr().err
    assert (out / "learning_curve.png").stat().st_size > 0


@pytest.mark.parametrize("damage", ["cut", "timesteps_only"])
def test_damaged_evaluations_are_reported_and_set_aside(tmp_path, capsys, damage):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, "--eval-episodes", "1", "--eval-freq", "256",
            "--checkpoint-freq", "256"]
    assert main([*argv, "--timesteps", "512"]) == 0
    path = out / "eval" / "evaluations.npz"
    if damage == "cut":  # what an in-place write killed halfway leaves
        blob = path.read_bytes()
        path.write_bytes(blob[: len(blob) // 2])
    else:  # what today's crash of a resume with another --eval-episodes left
        np.savez(path, timesteps=np.array([256, 512]))
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256", "--resume"]) == 0
    err = capsys.readouterr().err
    assert f"{path}: damaged" in err and "evaluations.npz.damaged" in err
    assert list(_npz(out)["timesteps"]) == [1024]  # one rollout of 2 x 256 steps
    assert (out / "eval" / "evaluations.npz.damaged").is_file()


def test_damaged_train_info_is_reported(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, "--eval-episodes", "1", "--checkpoint-freq", "256"]
    assert main([*argv, "--timesteps", "256"]) == 0
    (out / "train_info.json").write_text('{"num_timesteps": 2')
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256", "--resume"]) == 0
    assert f"{out / 'train_info.json'} is damaged" in capsys.readouterr().err
    assert rf.trained_steps(out) == 512


def test_a_kill_during_a_save_leaves_no_cut_file(tmp_path, monkeypatch, capsys):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, "--eval-episodes", "1", "--eval-freq", "10000",
            "--checkpoint-freq", "256"]
    original = BaseAlgorithm.save

    def save_then_die(self, path, *args, **kwargs):
        original(self, path, *args, **kwargs)
        if "512" in str(path):  # the checkpoint at step 512: cut short, then killed
            with open(path, "r+b") as fh:
                fh.truncate(100)
            raise _Killed(path)

    with monkeypatch.context() as m:
        m.setattr(BaseAlgorithm, "save", save_then_die)
        with pytest.raises(_Killed):
            main([*argv, "--timesteps", "1024"])
    names = sorted(p.name for p in (out / "checkpoints").iterdir())
    # the checkpoint at 256 is whole, with its safe agent folder (written after the model)
    assert names == ["agent_256_steps", "model_256_steps.zip", "model_vecnormalize_256_steps.npz",
                     "model_vecnormalize_256_steps.pkl", "model_vecnormalize_512_steps.npz",
                     "model_vecnormalize_512_steps.pkl"]
    assert not list(out.rglob(".tmp-*"))
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256", "--resume"]) == 0
    captured = capsys.readouterr()
    assert "model_256_steps.zip at step 256" in captured.out and "skipping" not in captured.err
    assert rf.trained_steps(out) == 256 + 1024  # one rollout of 2 x 512 steps


def test_a_kill_during_an_evaluation_write_keeps_the_old_history(tmp_path, monkeypatch):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST, "--eval-episodes", "1", "--eval-freq", "256",
            "--checkpoint-freq", "256"]
    original = np.savez
    calls = []

    def savez_then_die(file, *args, **kwds):
        calls.append(1)
        if len(calls) < 2:
            return original(file, *args, **kwds)
        if isinstance(file, str) and not file.endswith(".npz"):
            file += ".npz"  # as numpy names it
        with open(file, "wb") if isinstance(file, str) else _same(file) as fh:
            fh.write(b"PK\x03\x04 cut")
        raise _Killed("savez")

    monkeypatch.setattr(np, "savez", savez_then_die)
    with pytest.raises(_Killed):
        main([*argv, "--timesteps", "1024"])
    monkeypatch.setattr(np, "savez", original)
    assert list(_npz(out)["timesteps"]) == [256]
    assert not list(out.rglob(".tmp-*"))


class _same:
    def __init__(self, fh):
        self.fh = fh

    def __enter__(self):
        return self.fh

    def __exit__(self, *exc):
        return False


def test_wall_time_of_a_call_killed_before_its_first_rewrite_counts(tmp_path, monkeypatch):
    out = tmp_path / "run"
    base = dict(out=str(out), n_envs=2, no_progress=True, eval_episodes=1, eval_freq=256,
                checkpoint_freq=256, env_kwargs=("orbits_per_episode=0.05",))
    assert callbacks.PROGRESS_EVERY_S >= 30.0  # no rewrite within this test's calls
    evaluate, save = sb3_evaluation.evaluate_policy, BaseAlgorithm.save

    def slow_evaluate(model, *args, **kwargs):
        if model.num_timesteps >= 512:
            time.sleep(2.0)  # work that no record sees, only the files written after it
        return evaluate(model, *args, **kwargs)

    def save_then_die(self, path, *args, **kwargs):
        save(self, path, *args, **kwargs)
        if "512_steps" in str(path):
            raise _Killed(path)

    with monkeypatch.context() as m:
        m.setattr(sb3_evaluation, "evaluate_policy", slow_evaluate)
        m.setattr(sb3_callbacks, "evaluate_policy", slow_evaluate)
        m.setattr(BaseAlgorithm, "save", save_then_die)
        with pytest.raises(_Killed):
            train(resolve_settings(TrainOptions(**base, timesteps=2048)))
    killed = json.loads((out / "train_info.json").read_text())
    assert killed["status"] == "running"
    assert killed["wall_time_s"] < 2.0  # the record is from the start of the call
    summary = train(resolve_settings(TrainOptions(**base, timesteps=256, resume=True)))
    assert summary.total_wall_s - summary.wall_s >= 2.0  # the killed call's time counts


def test_train_info_is_written_before_the_envs_are_built(tmp_path, monkeypatch):
    from tether_gym_agents.training import run

    def die(*args, **kwargs):
        raise _Killed("make_venv")

    monkeypatch.setattr(run, "make_venv", die)
    with pytest.raises(_Killed):
        main(["--out", str(tmp_path / "r"), *FAST, "--timesteps", "64"])
    info = json.loads((tmp_path / "r" / "train_info.json").read_text())
    assert info["status"] == "running" and info["num_timesteps"] == 0


def test_every_run_ends_with_an_evaluation_of_its_final_weights(tmp_path, monkeypatch):
    seen = []
    original = sb3_evaluation.evaluate_policy

    def recording(model, *args, **kwargs):
        seen.append((model, int(model.num_timesteps), int(model._n_updates)))
        return original(model, *args, **kwargs)

    monkeypatch.setattr(sb3_evaluation, "evaluate_policy", recording)
    monkeypatch.setattr(sb3_callbacks, "evaluate_policy", recording)
    out = tmp_path / "run"
    # one rollout of 2 x 512 steps: evaluations are due at 512 and 1024, both before the update
    assert main(["--out", str(out), *FAST, "--eval-episodes", "1", "--timesteps", "1024",
                 "--eval-freq", "512"]) == 0
    model = seen[-1][0]
    assert [(steps, updates) for _, steps, updates in seen] == [(512, 0),
                                                               (1024, model._n_updates)]
    assert model._n_updates > 0
    assert list(_npz(out)["timesteps"]) == [512, 1024]


def test_resume_with_a_damaged_config_names_the_file(tmp_path, capsys):
    """A config.yml that is not YAML ends in one error naming it, exit 2, no traceback."""
    from tether_gym_agents.cli.train import main

    run = tmp_path / "run"
    run.mkdir()
    (run / "config.yml").write_text("algo: ppo\nhyperparams: {n_steps: [1, 2\n")
    assert main(["--resume", "--out", str(run), "--timesteps", "64"]) == 2
    err = capsys.readouterr().err
    assert "config.yml cannot be read" in err and "Traceback" not in err
