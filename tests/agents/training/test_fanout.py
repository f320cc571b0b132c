"""train.py --seeds: one single-run folder per seed as Ray tasks; skip finished, resume.

The seeds are trained from records (TrainSettings.for_seed) by the training function:
tests that need no real training replace ``fanout.train`` and run the jobs in-process.
"""

from __future__ import annotations

import io
import json
import shutil
import sys
import zipfile
from dataclasses import FrozenInstanceError

import numpy as np
import pytest
import yaml

from tether_gym_agents.cli.train import main
from tether_gym_agents.files.run_folder import write_train_info
from tether_gym_agents.training import fanout
from tether_gym_agents.training.config import ConfigError
from tether_gym_agents.training.fanout import RAY_PIP, RunState, run_state
from tether_gym_agents.training.settings import TrainSettings

# 2 envs x n_steps 128 (the tiny config): one PPO update per 256 steps, three in TARGET
TINY = ["--n-envs", "2", "--eval-freq", "128", "--checkpoint-freq", "256", "--eval-episodes",
        "1", "--env-kwargs", "orbits_per_episode=0.05"]
TARGET = 768


def _weights(path):
    import torch

    with zipfile.ZipFile(path) as archive:
        return torch.load(io.BytesIO(archive.read("policy.pth")), weights_only=True)


def _same_weights(a, b) -> bool:
    import torch

    wa, wb = _weights(a), _weights(b)
    return wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa)


def _info(run_dir):
    return json.loads((run_dir / "train_info.json").read_text())


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """TINY with a small PPO config (``--config``)."""
    path = tmp_path_factory.mktemp("config") / "ppo_tiny.yml"
    path.write_text(yaml.safe_dump({"default": {
        "policy": "MlpPolicy", "n_steps": 128, "batch_size": 64, "n_epochs": 4,
        "normalize": {"norm_obs": True, "norm_reward": True},
        "policy_kwargs": {"net_arch": [16, 16]}}}))
    return [*TINY, "--config", str(path)]


@pytest.fixture(scope="module")
def fanned(ray_session, tmp_path_factory, tiny):
    out = tmp_path_factory.mktemp("fanout") / "ppo"
    assert main(["--algo", "ppo", "--seeds", "2", "--out", str(out), "--timesteps", str(TARGET),
                 *tiny]) == 0
    return out


@pytest.mark.slow
def test_two_seeds_are_single_runs(fanned, tmp_path, tiny):
    for seed in (0, 1):
        run = fanned / f"seed_{seed}"
        for name in ("config.yml", "command.txt", "final_model.zip", "vecnormalize.pkl",
                     "train_info.json", "eval/evaluations.npz", "train.log"):
            assert (run / name).is_file(), (seed, name)
        info = _info(run)
        assert info["seed"] == seed and info["num_timesteps"] == TARGET
        log = (run / "train.log").read_text()
        assert "total_timesteps" in log  # SB3's progress table
        assert "(torch threads 1, numba threads 1, pid" in log
    assert f"--out {fanned / 'seed_1'}" in (fanned / "seed_1" / "command.txt").read_text()
    summary = (fanned / "fanout.log").read_text()
    assert "seed 0: trained in" in summary and "seed 1: trained in" in summary
    assert not _same_weights(fanned / "seed_0" / "final_model.zip",
                             fanned / "seed_1" / "final_model.zip")
    # seed 1 of the fan-out is, bit for bit, the single run train.py --seed 1 makes
    single = tmp_path / "single"
    assert main(["--algo", "ppo", "--seed", "1", "--out", str(single), "--timesteps",
                 str(TARGET), "--no-progress", *tiny]) == 0
    assert _same_weights(single / "final_model.zip", fanned / "seed_1" / "final_model.zip")
    curves = [np.load(run / "eval" / "evaluations.npz")["results"]
              for run in (single, fanned / "seed_1")]
    np.testing.assert_array_equal(*curves)


@pytest.mark.slow
def test_rerun_skips_finished_seeds(fanned, capsys, tiny):
    files = [fanned / f"seed_{s}" / name for s in (0, 1)
             for name in ("final_model.zip", "train_info.json", "train.log", "command.txt")]
    before = {f: (f.stat().st_mtime_ns, f.stat().st_size) for f in files}
    capsys.readouterr()
    assert main(["--algo", "ppo", "--seeds", "2", "--out", str(fanned), "--timesteps",
                 str(TARGET), *tiny]) == 0
    assert {f: (f.stat().st_mtime_ns, f.stat().st_size) for f in files} == before
    assert capsys.readouterr().out.count("already finished") == 2


