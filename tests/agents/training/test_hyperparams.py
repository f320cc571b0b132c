"""Every PPO/SAC hyperparameter is checked before any work: one line, the key named, exit 2.

Before these checks the values below reached stable-baselines3 or torch and failed there
with a traceback (or, for ``gamma: 2``, with NaNs some updates later).
"""

from __future__ import annotations

import importlib.util

import pytest
import yaml

from tether_gym_agents.cli.train import main
from tether_gym_agents.training import run
from tether_gym_agents.training.config import ConfigError, fit_rollout, with_schedules
from tether_gym_agents.training.hyperparams import check_hyperparams

BAD = [  # (algo, config values, the key the message names)
    ("ppo", {"batch_size": 0}, "batch_size"),
    ("ppo", {"n_steps": 0}, "n_steps"),
    ("ppo", {"n_steps": 1.5}, "n_steps"),
    ("ppo", {"learning_rate": -1}, "learning_rate"),
    ("ppo", {"gamma": 2}, "gamma"),
    ("ppo", {"policy": "CnnPolicy"}, "policy"),
    ("ppo", {"policy_kwargs": {"activation_fn": "Tanhh"}}, "policy_kwargs.activation_fn"),
    ("ppo", {"policy_kwargs": {"net_arch": "big"}}, "policy_kwargs.net_arch"),
    ("ppo", {"policy_kwargs": {"net_arch": [200000, 200000]}}, "policy_kwargs.net_arch"),
    ("ppo", {"policy_kwargs": {"net_arch": {"pi": [64], "qf": [64]}}}, "policy_kwargs.net_arch"),
    ("ppo", {"policy_kwargs": {"net_arch": [4096] * 3}}, "policy_kwargs.net_arch"),  # 33M
    ("ppo", {"policy_kwargs": {"net_arch": [8] * 9}}, "policy_kwargs.net_arch"),
    ("ppo", {"policy_kwargs": {"log_std_init": "low"}}, "policy_kwargs.log_std_init"),
    ("ppo", {"policy_kwargs": {"features_extractor_class": "os.system"}}, "policy_kwargs"),
    ("ppo", {"policy_kwargs": "dict(net_arch=[8])"}, "policy_kwargs"),
    ("ppo", {"gae_lambda": -0.1}, "gae_lambda"),
    ("ppo", {"clip_range": "lin_x"}, "clip_range"),
    ("ppo", {"clip_range": 0}, "clip_range"),
    ("ppo", {"n_epochs": 0}, "n_epochs"),
    ("ppo", {"ent_coef": "auto"}, "ent_coef"),
    ("ppo", {"vf_coef": float("nan")}, "vf_coef"),
    ("ppo", {"max_grad_norm": 0}, "max_grad_norm"),
    ("ppo", {"target_kl": -0.01}, "target_kl"),
    ("ppo", {"use_sde": "yes"}, "use_sde"),
    ("ppo", {"sde_sample_freq": 0}, "sde_sample_freq"),
    ("ppo", {"normalize_advantage": 1}, "normalize_advantage"),
    ("ppo", {"rollout_buffer_class": "DictRolloutBuffer"}, "rollout_buffer_class"),
    ("sac", {"buffer_size": 0}, "buffer_size"),
    ("sac", {"learning_starts": -1}, "learning_starts"),
    ("sac", {"tau": 0}, "tau"),
    ("sac", {"tau": 1.5}, "tau"),
    ("sac", {"train_freq": [1, "epoch"]}, "train_freq"),
    ("sac", {"gradient_steps": 0}, "gradient_steps"),
    ("sac", {"ent_coef": "auto_x"}, "ent_coef"),
    ("sac", {"ent_coef": -0.1}, "ent_coef"),
    ("sac", {"target_entropy": "low"}, "target_entropy"),
    ("sac", {"caps_magnitude": -1.0}, "caps_magnitude"),
    ("sac", {"caps_sigma": float("nan")}, "caps_sigma"),
    ("sac", {"action_noise": "normal"}, "action_noise"),
    ("sac", {"policy_kwargs": {"net_arch": {"pi": [64], "vf": [64]}}}, "policy_kwargs.net_arch"),
    ("sac", {"policy_kwargs": {"ortho_init": True}}, "policy_kwargs"),
    ("sac", {"policy_kwargs": {"n_critics": 0}}, "policy_kwargs.n_critics"),
]


