"""``init_policy``: a PPO run whose actor and observation statistics start from an agent.

The warm-started model must act exactly as the agent it came from (same deterministic
action on the same raw observation, features and normalisation included) before its
first update, and every mismatch of layout, mode or algorithm is refused before the run
folder is written.
"""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
import yaml

import tether_gym
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.common.features import FeatureSpec, add_features
from tether_gym_agents.files import TrainedAgent
from tether_gym_agents.files.safe_format import ObsNormalization, save_agent
from tether_gym_agents.training import dagger
from tether_gym_agents.training.config import ConfigError, training_distribution
from tether_gym_agents.training.run import _model
from tether_gym_agents.training.settings import TrainOptions, resolve_settings

SCALE = 1e-4
KWARGS = {**training_distribution(), "action_mode": "rate", "orbits_per_episode": 0.02}
KWARGS.pop("increment_gain", None)


def _agent(path, widths=(32, 32), features=True):
    """A DAgger-style student with random weights and statistics, saved as an agent."""
    import torch

    env = gym.make(tether_gym.ENV_ID, **KWARGS)
    settings = dagger.DaggerSettings(net_arch=widths, symlog_scale=SCALE if features else None)
    policy = dagger.make_student(env, settings)
    gen = torch.Generator().manual_seed(3)
    with torch.no_grad():
        for p in policy.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=gen, dtype=p.dtype))
    n = policy.observation_space.shape[0]
    rng = np.random.default_rng(4)
    norm = ObsNormalization(rng.normal(0, 0.1, n), rng.uniform(0.01, 2.0, n), 5e5)
    spec = FeatureSpec("symlog_errors", SCALE).to_dict() if features else None
    save_agent(path, policy, "ppo", norm, tether_gym.ENV_ID, KWARGS, features=spec)
    env.close()
    return path


def _config(tmp_path, agent, **changes):
    block = {"policy": "MlpPolicy", "init_policy": str(agent), "n_envs": 2,
             "n_timesteps": 64, "normalize": {"norm_obs": True, "norm_reward": True},
             "n_steps": 32, "batch_size": 32, "n_epochs": 1, "learning_rate": 1e-4,
             "policy_kwargs": {"net_arch": {"pi": [32, 32], "vf": [16]},
                               "log_std_init": -4.5},
             "features": {"name": "symlog_errors", "scale": SCALE},
             "env_kwargs": dict(KWARGS), "eval_freq": 64, "checkpoint_freq": 64}
    for key, value in changes.items():
        if value is None:
            block.pop(key)
        else:
            block[key] = value
    path = tmp_path / "ft.yml"
    path.write_text(yaml.safe_dump({tether_gym.ENV_ID: block}))
    return path


@pytest.fixture(scope="module")
def agent(tmp_path_factory):
    return _agent(tmp_path_factory.mktemp("student") / "agent")


def test_the_warm_started_model_acts_as_the_agent(agent, tmp_path):
    options = TrainOptions(config=str(_config(tmp_path, agent)), out=str(tmp_path / "run"),
                           no_progress=True)
    model, venv, eval_env = _model(resolve_settings(options))
    student = TrainedAgent.load(agent)
    env = gym.make(tether_gym.ENV_ID, **KWARGS)
    raw = np.stack([env.reset(seed=s)[0] for s in range(16)]).astype(np.float32)
    raw[:, :2] += np.random.default_rng(5).normal(0, 0.02, (16, 2)).astype(np.float32)
    inputs = add_features(FeatureSpec("symlog_errors", SCALE), raw, 2)
    ours = model.policy.predict(venv.normalize_obs(inputs), deterministic=True)[0]
    theirs = student.predict(raw, deterministic=True)[0]
    assert np.abs(theirs).max() > 0.05  # the check is not on a law that is ~0 everywhere
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(venv.obs_rms.mean, student.norm.mean)
    np.testing.assert_array_equal(venv.obs_rms.var, student.norm.var)
    assert venv.obs_rms.count == student.norm.count
    # the critic and the noise are new: the exploration std is the config's
    np.testing.assert_allclose(model.policy.log_std.detach().numpy(), -4.5)
    for e in (venv, eval_env, env):
        e.close()