def _interrupt_after(run_dir, steps):
    """Leave a run folder as a run killed after its checkpoint and evaluation at `steps`."""
    for name in ("final_model.zip", "vecnormalize.pkl", "train_info.json", "learning_curve.png"):
        (run_dir / name).unlink(missing_ok=True)
    for path in (run_dir / "checkpoints").iterdir():
        if int(path.stem.split("_")[-2]) > steps:
            if path.is_dir():  # a checkpoint's safe agent folder
                shutil.rmtree(path)
            else:
                path.unlink()
    curve = run_dir / "eval" / "evaluations.npz"
    with np.load(curve) as data:
        keep = data["timesteps"] <= steps
        np.savez(curve, **{k: data[k][keep] for k in data.files})


@pytest.mark.slow
def test_resume_after_interrupt(fanned, tmp_path, tiny):
    out = tmp_path / "ppo"
    shutil.copytree(fanned, out)
    _interrupt_after(out / "seed_1", 512)
    assert run_state(out / "seed_1", TARGET) == (RunState.PARTIAL, 512)
    seed0 = (out / "seed_0" / "final_model.zip").stat().st_mtime_ns
    assert main(["--algo", "ppo", "--seeds", "2", "--out", str(out), "--timesteps", str(TARGET),
                 *tiny]) == 0
    run = out / "seed_1"
    assert (out / "seed_0" / "final_model.zip").stat().st_mtime_ns == seed0  # skipped
    assert _info(run)["num_timesteps"] == TARGET  # the missing 256 steps, not 768 again
    log = (run / "train.log").read_text()
    assert "model_512_steps.zip at step 512" in log
    assert "--resume --timesteps 256" in (run / "command.txt").read_text().splitlines()[-1]
    steps = np.load(run / "eval" / "evaluations.npz")["timesteps"]
    np.testing.assert_array_equal(steps, np.arange(128, TARGET + 1, 128))


def test_run_state(tmp_path):
    run = tmp_path / "run"
    assert run_state(run, 100) == (RunState.NEW, 0)
    (run / "checkpoints").mkdir(parents=True)
    for name in ("model_32_steps.zip", "model_64_steps.zip", "model_vecnormalize_64_steps.pkl",
                 "notes_128_steps.txt"):
        (run / "checkpoints" / name).write_bytes(b"")
    assert run_state(run, 100) == (RunState.NEW, 64)  # no config.yml: --resume cannot work
    (run / "config.yml").write_text("hyperparams: {}\n")
    assert run_state(run, 100) == (RunState.PARTIAL, 64)
    (run / "train_info.json").write_text(json.dumps({"num_timesteps": 80}))
    assert run_state(run, 100) == (RunState.PARTIAL, 80)
    (run / "train_info.json").write_text(json.dumps({"num_timesteps": 100}))
    assert run_state(run, 100) == (RunState.DONE, 100)


@pytest.mark.parametrize(("argv", "message"), [
    (["--seeds", "0"], "--seeds 0: must be an integer >= 1"),
    (["--seeds", "2", "--resume"], "--resume cannot be combined with --seeds"),
    (["--ray-address", "auto"], "needs --seeds N or --sweep"),
    (["--seeds", "2", "--torch-threads", "0"], "--torch-threads 0: must be an integer >= 1"),
    (["--seeds", "2", "--env-kwargs", "eccentricity"], "must look like key=value"),
    (["--seeds", "2", "--timesteps", "0"], "--timesteps 0: must be an integer >= 1"),
    (["--seeds", "1", "--env-kwargs", "eccentricity=1.5"], "--env-kwargs eccentricity=1.5"),
])
def test_bad_flags_fail_before_work(tmp_path, capsys, argv, message, monkeypatch):
    monkeypatch.setattr(fanout, "train", _no_training)
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.startswith("train.py: error: ")
    assert not (tmp_path / "o").exists()


def _no_training(settings):
    raise AssertionError(f"trained {settings.out}")


def test_a_run_folder_as_out_is_refused_naming_what_to_give(tmp_path, capsys, monkeypatch):
    """Before: the one-run refusal, whose advice (--resume) --seeds refuses."""
    monkeypatch.setattr(fanout, "train", _no_training)
    run = tmp_path / "seed_0"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "model_64_steps.zip").write_bytes(b"")
    assert main(["--seeds", "2", "--out", str(run)]) == 2
    err = capsys.readouterr().err
    assert err == (f"train.py: error: --out {run} is itself a training run "
                   "(checkpoints/model_64_steps.zip); --seeds writes one seed_K/ run per seed "
                   "into a folder of its own: give a new folder, or the one that holds the "
                   "seed_K/ runs\n")
    assert sorted(p.name for p in run.rglob("*")) == ["checkpoints", "model_64_steps.zip"]


