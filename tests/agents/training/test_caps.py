"""CapsSAC: with zero weights it is SAC step for step; with weights it smooths the actor."""

import numpy as np
import pytest
import torch as th
from stable_baselines3 import SAC

from tether_gym_agents.training.caps import CapsSAC, smoothness_terms
from tether_gym_agents.training.vec_env import make_sb3_vec_env


def _model(cls, **kwargs):
    env = make_sb3_vec_env(2, seed=0, env_kwargs={"increment_gain": 0.5})
    return cls("MlpPolicy", env, seed=3, device="cpu", learning_starts=50, batch_size=32,
               policy_kwargs={"net_arch": [16, 16]}, **kwargs)


def _actor_weights(model):
    return th.cat([p.detach().flatten() for p in model.actor.parameters()])


def test_zero_weights_are_sac():
    th.manual_seed(0)
    caps = _model(CapsSAC).learn(120)
    th.manual_seed(0)
    sac = _model(SAC).learn(120)
    assert th.equal(_actor_weights(caps), _actor_weights(sac))


def test_own_loop_equals_sac_when_terms_weigh_nothing():
    # a tiny sigma turns the smoothing loop on; weights of 0 leave SAC's update
    th.manual_seed(0)
    caps = _model(CapsSAC, caps_magnitude=1e-300).learn(120)
    th.manual_seed(0)
    sac = _model(SAC).learn(120)
    assert caps.smoothing
    np.testing.assert_allclose(_actor_weights(caps).numpy(), _actor_weights(sac).numpy(),
                               atol=1e-5)


def test_magnitude_term_shrinks_the_actions():
    model = _model(CapsSAC, caps_magnitude=100.0).learn(400)
    obs = th.as_tensor(model.replay_buffer.observations[:200, 0], dtype=th.float32)
    _, _, magnitude = smoothness_terms(model.actor, obs, obs, 0.0)
    assert magnitude.item() < 0.05


@pytest.mark.parametrize("name", ["caps_temporal", "caps_spatial", "caps_magnitude",
                                  "caps_sigma"])
def test_bad_weights_are_refused(name):
    with pytest.raises(ValueError, match=name):
        _model(CapsSAC, **{name: -1.0})


def test_train_py_trains_caps_sac_from_a_config(tmp_path):
    """train.py --algo sac: the config's caps_* keys reach the model, and resume keeps them."""
    import yaml

    from tether_gym_agents.cli.train import main
    from tether_gym_agents.training.config import algo_class

    assert algo_class("sac") is CapsSAC and issubclass(CapsSAC, SAC)
    cfg = tmp_path / "caps.yml"
    cfg.write_text(yaml.safe_dump({"default": {
        "policy": "MlpPolicy", "learning_starts": 64, "batch_size": 32, "buffer_size": 2000,
        "caps_magnitude": 3.0, "caps_temporal": 0.5, "caps_sigma": 0.1,
        "policy_kwargs": {"net_arch": [16, 16]}}}))
    out = tmp_path / "run"
    tiny = ["--n-envs", "2", "--no-progress", "--eval-freq", "256", "--checkpoint-freq",
            "256", "--eval-episodes", "1", "--env-kwargs", "orbits_per_episode=0.05"]
    assert main(["--algo", "sac", "--config", str(cfg), "--out", str(out), "--timesteps",
                 "256", *tiny]) == 0
    resolved = yaml.safe_load((out / "config.yml").read_text())["hyperparams"]
    assert resolved["caps_magnitude"] == 3.0 and resolved["caps_temporal"] == 0.5
    assert main(["--algo", "sac", "--out", str(out), "--timesteps", "128", "--resume",
                 *tiny]) == 0
    model = CapsSAC.load(out / "final_model.zip", device="cpu")  # our own file
    assert (model.caps_magnitude, model.caps_temporal, model.caps_spatial,
            model.caps_sigma) == (3.0, 0.5, 0.0, 0.1)
    assert model.num_timesteps >= 384



# --- TQC (sb3-contrib, the `tqc` extra) -------------------------------------------------

def test_tqc_with_zero_weights_is_tqc_and_its_own_loop_matches_it():
    from sb3_contrib import TQC

    from tether_gym_agents.training.caps import caps_tqc_class

    caps_tqc = caps_tqc_class()
    assert caps_tqc is caps_tqc_class() and issubclass(caps_tqc, TQC)
    th.manual_seed(0)
    plain = _model(TQC).learn(120)
    th.manual_seed(0)
    zero = _model(caps_tqc).learn(120)
    assert th.equal(_actor_weights(zero), _actor_weights(plain))
    # the smoothing loop with a weight of ~0: TQC's target and loss, through the hooks
    th.manual_seed(0)
    loop = _model(caps_tqc, caps_magnitude=1e-300).learn(120)
    assert loop.smoothing
    np.testing.assert_allclose(_actor_weights(loop).numpy(), _actor_weights(plain).numpy(),
                               atol=1e-5)
    crit_loop = th.cat([p.detach().flatten() for p in loop.critic.parameters()])
    crit_plain = th.cat([p.detach().flatten() for p in plain.critic.parameters()])
    np.testing.assert_allclose(crit_loop.numpy(), crit_plain.numpy(), atol=1e-5)


