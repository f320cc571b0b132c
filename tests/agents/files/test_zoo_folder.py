"""rl-baselines3-zoo run folders (issue 24): converted and evaluated like train.py's.

Before: ``evaluate.py logs/ppo/tether_gym-TetherLibration-v2_1 --allow-pickle`` said
"no agent.json" and ``python -m tether_gym_agents.files convert`` found no model.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from collections import OrderedDict

import numpy as np
import pytest
import yaml

import tether_gym
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.files.cli import main as agent_files_main
from tether_gym_agents.files.safe_format import AGENT_FILE, AgentLoadError
from tether_gym_agents.files.trained import TrainedAgent
from tether_gym_agents.files.zoo_folder import ZooFolderError, find_zoo_run, read_zoo_yaml

ENV_NAME = tether_gym.ENV_ID.replace("/", "-")
ENV_KWARGS = {"orbits_per_episode": 0.05, "init_theta_range": 0.1}


def _zoo_run(root, normalize=True):
    """An rl_zoo3 run folder as its ExperimentManager writes it, from a tiny model
    trained in-process (256 steps)."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from tether_gym_agents.training.vec_env import make_sb3_vec_env

    run = root / "ppo" / f"{ENV_NAME}_1"
    params = run / ENV_NAME
    params.mkdir(parents=True)
    venv = make_sb3_vec_env(2, seed=0, env_kwargs=ENV_KWARGS)
    if normalize:
        venv = VecNormalize(venv, gamma=0.99)
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=64, n_epochs=1, seed=0,
                device="cpu", policy_kwargs={"net_arch": [16, 16]})
    model.learn(256)
    model.save(run / ENV_NAME)  # SB3 adds .zip
    if normalize:
        venv.save(str(params / "vecnormalize.pkl"))
    hyper = {"env_kwargs": ENV_KWARGS, "n_envs": 2, "n_steps": 64, "n_timesteps": 256,
             "normalize": {"norm_obs": True, "norm_reward": True, "gamma": 0.99}
             if normalize else False,
             "policy": "MlpPolicy", "policy_kwargs": {"net_arch": [16, 16]}}
    args = {"algo": "ppo", "env": tether_gym.ENV_ID, "env_kwargs": None, "seed": 0,
            "gym_packages": ["tether_gym"], "hyperparams": None}
    # the zoo dumps OrderedDicts: !!python/object/apply:collections.OrderedDict
    (params / "config.yml").write_text(yaml.dump(OrderedDict(sorted(hyper.items()))))
    (params / "args.yml").write_text(yaml.dump(OrderedDict(sorted(args.items()))))
    (params / "command.txt").write_text("python -m rl_zoo3.train --algo ppo")
    return run, model, venv


@pytest.fixture(scope="module")
def zoo(tmp_path_factory):
    return _zoo_run(tmp_path_factory.mktemp("logs"))


def _expected(model, venv, obs):
    return model.predict(venv.normalize_obs(obs), deterministic=True)[0]


def test_the_fabricated_folder_is_read_as_plain_data(zoo):
    run, _, _ = zoo
    assert "!!python/object/apply:collections.OrderedDict" in \
        (run / ENV_NAME / "config.yml").read_text()
    found = find_zoo_run(run)
    assert found.model_path == run / f"{ENV_NAME}.zip"
    assert found.stats_path == run / ENV_NAME / "vecnormalize.pkl"
    assert find_zoo_run(run / ENV_NAME) == found  # its params folder designates it too
    assert find_zoo_run(run / f"{ENV_NAME}.zip") == found


def test_zoo_yaml_with_any_other_python_tag_is_refused_without_running_it(tmp_path):
    marker = tmp_path / "PWNED"
    bad = tmp_path / "config.yml"
    bad.write_text(f"!!python/object/apply:os.system ['touch {marker}']\n")
    with pytest.raises(ZooFolderError, match="cannot be read as rl_zoo3's YAML"):
        read_zoo_yaml(bad)
    assert not marker.exists()
    bad.write_text("- - [a, 1]\n")
    with pytest.raises(ZooFolderError, match="not a mapping"):
        read_zoo_yaml(bad)