@pytest.mark.parametrize("changes, named", [
    ({"features": {"name": "symlog_errors", "scale": 1e-3}}, "input features"),
    ({"features": None}, "input features"),
    ({"env_kwargs": {**KWARGS, "action_mode": "increment"}}, "action_mode='rate'"),
    ({"normalize": False}, "normalises its observations"),
    ({"init_policy": "no/such/agent"}, "does not exist"),
    ({"init_policy": 3}, "must be the path of a trained agent"),
])
def test_a_mismatch_is_refused_before_the_run_folder(agent, tmp_path, changes, named, capsys):
    out = tmp_path / "run"
    code = train_main(["--config", str(_config(tmp_path, agent, **changes)), "--out", str(out),
                       "--no-progress"])
    assert code == 2
    err = capsys.readouterr().err
    assert "init_policy" in err and named in err, err
    assert not out.exists()


def test_other_algorithms_are_refused(agent, tmp_path):
    options = TrainOptions(algo="sac", config=str(_config(
        tmp_path, agent, n_epochs=None, policy_kwargs={"net_arch": [32, 32]})),
                           out=str(tmp_path / "run"))
    with pytest.raises(ConfigError, match="init_policy starts an on-policy actor-critic"):
        resolve_settings(options)


def test_other_widths_are_refused_when_the_model_is_built(agent, tmp_path):
    config = _config(tmp_path, agent, policy_kwargs={"net_arch": {"pi": [64, 32], "vf": [16]}})
    options = TrainOptions(config=str(config), out=str(tmp_path / "run"))
    with pytest.raises(ConfigError, match=r"set policy_kwargs.net_arch.pi to the agent's widths"):
        _model(resolve_settings(options))


def test_train_py_records_the_key_and_resumes_without_the_agent(tmp_path):
    agent = _agent(tmp_path / "agent")
    out = tmp_path / "run"
    config = _config(tmp_path, agent)
    assert train_main(["--config", str(config), "--out", str(out), "--no-progress",
                       "--eval-episodes", "1"]) == 0
    recorded = yaml.safe_load((out / "config.yml").read_text())
    assert recorded["hyperparams"]["init_policy"] == str(agent)
    info = json.loads((out / "train_info.json").read_text())
    assert info["num_timesteps"] == 64
    student = TrainedAgent.load(agent).norm
    # the statistics stayed the agent's through the rollouts (they are fixed)
    trained = TrainedAgent.load(out / "final_agent").norm
    np.testing.assert_array_equal(trained.mean, student.mean)
    np.testing.assert_array_equal(trained.var, student.var)
    for f in agent.iterdir():  # a resumed run starts from its own checkpoint
        f.unlink()
    agent.rmdir()
    assert train_main(["--out", str(out), "--resume", "--timesteps", "64", "--no-progress",
                       "--eval-episodes", "1"]) == 0
    assert json.loads((out / "train_info.json").read_text())["num_timesteps"] == 128
    resumed = TrainedAgent.load(out / "final_agent").norm  # and through the resumed ones
    np.testing.assert_array_equal(resumed.mean, student.mean)
    np.testing.assert_array_equal(resumed.var, student.var)


def test_seed_field_picks_each_seeds_own_agent(tmp_path, monkeypatch):
    """``{seed}`` stands for the run's training seed; a shipped agent's name is found in
    ``agents/pretrained/`` (what ``agents/configs/distill_ppo.yml`` relies on)."""
    from tether_gym_agents.training import warm_start

    for k in (3, 4):
        _agent(tmp_path / "students" / f"seed_{k}", widths=(32, 32))
    config = _config(tmp_path, tmp_path / "students" / "seed_{seed}")
    for k in (3, 4):
        options = TrainOptions(config=str(config), out=str(tmp_path / f"run{k}"), seed=k,
                               no_progress=True)
        settings = resolve_settings(options)
        assert settings.run["init_policy"] == str(tmp_path / "students" / f"seed_{k}")
    with pytest.raises(ConfigError, match="seed_5"):  # no such student: named, before a run
        resolve_settings(TrainOptions(config=str(config), out=str(tmp_path / "run5"), seed=5,
                                      no_progress=True))
    assert not (tmp_path / "run5").exists()
    assert warm_start.init_policy_for("a/{seed}/b_{seed}", 7) == "a/7/b_7"
    assert warm_start.init_policy_for("a/{seeds}/{0}", 7) == "a/{seeds}/{0}"  # no format
    monkeypatch.setattr(warm_start, "pretrained_agents",
                        lambda: {"student": tmp_path / "students"})
    monkeypatch.chdir(tmp_path / "students")  # no folder "student" here
    assert warm_start.agent_location("student/seed_3") == tmp_path / "students" / "seed_3"
    here = warm_start.agent_location("seed_3")  # an existing path wins
    assert here.resolve() == (tmp_path / "students" / "seed_3").resolve()
    assert warm_start.agent_location("nothing/seed_3").as_posix() == "nothing/seed_3"