def test_without_ray(tmp_path, capsys, monkeypatch, tiny):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert main(["--seeds", "2", "--out", str(tmp_path / "two"), *tiny]) == 2
    assert RAY_PIP in capsys.readouterr().err
    assert not (tmp_path / "two").exists()
    # a single run and --seeds 1 train in this process without Ray
    assert main(["--out", str(tmp_path / "one"), "--timesteps", "256", "--no-progress",
                 *tiny]) == 0
    assert _info(tmp_path / "one")["num_timesteps"] >= 256
    assert main(["--seeds", "1", "--seed", "3", "--out", str(tmp_path / "fan"), "--timesteps",
                 "256", *tiny]) == 0
    assert _info(tmp_path / "fan" / "seed_3")["seed"] == 3


def _in_process(monkeypatch, fake_train=None):
    """Seeds run in this process, with ``fake_train`` as the training function if given."""
    if fake_train is not None:
        monkeypatch.setattr(fanout, "train", fake_train)
    monkeypatch.setattr(fanout, "require_ray", lambda: None)
    real = fanout.run_jobs
    monkeypatch.setattr(fanout, "run_jobs", lambda jobs, **kw: real(jobs, **{**kw,
                                                                           "use_ray": False}))
    resolved = []
    real_resolve = fanout.resolve_settings

    def resolve(*args, **kwargs):
        resolved.append(args[0])
        return real_resolve(*args, **kwargs)

    monkeypatch.setattr(fanout, "resolve_settings", resolve)
    return resolved


def test_seeds_are_trained_from_records_and_failures_carry_their_message(tmp_path, capsys,
                                                                         monkeypatch):
    """Every seed gets a TrainSettings derived from one resolution; a seed's exception is
    reported with its message and the other seeds go on."""
    calls = []

    def fake_train(settings):
        calls.append(settings)
        if settings.seed == 4:
            raise ConfigError("seed 4 cannot train: boom")
        if settings.seed == 5:
            raise RuntimeError("worker lost")
        write_train_info(settings.out, {"num_timesteps": settings.timesteps, "wall_time_s": 1.5})

    resolved = _in_process(monkeypatch, fake_train)
    out = tmp_path / "fan"
    assert main(["--seeds", "3", "--seed", "3", "--out", str(out), "--timesteps", "64",
                 "--env-kwargs", "orbits_per_episode=0.05", "--verbose", "0"]) == 1
    assert len(resolved) == 1  # the settings were resolved once, for every seed
    assert [s.seed for s in calls] == [3, 4, 5]
    for settings in calls:
        assert isinstance(settings, TrainSettings)
        with pytest.raises(FrozenInstanceError):
            settings.n_envs = 3  # type: ignore[misc]
        assert settings.out == out.absolute() / f"seed_{settings.seed}"
        assert settings.timesteps == 64 and settings.env_kwargs == calls[0].env_kwargs
        assert settings.options.seeds is None and settings.options.no_progress
        assert settings.options.verbose == 1  # the task's log shows SB3's tables
        assert settings.command == ("--env-kwargs", "orbits_per_episode=0.05", "--timesteps",
                                    "64", "--seed", str(settings.seed), "--out",
                                    str(settings.out), "--no-progress", "--verbose", "1")
    printed = capsys.readouterr().out
    assert "seed 3: trained in" in printed
    assert "seed 4: FAILED after" in printed and ": seed 4 cannot train: boom (log" in printed
    assert "seed 5: FAILED after" in printed and "RuntimeError: worker lost" in printed
    log4 = (out / "seed_4" / "train.log").read_text()
    assert "train.py: error: seed 4 cannot train: boom" in log4 and "Traceback" not in log4
    assert "Traceback" in (out / "seed_5" / "train.log").read_text()
    assert (out / "fanout.log").read_text().count("FAILED") == 2
    # the same command again: seed 3 is skipped, the failed ones are trained again
    calls.clear()
    assert main(["--seeds", "3", "--seed", "3", "--out", str(out), "--timesteps", "64",
                 "--env-kwargs", "orbits_per_episode=0.05"]) == 1
    assert [s.seed for s in calls] == [4, 5]


