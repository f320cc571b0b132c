"""A policy's input features: their values, the training wrapper, the ``features`` config
key, the ``features`` entry of agent files and evaluation of an agent that has them."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from tether_gym.envs.layout import OBSERVATION
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main
from tether_gym_agents.common.features import FeatureSpec, add_features
from tether_gym_agents.files.safe_format import AgentLoadError
from tether_gym_agents.files.trained import TrainedAgent
from tether_gym_agents.training.config import ConfigError, feature_spec
from tether_gym_agents.training.vec_env import FeatureVecEnv, make_sb3_vec_env

TINY = ["--n-envs", "2", "--no-progress", "--eval-freq", "256", "--checkpoint-freq", "256",
        "--eval-episodes", "1", "--env-kwargs", "orbits_per_episode=0.05"]


def test_symlog_errors_are_signed_logs_of_the_scaled_errors():
    n = 2
    sl = OBSERVATION.slices(n)
    obs = np.zeros((3, OBSERVATION.size(n)), dtype=np.float32)
    obs[:, sl["error"]] = [[0.0, 1e-3], [-1e-3, 9e-3], [0.1, -1e-5]]
    obs[:, sl["derror"]] = [[2e-3, -2e-3], [0.0, 1.0], [5e-4, 0.0]]
    out = add_features(FeatureSpec("symlog_errors", 1e-3), obs, n)
    assert out.shape == (3, obs.shape[1] + 4) and out.dtype == np.float32
    assert np.array_equal(out[:, :obs.shape[1]], obs)
    e = obs[:, sl["error"]].astype(float)
    de = obs[:, sl["derror"]].astype(float)
    # symlog(x) = sign(x) ln(1 + |x|): ln 2 at e = S, odd, linear (slope 1 / S) near 0
    np.testing.assert_allclose(out[0, -4:], [0.0, np.log(2.0), np.log(3.0), -np.log(3.0)],
                               rtol=1e-6)
    np.testing.assert_allclose(out[:, -4:-2], np.sign(e) * np.log1p(np.abs(e) / 1e-3),
                               rtol=1e-6)
    np.testing.assert_allclose(out[:, -2:], np.sign(de) * np.log1p(np.abs(de) / 1e-3),
                               rtol=1e-6)
    assert abs(out[2, -3] - (-1e-2)) < 1e-4  # e = -1e-5 = -S / 100: about -0.01
    # a single observation and a batch give the same features
    assert np.array_equal(add_features(FeatureSpec(), obs[1], n), out[1])
    assert add_features(None, obs, n) is obs


def test_spec_is_validated():
    assert FeatureSpec.from_dict({"name": "symlog_errors"}) == FeatureSpec("symlog_errors", 1e-3)
    spec = FeatureSpec.from_dict({"name": "symlog_errors", "scale": 0.01})
    assert FeatureSpec.from_dict(spec.to_dict()) == spec
    for bad, match in (([1], "must be a mapping"), ({"name": "frames"}, "is not one of"),
                       ({"name": "symlog_errors", "scale": 0}, "finite number > 0"),
                       ({"name": "symlog_errors", "scale": True}, "finite number > 0"),
                       ({"name": "symlog_errors", "gain": 1}, r"unknown key\(s\) \['gain'\]")):
        with pytest.raises(ValueError, match=match):
            FeatureSpec.from_dict(bad)


def test_wrapper_extends_observations_and_terminal_observations():
    spec = FeatureSpec("symlog_errors", 1e-3)
    plain = make_sb3_vec_env(2, seed=3, env_kwargs={"orbits_per_episode": 0.02})
    wrapped = FeatureVecEnv(make_sb3_vec_env(2, seed=3, env_kwargs={"orbits_per_episode": 0.02}),
                            spec)
    assert wrapped.observation_space.shape == (plain.observation_space.shape[0] + 4,)
    assert np.array_equal(wrapped.reset(), add_features(spec, plain.reset(), 2))
    action = np.full((2, 2), 0.3, dtype=np.float32)
    ended = False
    for _ in range(40):
        plain.step_async(action)
        wrapped.step_async(action)
        obs_p, _, done_p, infos_p = plain.step_wait()
        obs_w, _, done_w, infos_w = wrapped.step_wait()
        assert np.array_equal(obs_w, add_features(spec, obs_p, 2))
        for info_p, info_w in zip(infos_p, infos_w, strict=True):
            if "terminal_observation" in info_p:
                ended = True
                assert np.array_equal(info_w["terminal_observation"],
                                      add_features(spec, info_p["terminal_observation"], 2))
    assert ended


def _features_config(tmp_path, value) -> str:
    path = tmp_path / "ppo_features.yml"
    path.write_text(yaml.safe_dump({"default": {
        "policy": "MlpPolicy", "n_steps": 64, "batch_size": 64,
        "normalize": {"norm_obs": True, "norm_reward": True},
        "policy_kwargs": {"net_arch": [8, 8]}, "features": value}}))
    return str(path)


@pytest.fixture(scope="module")
def feature_run(tmp_path_factory):
    """A PPO run of 512 steps whose network sees the symlog error features."""
    tmp = tmp_path_factory.mktemp("features")
    out = tmp / "run"
    config = _features_config(tmp, {"name": "symlog_errors", "scale": 0.002})
    assert main(["--algo", "ppo", "--config", config, "--out", str(out), "--timesteps", "512",
                 *TINY]) == 0
    return out


def test_training_records_the_features(feature_run):
    cfg = yaml.safe_load((feature_run / "config.yml").read_text())
    assert cfg["hyperparams"]["features"] == {"name": "symlog_errors", "scale": 0.002}
    for folder in (feature_run, feature_run / "final_agent"):
        meta = json.loads((folder / "agent.json").read_text())
        assert meta["features"] == {"name": "symlog_errors", "scale": 0.002}
    agent = TrainedAgent.load(feature_run)
    assert agent.features == FeatureSpec("symlog_errors", 0.002)
    env_dim = OBSERVATION.size(2)
    assert agent.observation_space.shape == (env_dim + 4,)
    # the agent takes the env's observation and appends its features itself
    obs = np.zeros(env_dim, dtype=np.float32)
    action, _ = agent.predict(obs)
    assert action.shape == (2,)
    with pytest.raises(ValueError, match="its features included"):
        agent.predict(np.zeros(env_dim + 4, dtype=np.float32))


def test_a_malformed_features_entry_is_refused(feature_run, tmp_path):
    import shutil

    copy = tmp_path / "agent"
    shutil.copytree(feature_run / "final_agent", copy)
    meta = json.loads((copy / "agent.json").read_text())
    meta["features"] = {"name": "symlog_errors", "scale": -1}
    (copy / "agent.json").write_text(json.dumps(meta))
    with pytest.raises(AgentLoadError, match="features: scale -1"):
        TrainedAgent.load(copy)


def test_evaluation_runs_an_agent_with_features(feature_run, tmp_path):
    rc = evaluate_main([str(feature_run), "--suite", "paper", "--seeds", "1",
                        "--out", str(tmp_path / "eval"), "--no-plots"])
    assert rc == 0
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert results["policies"][str(feature_run)]["kind"] == "rl"


def test_bad_features_key_is_a_config_error(tmp_path, capsys):
    config = _features_config(tmp_path, {"name": "symlog_errors", "scale": "big"})
    assert main(["--algo", "ppo", "--config", config, "--out", str(tmp_path / "r"),
                 "--timesteps", "64", *TINY]) == 2
    assert "features: scale 'big' must be a finite number > 0" in capsys.readouterr().err
    with pytest.raises(ConfigError, match="cfg: features: name 'x' is not one of"):
        feature_spec({"name": "x"}, "cfg")
