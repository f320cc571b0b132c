"""``bc_term``: supervised steps on mpc's labels between PPO's updates.

The term must pull the actor's deterministic action (through the run's features and
normalisation) towards the stored labels, leave PPO's own update alone, and refuse bad
settings before the run folder is written.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import yaml

import tether_gym
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.common.features import FeatureSpec, add_features
from tether_gym_agents.files import TrainedAgent
from tether_gym_agents.training.bc_term import BCTermSpec, bc_term_spec, load_pairs
from tether_gym_agents.training.config import ConfigError, training_distribution
from tether_gym_agents.training.dagger import Dataset

KWARGS = {**training_distribution(), "action_mode": "rate", "orbits_per_episode": 0.02}
KWARGS.pop("increment_gain", None)
TARGET = np.array([0.3, -0.2])


def _data(path, n=64):
    """A DAgger dataset of real observations whose label is the constant TARGET."""
    env = gym.make(tether_gym.ENV_ID, **KWARGS)
    obs = np.stack([env.reset(seed=s)[0] for s in range(n)]).astype(np.float32)
    env.close()
    data = Dataset(obs, np.tile(TARGET, (n, 1)), np.zeros(n, np.int32), np.zeros(n, np.int32),
                   np.ones(n, bool), [{"env_seed": 0, "eccentricity": 0.0, "masses": [1.0] * 2,
                                       "beta": 1.0, "mixture_seed": 0}])
    data.save(path)
    return path


def _config(tmp_path, data, **term):
    block = {"policy": "MlpPolicy", "n_envs": 2, "n_timesteps": 128,
             "normalize": {"norm_obs": True, "norm_reward": True},
             "n_steps": 32, "batch_size": 32, "n_epochs": 1, "learning_rate": 1e-12,
             "policy_kwargs": {"net_arch": [16, 16], "log_std_init": -3.0},
             "features": {"name": "symlog_errors", "scale": 1e-3},
             "bc_term": {"data": str(data), "steps": 300, "batch_size": 32,
                         "learning_rate": 1e-2, **term},
             "env_kwargs": dict(KWARGS), "eval_freq": 128, "checkpoint_freq": 128}
    path = tmp_path / "bc.yml"
    path.write_text(yaml.safe_dump({tether_gym.ENV_ID: block}))
    return path


def test_the_term_pulls_the_actor_to_the_labels(tmp_path):
    data = _data(tmp_path / "part.npz")
    out = tmp_path / "run"
    # PPO's own steps are ~0 (learning rate 1e-12): any change of the actor is the term's
    assert train_main(["--config", str(_config(tmp_path, data)), "--out", str(out),
                       "--no-progress", "--eval-episodes", "1"]) == 0
    before = tmp_path / "before"
    assert train_main(["--config", str(_config(tmp_path, data, steps=1, learning_rate=1e-9)),
                       "--out", str(before), "--no-progress", "--eval-episodes", "1"]) == 0
    obs = Dataset.load(data).obs
    after = TrainedAgent.load(out / "final_agent").predict(obs)[0]
    start = TrainedAgent.load(before / "final_agent").predict(obs)[0]
    # (the statistics move on during the last rollout, after the term's last phase)
    assert np.abs(after - TARGET).mean() < 0.03 and np.abs(after - TARGET).max() < 0.1
    assert np.abs(start - TARGET).mean() > 0.1  # it was not there without the term
    recorded = yaml.safe_load((out / "config.yml").read_text())["hyperparams"]["bc_term"]
    assert recorded["data"] == [str(data)] and recorded["steps"] == 300


def test_the_pairs_go_through_the_runs_features(tmp_path):
    data = _data(tmp_path / "part.npz", n=8)
    spec = BCTermSpec((str(data),))
    features = FeatureSpec("symlog_errors", 1e-3)
    inputs, labels = load_pairs(spec, features, 2, 24)
    obs = Dataset.load(data).obs
    np.testing.assert_array_equal(inputs, add_features(features, obs, 2))
    assert inputs.shape == (8, 24) and obs.shape == (8, 20)
    np.testing.assert_array_equal(labels, np.tile(TARGET, (8, 1)).astype(np.float32))
    with pytest.raises(ConfigError, match="the run's policy takes 20"):
        load_pairs(spec, features, 2, 20)


@pytest.mark.parametrize("value, named", [
    ("x", "must be a mapping"),
    ({"data": "DATA", "step": 3}, "unknown key(s) ['step']"),
    ({"data": "nothing/*.npz"}, "matches no file"),
    ({"data": "no/such.npz"}, "does not exist"),
    ({"data": 3}, "must be a glob pattern or a list"),
    ({"data": "DATA", "steps": 0}, "steps 0 must be an integer in [1, 10000]"),
    ({"data": "DATA", "batch_size": 2.5}, "batch_size 2.5 must be an integer"),
    ({"data": "DATA", "learning_rate": float("nan")}, "learning_rate nan must be a number"),
])
def test_bad_settings_are_refused(tmp_path, value, named):
    data = str(_data(tmp_path / "part.npz", n=2))
    if isinstance(value, dict) and value.get("data") == "DATA":
        value = {**value, "data": data}
    with pytest.raises(ConfigError) as info:
        bc_term_spec(value, "c.yml", "ppo")
    assert "c.yml: bc_term" in str(info.value) and named in str(info.value)


def test_only_ppo_takes_the_term(tmp_path):
    data = str(_data(tmp_path / "part.npz", n=2))
    with pytest.raises(ConfigError, match="--algo sac is not ppo or ppo_lag"):
        bc_term_spec({"data": data}, "c.yml", "sac")


def test_a_bad_term_is_refused_before_the_run_folder(tmp_path, capsys):
    out = tmp_path / "run"
    config = _config(tmp_path, tmp_path / "missing.npz")
    assert train_main(["--config", str(config), "--out", str(out), "--no-progress"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not out.exists()