@pytest.fixture
def no_training(monkeypatch):
    """Fail the test if anything reaches the training function."""
    def refuse(settings):
        raise AssertionError("a bad hyperparameter reached training")
    monkeypatch.setattr("tether_gym_agents.cli.train.train", refuse)


@pytest.mark.parametrize(("algo", "values", "key"), BAD,
                         ids=[f"{a}-{k}-{v}" for a, v, k in BAD])
def test_bad_hyperparameter_is_one_line_naming_the_key(tmp_path, capsys, no_training,
                                                       algo, values, key):
    config = tmp_path / "bad.yml"
    config.write_text(yaml.safe_dump({"default": {"policy": "MlpPolicy", **values}}))
    out = tmp_path / "run"
    assert main(["--algo", algo, "--config", str(config), "--out", str(out), "--timesteps",
                 "64", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("train.py: error: ")
    assert f"{key}: " in err and "Traceback" not in err
    assert not out.exists()  # nothing was made, let alone trained


def test_bad_value_in_a_resumed_config_is_named(tmp_path, capsys, no_training):
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.yml").write_text(yaml.safe_dump(
        {"algo": "ppo", "hyperparams": {"policy": "MlpPolicy", "gamma": 2}}))
    assert main(["--out", str(out), "--resume", "--timesteps", "64"]) == 2
    assert "config.yml: gamma: 2 must be a number in [0, 1]" in capsys.readouterr().err


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_shipped_configs_and_sb3_forms_pass(algo):
    from tether_gym_agents.training.config import CONFIG_DIR, config_algo, load_hyperparams

    paths = [p for p in CONFIG_DIR.glob("*.yml") if config_algo(p) == algo]
    assert paths  # ppo.yml and ppo_fast.yml are PPO's; ppo_lag.yml is not
    for path in paths:
        load_hyperparams(path, algo, "tether_gym/TetherLibration-v2")
    good = {"learning_rate": "lin_3e-4", "gamma": 1, "use_sde": False, "sde_sample_freq": -1,
            "policy_kwargs": {"net_arch": [64, 64], "activation_fn": "nn.Tanh",
                              "log_std_init": -2.0, "optimizer_kwargs": {"eps": 1e-5},
                              "use_sde": False}}
    if algo == "ppo":
        good |= {"clip_range": "lin_0.2", "target_kl": None, "ent_coef": 0.0}
        good["policy_kwargs"] |= {"ortho_init": False, "net_arch": {"pi": [8], "vf": [8]}}
    else:
        good |= {"ent_coef": "auto_0.1", "target_entropy": "auto", "train_freq": [1, "episode"],
                 "gradient_steps": -1}
        good["policy_kwargs"] |= {"n_critics": 2, "net_arch": {"pi": [8], "qf": [8]}}
    check_hyperparams(good, algo, "x.yml", "MlpPolicy")


def test_activation_by_name_reaches_the_model_as_a_torch_class():
    import torch

    params = with_schedules({"policy_kwargs": {"activation_fn": "Tanh", "net_arch": [8]}})
    assert params["policy_kwargs"]["activation_fn"] is torch.nn.Tanh


def test_activation_by_name_trains_and_is_recorded_as_written(tmp_path):
    config = tmp_path / "tanh.yml"
    config.write_text(yaml.safe_dump({"default": {
        "policy": "MlpPolicy", "n_steps": 32, "batch_size": 32, "n_epochs": 1,
        "policy_kwargs": {"net_arch": [8], "activation_fn": "Tanh"}}}))
    out = tmp_path / "run"
    assert main(["--config", str(config), "--out", str(out), "--timesteps", "32",
                 "--no-progress", "--eval-episodes", "1", "--env-kwargs",
                 "orbits_per_episode=0.02"]) == 0
    recorded = yaml.safe_load((out / "config.yml").read_text())
    assert recorded["hyperparams"]["policy_kwargs"]["activation_fn"] == "Tanh"


