"""TD3, added through the algorithm table: train.py trains it, resumes it, saves a safe
agent that loads and acts, and evaluate.py scores it; its action noise is checked."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

import tether_gym
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main
from tether_gym_agents.training.config import CONFIG_DIR, load_hyperparams

TINY = ["--n-envs", "2", "--no-progress", "--eval-freq", "256", "--checkpoint-freq", "256",
        "--eval-episodes", "1", "--env-kwargs", "orbits_per_episode=0.05"]


def _tiny_config(tmp_path, **changes):
    """The shipped td3.yml with a small buffer, an early start and small networks."""
    doc = yaml.safe_load((CONFIG_DIR / "td3.yml").read_text())
    block = {**doc[tether_gym.ENV_ID], "learning_starts": 64, "batch_size": 32,
             "buffer_size": 2000, "policy_kwargs": {"net_arch": [16, 16]}, **changes}
    path = tmp_path / "td3.yml"
    path.write_text(yaml.safe_dump({tether_gym.ENV_ID: block, "default": doc["default"]}))
    return path


def test_the_shipped_config_is_valid():
    params = load_hyperparams(CONFIG_DIR / "td3.yml", "td3", tether_gym.ENV_ID)
    assert (params["noise_type"], params["noise_std"], params["policy_delay"]) == (
        "normal", 0.1, 2)


def test_train_py_trains_td3_resumes_and_evaluate_py_scores_it(tmp_path, capsys):
    from stable_baselines3 import TD3
    from stable_baselines3.common.noise import NormalActionNoise

    from tether_gym_agents.files.pickled import load_pickled_run
    from tether_gym_agents.files.trained import TrainedAgent

    out = tmp_path / "run"
    assert main(["--algo", "td3", "--config", str(_tiny_config(tmp_path)), "--out", str(out),
                 "--timesteps", "256", *TINY]) == 0
    assert (out / "final_replay_buffer.npz").is_file()  # off-policy: its buffer is kept
    assert main(["--algo", "td3", "--out", str(out), "--timesteps", "128", "--resume",
                 *TINY]) == 0
    assert "with its replay buffer" in capsys.readouterr().out
    info = json.loads((out / "train_info.json").read_text())
    assert info["num_timesteps"] == 384

    model = TD3.load(out / "final_model.zip", device="cpu")  # our own file
    assert (model.policy_delay, model.target_policy_noise, model.learning_starts) == (
        2, 0.2, 64)
    noise = model.action_noise.base_noise  # SB3 gives each of the 2 envs a copy (VecNoise)
    assert isinstance(noise, NormalActionNoise)  # the config's noise, resumed
    np.testing.assert_array_equal(noise._sigma, [0.1, 0.1])

    meta = json.loads((out / "final_agent" / "agent.json").read_text())
    assert (meta["algo"], meta["policy_class"], meta["weights"]["module"]) == (
        "td3", "TD3Policy", "actor")
    assert "log_std_init" not in meta["policy_kwargs"]  # a deterministic actor
    agent = TrainedAgent.load(out / "final_agent")
    assert agent.algo == "td3" and agent.mlp is not None  # the float64 forward pass
    obs = np.random.default_rng(0).normal(size=(5, *agent.model.observation_space.shape))
    obs = obs.astype(np.float32)
    # the NumPy pass equals the policy's own (TD3's tanh ends mu; it is not applied twice)
    np.testing.assert_allclose(agent.mlp(obs), agent.model.predict(obs, deterministic=True)[0],
                               rtol=0, atol=2e-6)
    action, _ = agent.predict(obs[0])
    assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)

    # the pickled model is read (on opt-in) by the row's library class
    with pytest.warns(UserWarning, match="pickle"):
        pickled = load_pickled_run(out, allow_pickle=True)
    assert (pickled.algo, type(pickled.model)) == ("td3", TD3)

    assert evaluate_main([str(out), "--suite", "paper", "--seeds", "1", "--no-plots",
                          "--env-kwargs", "orbits_per_episode=0.2", "--out",
                          str(tmp_path / "eval")]) == 0
    (block,) = json.loads((tmp_path / "eval" / "results.json").read_text())[
        "policies"].values()
    assert block["n_episodes"] == 1


@pytest.mark.parametrize("changes, message", [
    ({"noise_type": "uniform"},
     "noise_type: 'uniform' must be one of ['normal', 'ornstein-uhlenbeck']"),
    ({"noise_std": 5.0}, "noise_std: 5.0 must be a number in [0, 1.0]"),
    ({"noise_std": float("nan")}, "noise_std: nan must be a number in [0, 1.0]"),
    ({"noise_std": "0.1"}, "noise_std: '0.1' must be a number in [0, 1.0]"),
])
def test_bad_action_noise_is_refused_before_any_work(tmp_path, capsys, changes, message):
    out = tmp_path / "r"
    assert main(["--algo", "td3", "--config", str(_tiny_config(tmp_path, **changes)),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "td3.yml" in err and "Traceback" not in err
    assert not (out / "config.yml").exists()


def test_noise_needs_both_keys_and_an_off_policy_algorithm(tmp_path, capsys):
    doc = {"default": {"noise_std": 0.1}}
    cfg = tmp_path / "half.yml"
    cfg.write_text(yaml.safe_dump(doc))
    assert main(["--algo", "td3", "--config", str(cfg), "--out", str(tmp_path / "a")]) == 2
    assert "noise_std needs noise_type" in capsys.readouterr().err
    cfg.write_text(yaml.safe_dump({"default": {"noise_type": "normal", "noise_std": 0.1}}))
    assert main(["--algo", "ppo", "--config", str(cfg), "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "noise_type" in err and "PPO" in err


def test_an_unknown_algorithm_lists_td3(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--algo", "dqn"])
    assert exc.value.code == 2
    assert "'ppo', 'ppo_lag', 'sac', 'td3', 'tqc'" in capsys.readouterr().err