def test_a_zoo_run_loads_on_opt_in_and_acts_as_trained(zoo):
    run, model, venv = zoo
    with pytest.raises(AgentLoadError, match=r"refusing pickled agent files .*"
                                             rf"{ENV_NAME}.zip.*vecnormalize.pkl"):
        TrainedAgent.load(run)
    with pytest.warns(UserWarning, match="pickle can run any code"):
        agent = TrainedAgent.load(run, allow_pickle=True)
    assert agent.algo == "ppo" and agent.env_id == tether_gym.ENV_ID
    assert agent.env_kwargs == ENV_KWARGS and agent.norm is not None
    obs = np.random.default_rng(0).normal(size=(8, 20)).astype(np.float32)
    np.testing.assert_allclose(agent.predict(obs)[0], _expected(model, venv, obs), atol=2e-6)


def test_convert_writes_a_safe_agent_into_the_zoo_run(tmp_path):
    run, model, venv = _zoo_run(tmp_path / "logs")
    assert agent_files_main(["convert", str(run)]) == 2  # refused without the opt-in
    with pytest.warns(UserWarning):
        assert agent_files_main(["convert", str(run), "--allow-pickle"]) == 0
    assert (run / "final_agent" / AGENT_FILE).is_file()
    safe = TrainedAgent.load(run)  # no opt-in needed any more: the safe files are read
    assert safe.path == run / "final_agent" and safe.env_kwargs == ENV_KWARGS
    obs = np.random.default_rng(1).normal(size=(8, 20)).astype(np.float32)
    np.testing.assert_allclose(safe.predict(obs)[0], _expected(model, venv, obs), atol=2e-6)


def test_a_zoo_run_without_normalisation(tmp_path):
    run, model, _ = _zoo_run(tmp_path / "logs", normalize=False)
    with pytest.warns(UserWarning):
        agent = TrainedAgent.load(run, allow_pickle=True)
    assert agent.norm is None
    obs = np.random.default_rng(2).normal(size=(4, 20)).astype(np.float32)
    np.testing.assert_allclose(agent.predict(obs)[0],
                               model.predict(obs, deterministic=True)[0], atol=2e-6)


def test_a_zoo_run_without_a_model_is_named(tmp_path):
    run, _, _ = _zoo_run(tmp_path / "logs")
    (run / f"{ENV_NAME}.zip").unlink()
    with pytest.raises(AgentLoadError, match=rf"rl_zoo3 run .*{ENV_NAME}_1 holds no model"):
        TrainedAgent.load(run, allow_pickle=True)


def test_evaluate_scores_a_zoo_run(zoo, tmp_path, capsys):
    run, _, _ = zoo
    with pytest.warns(UserWarning):
        code = evaluate_main([str(run), "--allow-pickle", "--seeds", "1", "--no-plots",
                              "--out", str(tmp_path / "eval")])
    assert code in (0, None), capsys.readouterr().err
    assert (tmp_path / "eval" / "results.json").is_file()
    assert str(run) in capsys.readouterr().out


@pytest.mark.slow
def test_a_run_of_rl_zoo3_itself_is_converted(tmp_path):
    """The layout read above is the one rl_zoo3 writes (a real 256-step zoo run)."""
    if importlib.util.find_spec("rl_zoo3") is None:
        pytest.skip("rl_zoo3 is not installed: pip install -e '.[test]' installs it")
    from tether_gym_agents.training.config import CONFIG_DIR

    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", tether_gym.ENV_ID,
           "--gym-packages", "tether_gym", "--conf-file", str(CONFIG_DIR / "ppo.yml"),
           "-n", "256", "--eval-freq", "-1", "--save-freq", "-1", "-f", str(tmp_path),
           "--seed", "0", "--device", "cpu", "--hyperparams", "n_envs:2", "n_steps:64",
           "batch_size:64"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    run = tmp_path / "ppo" / f"{ENV_NAME}_1"
    with pytest.warns(UserWarning):
        assert agent_files_main(["convert", str(run), "--allow-pickle"]) == 0
    agent = TrainedAgent.load(run)
    assert agent.env_kwargs["mass_range"] == 0.25 and agent.norm is not None