def test_config_error_is_a_value_error():
    with pytest.raises(ConfigError, match="sac.yml: tau: 2 must be"):
        from tether_gym_agents.training.config import check_algo_params

        check_algo_params({"tau": 2}, "sac", "sac.yml")


# --- a budget smaller than one PPO rollout ------------------------------------------------

def test_budget_below_one_rollout_fits_the_rollout():
    params, note = fit_rollout({"n_steps": 2048, "batch_size": 256}, "ppo", 1, 64)
    assert params == {"n_steps": 64, "batch_size": 64}
    assert "--timesteps 64 is less than one PPO rollout (n_steps 2048 x 1 env(s)" in note
    assert fit_rollout({"n_steps": 8}, "ppo", 8, 64) == ({"n_steps": 8}, None)
    assert fit_rollout({}, "ppo", 3, 100)[0] == {"n_steps": 34, "batch_size": 64}
    assert fit_rollout({}, "ppo", 1, 1)[0]["n_steps"] == 2  # SB3 needs 2 samples
    assert "no gradient step" in fit_rollout({"learning_starts": 500}, "sac", 1, 64)[1]


def test_pendulum_64_steps_trains_64_steps_and_says_why(tmp_path, capsys, recwarn):
    out = tmp_path / "pendulum"
    assert main(["--env-id", "Pendulum-v1", "--timesteps", "64", "--out", str(out),
                 "--no-progress", "--eval-episodes", "1"]) == 0
    # one monitor: SB3's generic path wraps each env in Monitor (before, VecMonitor on top
    # warned that it overwrote Monitor's statistics)
    assert not [w for w in recwarn if "already wrapped with a `Monitor`" in str(w.message)]
    text = capsys.readouterr().out
    assert "--timesteps 64 is less than one PPO rollout (n_steps 2048 x 1 env(s)" in text
    assert "trained PPO to step 64 " in text
    recorded = yaml.safe_load((out / "config.yml").read_text())["hyperparams"]
    assert recorded["n_steps"] == 64 and recorded["batch_size"] == 64


@pytest.mark.parametrize("env_id, message", [
    # before: an IndexError traceback from the action noise, after the run folder was made
    ("CartPole-v1", "env 'CartPole-v1' observes a Box of shape (4,) and acts with a "
                    "Discrete of shape (); train.py trains MLP policies on a 1-D Box"),
    # before: gymnasium's DependencyNotInstalled traceback
    ("CarRacing-v3", "env 'CarRacing-v3' cannot be made: "),
])
def test_an_env_train_py_cannot_train_is_one_line(tmp_path, capsys, env_id, message):
    if env_id == "CarRacing-v3" and importlib.util.find_spec("Box2D") is not None:
        pytest.skip("Box2D is installed here: CarRacing can be made")
    out = tmp_path / "run"
    assert main(["--env-id", env_id, "--timesteps", "64", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"train.py: error: {message}") and len(err.splitlines()) == 1, err
    assert not out.exists()


def test_resume_keeps_the_saved_rollout(monkeypatch, tmp_path):
    """--resume trains the saved model: its n_steps is not fitted to the budget."""
    seen = {}
    monkeypatch.setattr(run, "train", lambda s: seen.setdefault("s", s))
    monkeypatch.setattr("tether_gym_agents.cli.train.train", lambda s: seen.setdefault("s", s))
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.yml").write_text(yaml.safe_dump(
        {"algo": "ppo", "hyperparams": {"policy": "MlpPolicy", "n_steps": 512}}))
    assert main(["--out", str(out), "--resume", "--timesteps", "16"]) == 0
    assert seen["s"].hyperparams["n_steps"] == 512 and not seen["s"].notes
