"""Training settings out of bounds (issue 33): each is one line naming the config file, the
key, the value and the allowed range, exit 2, before anything is allocated or trained.

Before: ``n_envs: 1000000000`` / ``buffer_size: 1000000000000`` asked for 74.5 GiB /
72.8 TiB; ``learning_rate: 1.0e+308``, ``vf_coef``, ``ent_coef``, ``caps_temporal`` or
TD3's target noise of 1e300 gave NaN actions or an overflow mid-run; unknown buffer keys
a TypeError from stable-baselines3; ``n_epochs: 1000000000`` and ``n_critics: 1000000``
hung; a batch larger than the rollout or the buffer was accepted; and ``env_kwargs:
{eccentricity: .nan}`` was reported as "got NoneType None" (train.py records env kwargs
as JSON, where NaN becomes null).
"""

from __future__ import annotations

import pytest

from tether_gym_agents.cli.train import main
from tether_gym_agents.common.algorithms import ALGORITHMS
from tether_gym_agents.training.hyperparams import _CHECKS, _POLICY_KWARGS

ENV = "tether_gym/TetherLibration-v2"

HOSTILE = {  # case: (algo, YAML lines under the env id, expected message after the file)
    "n_envs 1e9": ("ppo", "n_envs: 1000000000",
                   "n_envs: 1000000000 must be a whole number in [1, 1024]"),
    "buffer_size 1e12": ("sac", "buffer_size: 1000000000000",
                         "buffer_size: 1000000000000 must be a whole number in [1, 10000000]"),
    "buffer_size 1e12 float": ("tqc", "buffer_size: 1.0e+12",
                               "buffer_size: 1000000000000.0 must be a whole number in "
                               "[1, 10000000]"),
    "learning_rate 1e308": ("ppo", "learning_rate: 1.0e+308",
                            "learning_rate: 1e+308 must be a number or 'lin_<start>', in "
                            "(0, 1]"),
    "learning_rate lin_1e308": ("sac", "learning_rate: lin_1e308",
                                "learning_rate: 'lin_1e308' must be a number or "
                                "'lin_<start>', in (0, 1]"),
    "rollout_buffer_kwargs": ("ppo", "rollout_buffer_kwargs: {gamma: 0.5}",
                              "rollout_buffer_kwargs: {'gamma': 0.5} must be null or a mapping "
                              "of []; ['gamma'] not allowed"),
    "replay_buffer_kwargs": ("sac", "replay_buffer_kwargs: {foo: 1}",
                             "replay_buffer_kwargs: {'foo': 1} must be null or a mapping of "
                             "['handle_timeout_termination']; ['foo'] not allowed"),
    "n_epochs 1e9": ("ppo", "n_epochs: 1000000000",
                     "n_epochs: 1000000000 must be a whole number in [1, 1000]"),
    "gradient_steps 1e9": ("td3", "gradient_steps: 1000000000",
                           "gradient_steps: 1000000000 must be a whole number in [1, 1000]"),
    "n_critics 1e6": ("sac", "policy_kwargs: {n_critics: 1000000}",
                      "policy_kwargs.n_critics: 1000000 must be a whole number in [1, 16]"),
    "n_critics td3": ("td3", "policy_kwargs: {n_critics: 1000000}",
                      "policy_kwargs.n_critics: 1000000 must be a whole number in [1, 16]"),
    "n_quantiles": ("tqc", "policy_kwargs: {n_quantiles: 100000}",
                    "policy_kwargs.n_quantiles: 100000 must be a whole number in [1, 256]"),
    "batch > rollout": ("ppo", "n_envs: 2\n  n_steps: 8\n  batch_size: 64",
                        "batch_size: 64 must be <= n_steps x n_envs = 8 x 2 = 16"),
    "rollout too big": ("ppo", "n_envs: 1024\n  n_steps: 100000",
                        "n_steps x n_envs: 100000 x 1024 = 102400000 must be <= 10000000"),
    "batch > buffer": ("sac", "buffer_size: 100\n  batch_size: 256",
                       "batch_size: 256 must be <= buffer_size (100)"),
    "batch > buffer td3": ("td3", "buffer_size: 10\n  batch_size: 11",
                           "batch_size: 11 must be <= buffer_size (10)"),
    "log_std_init td3": ("td3", "policy_kwargs: {log_std_init: 0.0}",
                         "policy_kwargs: unknown key 'log_std_init' for TD3"),
    "nan env_kwargs": ("ppo", "env_kwargs: {eccentricity: .nan}",
                       "env_kwargs.eccentricity: nan must be finite"),
    "inf env_kwargs list": ("sac", "env_kwargs: {masses: [1.0, .inf]}",
                            "env_kwargs.masses[1]: inf must be finite"),
    "nan normalize": ("ppo", "normalize: {clip_obs: .nan}",
                      "normalize.clip_obs: nan must be finite"),
    "nan learning_rate": ("td3", "learning_rate: .nan",
                          "learning_rate: nan must be a number"),
    "vf_coef 1e300": ("ppo", "vf_coef: 1.0e+300",
                      "vf_coef: 1e+300 must be a finite number >= 0 and <= 1000"),
    "ent_coef ppo 1e300": ("ppo", "ent_coef: 1.0e+300",
                           "ent_coef: 1e+300 must be a finite number >= 0 and <= 1000"),
    "ent_coef sac 1e300": ("sac", "ent_coef: 1.0e+300",
                           "ent_coef: 1e+300 must be a number in [0, 1000], 'auto'"),
    "ent_coef auto_1e300": ("tqc", "ent_coef: auto_1e300", "ent_coef: 'auto_1e300' must be"),
    "caps_temporal 1e300": ("sac", "caps_temporal: 1.0e+300",
                            "caps_temporal: 1e+300 must be a finite number >= 0 and <= 1000"),
    "caps_sigma 1e300": ("tqc", "caps_sigma: 1.0e+300",
                         "caps_sigma: 1e+300 must be a finite number >= 0 and <= 10"),
    "target_noise_clip 1e300": ("td3", "target_noise_clip: 1.0e+300",
                                "target_noise_clip: 1e+300 must be a finite number >= 0 and "
                                "<= 10"),
    "weight_decay 1e300": ("ppo", "policy_kwargs: {optimizer_kwargs: {weight_decay: 1.0e+300}}",
                           "policy_kwargs.optimizer_kwargs: {'weight_decay': 1e+300} must be "
                           "weight_decay: a finite number >= 0 and <= 1"),
    "policy_delay": ("td3", "policy_delay: 0", "policy_delay: 0 must be a whole number in"),
    "target_policy_noise": ("td3", "target_policy_noise: -1",
                            "target_policy_noise: -1 must be a finite number >= 0"),
}


