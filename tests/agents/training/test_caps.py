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