def test_partial_seed_is_resumed_as_train_py_resume(tmp_path, monkeypatch):
    """A seed with a checkpoint is continued from the run folder's config.yml."""
    calls = []

    def fake_train(settings):
        calls.append(settings)
        write_train_info(settings.out, {"num_timesteps": 64, "wall_time_s": 1.0})

    resolved = _in_process(monkeypatch, fake_train)
    run = tmp_path / "fan" / "seed_0"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "model_48_steps.zip").write_bytes(b"")
    (run / "config.yml").write_text(yaml.safe_dump({"algo": "ppo", "hyperparams": {
        "n_steps": 16, "batch_size": 32, "normalize": False, "n_envs": 2, "eval_freq": 32,
        "checkpoint_freq": 16, "env_kwargs": {"orbits_per_episode": 0.05}}}))
    assert main(["--seeds", "1", "--out", str(tmp_path / "fan"), "--timesteps", "64"]) == 0
    (settings,) = calls
    assert settings.resume and settings.timesteps == 16 and settings.n_envs == 2
    assert settings.source == str(run.absolute() / "config.yml")
    assert settings.command[-3:] == ("--resume", "--timesteps", "16")
    assert len(resolved) == 2  # the fan-out's settings, then the resumed run's


def test_resume_after_evaluation_past_the_checkpoint(tmp_path, monkeypatch, tiny):
    monkeypatch.setitem(sys.modules, "ray", None)  # --seeds 1 trains in this process
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    argv = ["--seeds", "1", "--out", str(tmp_path), "--timesteps", str(TARGET), *tiny]
    assert main(argv) == 0
    run = tmp_path / "seed_0"
    _interrupt_after(run, 512)
    curve = run / "eval" / "evaluations.npz"  # killed after the evaluation at step 640
    with np.load(curve) as data:
        np.savez(curve, timesteps=np.append(data["timesteps"], 640),
                 results=np.vstack([data["results"], data["results"][-1:]]),
                 ep_lengths=np.vstack([data["ep_lengths"], data["ep_lengths"][-1:]]))
    assert main(argv) == 0
    assert _info(run)["num_timesteps"] == TARGET
    steps = np.load(curve)["timesteps"]
    np.testing.assert_array_equal(steps, np.arange(128, TARGET + 1, 128))


@pytest.mark.parametrize("algo, hyperparams", [
    # the shipped sac.yml's learner in miniature: CAPS weights, several envs per update
    ("sac", {"policy": "MlpPolicy", "learning_starts": 64, "batch_size": 32,
             "buffer_size": 2000, "gradient_steps": 2, "ent_coef": "auto_0.005",
             "caps_temporal": 1.0, "caps_spatial": 1.0, "caps_magnitude": 1.0,
             "policy_kwargs": {"net_arch": [16, 16]}}),
    # ppo_fast.yml's geometry in miniature: many envs, short rollouts, a linear schedule
    ("ppo", {"policy": "MlpPolicy", "n_envs": 8, "n_steps": 16, "batch_size": 64,
             "n_epochs": 2, "learning_rate": "lin_1.0e-3",
             "policy_kwargs": {"net_arch": [16, 16], "log_std_init": -3.5}}),
])
def test_sac_and_fast_ppo_train_through_the_fanout(tmp_path, monkeypatch, algo, hyperparams):
    """Two seeds of each shipped learner's recipe, trained for real in this process."""
    _in_process(monkeypatch)
    config = tmp_path / f"{algo}.yml"
    config.write_text(yaml.safe_dump({"default": hyperparams}))
    out = tmp_path / "fan"
    argv = ["--algo", algo, "--config", str(config), "--seeds", "2", "--out", str(out),
            "--timesteps", "256", "--eval-freq", "128", "--checkpoint-freq", "128",
            "--eval-episodes", "1", "--env-kwargs", "orbits_per_episode=0.05"]
    assert main(argv) == 0
    for seed in (0, 1):
        run = out / f"seed_{seed}"
        info = _info(run)
        assert info["seed"] == seed and info["num_timesteps"] >= 256
        assert info["wall_time_s"] > 0
        assert (run / "agent.json").is_file() and (run / "final_agent" / "agent.json").is_file()
        resolved = yaml.safe_load((run / "config.yml").read_text())
        assert resolved["algo"] == algo
        assert all(resolved["hyperparams"][k] == v for k, v in hyperparams.items()
                   if k not in ("policy_kwargs", "learning_rate"))
    assert not _same_weights(out / "seed_0" / "final_model.zip",
                             out / "seed_1" / "final_model.zip")