def test_tqc_magnitude_term_shrinks_the_actions():
    from tether_gym_agents.training.caps import caps_tqc_class

    model = _model(caps_tqc_class(), caps_magnitude=100.0).learn(400)
    obs = th.as_tensor(model.replay_buffer.observations[:200, 0], dtype=th.float32)
    _, _, magnitude = smoothness_terms(model.actor, obs, obs, 0.0)
    assert magnitude.item() < 0.05


def test_train_py_trains_tqc_and_evaluate_py_scores_it(tmp_path, capsys):
    """--algo tqc through train.py (with resume) and the safe agent through evaluate.py."""
    import json

    import yaml

    from tether_gym_agents.cli.evaluate import main as evaluate_main
    from tether_gym_agents.cli.train import main
    from tether_gym_agents.files.trained import TrainedAgent

    cfg = tmp_path / "tqc.yml"
    cfg.write_text(yaml.safe_dump({"default": {
        "policy": "MlpPolicy", "learning_starts": 64, "batch_size": 32, "buffer_size": 2000,
        "top_quantiles_to_drop_per_net": 3, "caps_magnitude": 1.0,
        "policy_kwargs": {"net_arch": [16, 16], "n_quantiles": 5, "n_critics": 3}}}))
    out = tmp_path / "run"
    tiny = ["--n-envs", "2", "--no-progress", "--eval-freq", "256", "--checkpoint-freq",
            "256", "--eval-episodes", "1", "--env-kwargs", "orbits_per_episode=0.05"]
    assert main(["--algo", "tqc", "--config", str(cfg), "--out", str(out), "--timesteps",
                 "256", *tiny]) == 0
    assert main(["--algo", "tqc", "--out", str(out), "--timesteps", "128", "--resume",
                 *tiny]) == 0
    model = caps_tqc_model(out)
    assert (model.top_quantiles_to_drop_per_net, model.critic.n_quantiles,
            model.critic.n_critics, model.caps_magnitude) == (3, 5, 3, 1.0)
    meta = json.loads((out / "agent.json").read_text())
    assert (meta["algo"], meta["policy_class"]) == ("tqc", "TQCPolicy")
    agent = TrainedAgent.load(out)
    assert agent.algo == "tqc" and agent.mlp is not None  # TQC's actor is SAC's MLP
    obs = np.zeros(agent.model.observation_space.shape, dtype=np.float32)
    action, _ = agent.predict(obs)
    assert action.shape == (2,) and np.all(np.abs(action) <= 1.0)
    capsys.readouterr()
    assert evaluate_main([str(out), "--suite", "paper", "--seeds", "1", "--no-plots",
                          "--env-kwargs", "orbits_per_episode=0.2", "--out",
                          str(tmp_path / "eval")]) == 0
    (block,) = json.loads((tmp_path / "eval" / "results.json").read_text())[
        "policies"].values()
    assert block["n_episodes"] == 1


def caps_tqc_model(out):
    from tether_gym_agents.training.caps import caps_tqc_class

    return caps_tqc_class().load(out / "final_model.zip", device="cpu")  # our own file


def test_tqc_quantiles_to_drop_are_checked_before_any_work(tmp_path, capsys):
    import yaml

    from tether_gym_agents.cli.train import main

    cfg = tmp_path / "tqc.yml"
    cfg.write_text(yaml.safe_dump({"default": {
        "top_quantiles_to_drop_per_net": 5, "policy_kwargs": {"n_quantiles": 5}}}))
    assert main(["--algo", "tqc", "--config", str(cfg), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "top_quantiles_to_drop_per_net: 5 must be < policy_kwargs.n_quantiles (5)" in err
    assert not (tmp_path / "r" / "config.yml").exists()


def test_missing_sb3_contrib_names_the_pip_command(monkeypatch, tmp_path, capsys):
    import sys

    from tether_gym_agents.cli.train import main
    from tether_gym_agents.training import caps

    monkeypatch.setattr(caps, "_TQC_CLASS", [])
    monkeypatch.setitem(sys.modules, "sb3_contrib", None)  # import sb3_contrib fails
    with pytest.raises(ImportError, match="pip install"):
        caps.caps_tqc_class()
    assert main(["--algo", "tqc", "--out", str(tmp_path / "r")]) == 2
    assert "pip install" in capsys.readouterr().err