@pytest.fixture
def no_training(monkeypatch):
    def refuse(settings):
        raise AssertionError("a hostile setting reached training")
    monkeypatch.setattr("tether_gym_agents.cli.train.train", refuse)


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_setting_is_one_line_naming_file_key_value_range(tmp_path, capsys,
                                                                 no_training, case):
    algo, lines, message = HOSTILE[case]
    config = tmp_path / "hostile.yml"
    config.write_text(f"{ENV}:\n  {lines}\n")
    out = tmp_path / "run"
    assert main(["--algo", algo, "--config", str(config), "--out", str(out),
                 "--timesteps", "64", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith(f"train.py: error: {config}: {message}"), err
    assert not out.exists()


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_every_keyword_of_every_algorithm_is_checked(algo):
    """The table's rows say which keywords an algorithm takes; each has a check here (a
    row added without its checks fails this test, not a user's run)."""
    row = ALGORITHMS[algo]
    unchecked = sorted(row.hyperparams - set(_CHECKS) - {"n_steps", "ent_coef",
                                                         "policy_kwargs"})
    assert not unchecked
    loose = sorted(row.policy_kwargs - set(_POLICY_KWARGS) - set(row.defaults)
                   - {"net_arch", "activation_fn", "optimizer_kwargs",
                      "features_extractor_class", "features_extractor_kwargs"})
    assert not loose


def test_bounds_refuse_nothing_a_shipped_config_holds(tmp_path, capsys, no_training):
    """The shipped configs stay valid; a batch equal to the rollout or buffer is allowed."""
    for algo, lines in (("ppo", "n_envs: 1024\n  n_steps: 9765\n  batch_size: 9999360"),
                        ("sac", "buffer_size: 256\n  batch_size: 256\n  "
                                "replay_buffer_kwargs: {handle_timeout_termination: false}"),
                        ("ppo", "learning_rate: 1\n  n_epochs: 1000")):
        config = tmp_path / f"{algo}.yml"
        config.write_text(f"{ENV}:\n  {lines}\n")
        with pytest.raises(AssertionError, match="reached training"):
            main(["--algo", algo, "--config", str(config), "--out", str(tmp_path / "r"),
                  "--timesteps", "64", "--no-progress"])


def test_every_shipped_config_is_within_the_bounds():
    import glob

    import yaml

    from tether_gym_agents.training.config import CONFIG_DIR, config_algo, load_hyperparams

    checked = 0
    for path in sorted(glob.glob(str(CONFIG_DIR / "*.yml"))):
        name = path.rsplit("/", 1)[-1]
        algo = config_algo(name)
        if algo is None:
            continue  # gpu_*.yml: train.py gpu's own format and bounds
        for env_id in yaml.safe_load(open(path)):
            if env_id != "default":
                load_hyperparams(path, algo, env_id)
                checked += 1
    assert checked >= 7
