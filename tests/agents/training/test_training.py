"""train.py's main: PPO and SAC with tiny budgets, config validation, resume."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main
from tether_gym_agents.files.run_folder import checkpoint_agents
from tether_gym_agents.files.trained import TrainedAgent
from tether_gym_agents.training.config import ConfigError, load_hyperparams, parse_env_kwargs

TINY = ["--n-envs", "2", "--no-progress", "--eval-freq", "256", "--checkpoint-freq", "256",
        "--eval-episodes", "1", "--env-kwargs", "orbits_per_episode=0.05"]


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_train_then_evaluate(tmp_path, algo):
    out = tmp_path / algo
    extra = ["--timesteps", "512"]
    if algo == "sac":
        extra += ["--config", str(_tiny_sac_config(tmp_path))]
    assert main(["--algo", algo, "--out", str(out), *extra, *TINY]) == 0
    for name in ("config.yml", "args.yml", "command.txt", "vecnormalize.pkl", "final_model.zip",
                 "best_model.zip", "train_info.json", "eval/evaluations.npz",
                 "agent.json", "policy.safetensors", "final_agent/agent.json",
                 "final_agent/policy.safetensors", "learning_curve.png"):
        assert (out / name).is_file(), name
    cfg = yaml.safe_load((out / "config.yml").read_text())
    assert cfg["algo"] == algo and cfg["env_kwargs"]["orbits_per_episode"] == 0.05
    if algo == "ppo":  # the packaged config's value reaches the resolved config
        assert cfg["hyperparams"]["gamma"] == 0.995
    assert "--algo" in (out / "command.txt").read_text()
    info = json.loads((out / "train_info.json").read_text())
    assert info["num_timesteps"] >= 512 and info["seed"] == 0
    curve = np.load(out / "eval" / "evaluations.npz")
    assert curve["timesteps"].size >= 1
    # each checkpoint's policy as a safe agent recording its steps and wall time,
    # increasing along the run (learning curves against wall-clock time)
    ckpts = checkpoint_agents(out)
    assert [n for n, _ in ckpts] == sorted(n for n, _ in ckpts) and len(ckpts) >= 2
    walls = []
    for steps, folder in ckpts:
        training = json.loads((folder / "agent.json").read_text())["training"]
        assert training["num_timesteps"] == steps
        walls.append(training["wall_time_s"])
        TrainedAgent.load(folder)  # loads as any agent folder
    assert walls == sorted(walls) and 0 <= walls[0] <= info["wall_time_s"]
    final = json.loads((out / "final_agent" / "agent.json").read_text())["training"]
    assert final["wall_time_s"] <= info["wall_time_s"]
    # the saved agent acts on the env it was trained on, through evaluate.py's main
    rc = evaluate_main([str(out), "smc", "--suite", "paper", "--seeds", "2",
                        "--out", str(tmp_path / "eval"), "--no-plots"])
    assert rc == 0
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert set(results["policies"]) == {str(out), "smc"}
    assert results["policies"]["smc"]["success_rate"] == 1.0


def _tiny_sac_config(tmp_path):
    path = tmp_path / "sac_tiny.yml"
    path.write_text(yaml.safe_dump({"default": {
        "policy": "MlpPolicy", "learning_starts": 64, "batch_size": 32, "buffer_size": 2000,
        "normalize": {"norm_obs": True, "norm_reward": False},
        "policy_kwargs": {"net_arch": [16, 16]}}}))
    return path


def test_resume_continues_step_counter(tmp_path):
    out = tmp_path / "run"
    assert main(["--algo", "ppo", "--out", str(out), "--timesteps", "512", *TINY]) == 0
    first = json.loads((out / "train_info.json").read_text())["num_timesteps"]
    assert main(["--algo", "ppo", "--out", str(out), "--timesteps", "512", "--resume",
                 *TINY]) == 0
    second = json.loads((out / "train_info.json").read_text())["num_timesteps"]
    assert second >= first + 512
    assert len((out / "command.txt").read_text().splitlines()) == 2
    steps = np.load(out / "eval" / "evaluations.npz")["timesteps"]
    assert steps[0] <= first < steps[-1]  # the learning curve continues across the resume
    assert np.all(np.diff(steps) > 0)


def test_resume_without_run_folder(tmp_path, capsys):
    assert main(["--out", str(tmp_path / "none"), "--resume", "--timesteps", "8"]) == 2
    assert "config.yml" in capsys.readouterr().err


def test_unknown_config_key_rejected(tmp_path):
    path = tmp_path / "bad.yml"
    path.write_text("default:\n  n_steps: 64\n  learning_rat: 0.001\n")
    with pytest.raises(ConfigError, match=r"learning_rat.*valid keys"):
        load_hyperparams(path, "ppo", "tether_gym/TetherLibration-v2")
    assert main(["--config", str(path), "--out", str(tmp_path / "o"), "--timesteps", "8"]) == 2


def test_env_id_block_overrides_default(tmp_path):
    path = tmp_path / "c.yml"
    path.write_text("default: {n_steps: 64, gamma: 0.9}\n"
                    "tether_gym/TetherLibration-v2: {gamma: 0.5}\n")
    params = load_hyperparams(path, "ppo", "tether_gym/TetherLibration-v2")
    assert params == {"n_steps": 64, "gamma": 0.5}


def test_bad_normalize_and_yaml(tmp_path):
    bad = tmp_path / "n.yml"
    bad.write_text("default: {normalize: {norm_obs: true, nrm_reward: true}}\n")
    with pytest.raises(ConfigError, match="nrm_reward"):
        load_hyperparams(bad, "ppo", "x")
    broken = tmp_path / "b.yml"
    broken.write_text("default: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_hyperparams(broken, "ppo", "x")
    with pytest.raises(ConfigError, match="does not exist"):
        load_hyperparams(tmp_path / "missing.yml", "ppo", "x")


def test_env_kwargs_parsed_safely():
    parsed = parse_env_kwargs(["eccentricity=0.3", "masses=(1, 2)", "gravity=full",
                               "accel_limit=None"])
    assert parsed == {"eccentricity": 0.3, "masses": (1, 2), "gravity": "full",
                      "accel_limit": None}
    # code is never evaluated: it is not a literal, so it is refused
    with pytest.raises(ConfigError, match="is not a Python literal"):
        parse_env_kwargs(["x=__import__('os').getcwd()"])
    with pytest.raises(ConfigError, match="key=value"):
        parse_env_kwargs(["eccentricity"])


def test_unknown_env_id_suggests(tmp_path, capsys):
    assert main(["--env-id", "tether_gym/TetherLibraton-v0", "--out", str(tmp_path)]) == 2
    assert "did you mean 'tether_gym/TetherLibration-v2'" in capsys.readouterr().err


def test_bad_env_kwarg_is_reported(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["--out", str(out), "--timesteps", "8", "--env-kwargs", "eccentricity=1.5"]) == 2
    err = capsys.readouterr().err
    assert "--env-kwargs eccentricity=1.5" in err and "eccentricity" in err
    assert not out.exists()  # rejected before any work


def test_corrupt_or_missing_agent(tmp_path):
    from tether_gym_agents.files.trained import AgentLoadError

    with pytest.raises(AgentLoadError, match="does not exist"):
        TrainedAgent.load(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    with pytest.raises(AgentLoadError, match="no agent in"):
        TrainedAgent.load(tmp_path / "empty")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "final_model.zip").write_bytes(b"not a zip file")
    with pytest.raises(AgentLoadError, match="refusing pickled"):
        TrainedAgent.load(bad)
    assert evaluate_main([str(bad), "--seeds", "1", "--suite", "paper", "--no-plots",
                          "--out", str(tmp_path / "ev")]) == 2


def test_sac_resume_restores_replay_buffer(tmp_path, capsys):
    out = tmp_path / "sac"
    cfg = ["--config", str(_tiny_sac_config(tmp_path))]
    assert main(["--algo", "sac", "--out", str(out), "--timesteps", "512", *cfg, *TINY]) == 0
    # only the newest checkpoint keeps its replay buffer (pickle and arrays)
    steps = [int(p.stem.split("_")[1]) for p in (out / "checkpoints").glob("model_[0-9]*.zip")]
    buffers = sorted(p.name for p in (out / "checkpoints").glob("model_replay_buffer_*"))
    newest = max(steps)
    assert len(steps) >= 2
    assert buffers == [f"model_replay_buffer_{newest}_steps.npz",
                       f"model_replay_buffer_{newest}_steps.pkl"]
    capsys.readouterr()
    assert main(["--algo", "sac", "--out", str(out), "--timesteps", "256", "--resume",
                 *TINY]) == 0
    # the final model keeps its replay buffer beside it: 2 envs x 256 steps
    assert (out / "final_replay_buffer.pkl").is_file()
    text = capsys.readouterr().out
    assert "final_model.zip at step 512 with its replay buffer (512 transitions)" in text


def test_seed_learning_curves(tmp_path):
    """One plot of every seed's evaluation curve; needs two runs with evaluations."""
    pytest.importorskip("matplotlib")
    from tether_gym_agents.training.curves import plot_seed_learning_curves

    steps = np.array([100, 200, 300])
    for k in range(3):
        (tmp_path / f"seed_{k}" / "eval").mkdir(parents=True)
        np.savez(tmp_path / f"seed_{k}" / "eval" / "evaluations.npz", timesteps=steps[:2 + k // 2],
                 results=np.ones((2 + k // 2, 5)) * k, ep_lengths=np.ones((2 + k // 2, 5)))
    assert plot_seed_learning_curves(tmp_path / "seed_0") is None  # no seed folders inside
    out = plot_seed_learning_curves(tmp_path)
    assert out == tmp_path / "learning_curves.png" and out.stat().st_size > 1000
