"""The settings of a run: a frozen, typed record of the command line, resolved once."""

from __future__ import annotations

from dataclasses import FrozenInstanceError, fields, replace
from pathlib import Path

import pytest
import yaml

import tether_gym
from tether_gym_agents.cli.train import build_parser
from tether_gym_agents.training.config import CONFIG_DIR, ConfigError
from tether_gym_agents.training.settings import TrainOptions, TrainSettings, resolve_settings

SHORT = ("orbits_per_episode=0.05",)


def test_options_are_the_parser_options_with_the_same_defaults():
    args = build_parser().parse_args([])
    assert [f.name for f in fields(TrainOptions)] == list(vars(args))
    assert TrainOptions.from_namespace(args) == TrainOptions()


def test_options_are_frozen_and_checked_on_every_creation():
    options = TrainOptions(seed=3)
    with pytest.raises(FrozenInstanceError):
        options.seed = 4  # type: ignore[misc]
    with pytest.raises(ConfigError, match=r"--seed -1: must be an integer in \[0, 2147483647\]"):
        replace(options, seed=-1)
    with pytest.raises(ConfigError, match="--n-envs 0: must be an integer >= 1"):
        TrainOptions(n_envs=0)
    with pytest.raises(ConfigError, match="--algo 'a2c': must be one of"):
        TrainOptions(algo="a2c")
    with pytest.raises(ConfigError, match="is not a Python literal"):
        TrainOptions(env_kwargs=("masses=(1,2",))
    with pytest.raises(ConfigError, match="did you mean"):
        TrainOptions(env_id="tether_gym/TetherLibraton-v1")


def test_argv_reproduces_the_options(tmp_path):
    parser = build_parser()
    options = TrainOptions.from_namespace(parser.parse_args([
        "--algo", "sac", "--seeds", "3", "--seed", "2", "--env-kwargs", "eccentricity=0.1",
        "masses=(1, 2, 3)", "--no-progress", "--config", "rel.yml", "--timesteps", "64"]))
    seed = options.seed_run(4, Path("runs/x/seed_4"))
    again = TrainOptions.from_namespace(parser.parse_args(list(seed.argv())))
    assert again == seed
    assert seed.seeds is None and seed.seed == 4 and seed.verbose == 1
    assert seed.config == str(Path("rel.yml").absolute())
    assert seed.out == str(Path("runs/x/seed_4").absolute())
    assert "--seeds" not in seed.argv() and "--algo" in seed.argv()
    assert TrainOptions().argv() == ()


def test_resolved_once_then_derived_per_seed(tmp_path):
    options = TrainOptions(out=str(tmp_path / "run"), env_kwargs=SHORT + ("n_bodies=4",),
                           timesteps=64)
    settings = resolve_settings(options, command=("--out", "x"))
    assert isinstance(settings, TrainSettings) and settings.source == str(CONFIG_DIR / "ppo.yml")
    with pytest.raises(FrozenInstanceError):
        settings.timesteps = 5  # type: ignore[misc]
    packaged = yaml.safe_load((CONFIG_DIR / "ppo.yml").read_text())[tether_gym.ENV_ID]
    assert settings.n_envs == packaged["n_envs"] and settings.timesteps == 64
    assert settings.hyperparams["gamma"] == 0.995 and "normalize" not in settings.hyperparams
    assert settings.env_kwargs["initial_theta"] == [0.0, 0.0, 0.0]  # follows n_bodies
    assert settings.command_line == "python train.py --out x"
    seed = settings.for_seed(7, tmp_path / "fan" / "seed_7", timesteps=32)
    assert (seed.seed, seed.timesteps, seed.out) == (7, 32, tmp_path / "fan" / "seed_7")
    assert seed.hyperparams == settings.hyperparams and seed.options.timesteps == 32
    assert seed.command == seed.options.argv(keep=("seed",))
    assert seed.command[seed.command.index("--seed") + 1] == "7"
    first = settings.for_seed(0, tmp_path / "fan" / "seed_0")  # seed 0 is named too
    assert first.command[first.command.index("--seed") + 1] == "0"
    assert "--seed" not in first.options.argv()  # the default, left out elsewhere
    config = seed.resolved_config()
    assert config["seed"] == 7 and config["hyperparams"]["n_envs"] == settings.n_envs
    with pytest.raises(ConfigError, match="n_envs 0: must be an integer >= 1"):
        replace(settings, n_envs=0)


def test_settings_are_built_by_keyword_and_each_field_holds_its_value(tmp_path):
    options = TrainOptions(out=str(tmp_path / "run"), env_kwargs=SHORT, n_envs=2)
    settings = resolve_settings(options)
    doc = yaml.safe_load((CONFIG_DIR / "ppo.yml").read_text())
    block = doc[tether_gym.ENV_ID]
    assert settings.options is options and settings.out == tmp_path / "run"
    assert settings.run["policy"] == block["policy"] and "policy" not in settings.hyperparams
    assert settings.env_kwargs["obs_noise"] == block["env_kwargs"]["obs_noise"]
    assert settings.residual is None and settings.features is None
    assert (settings.n_envs, settings.timesteps) == (2, block["n_timesteps"])
    assert (settings.eval_freq, settings.checkpoint_freq) == (
        doc["default"]["eval_freq"], doc["default"]["checkpoint_freq"])
    assert settings.source == str(CONFIG_DIR / "ppo.yml")
    values = [getattr(settings, f.name) for f in fields(TrainSettings)]
    with pytest.raises(TypeError):
        TrainSettings(*values)  # type: ignore[misc]
    assert TrainSettings(**{f.name: getattr(settings, f.name)
                            for f in fields(TrainSettings)}) == settings


def test_resolution_errors_are_exceptions_with_their_message(tmp_path):
    with pytest.raises(ConfigError, match="--resume: .*config.yml not found"):
        resolve_settings(TrainOptions(out=str(tmp_path / "none"), resume=True))
    bad = tmp_path / "bad.yml"
    bad.write_text("default: {learning_rat: 0.1}\n")
    with pytest.raises(ConfigError, match="learning_rat.*valid keys"):
        resolve_settings(TrainOptions(config=str(bad), out=str(tmp_path / "o")))
    with pytest.raises(ConfigError, match="eccentricity"):
        resolve_settings(TrainOptions(env_kwargs=("eccentricity=1.5",),
                                      out=str(tmp_path / "o")))
    assert not (tmp_path / "o").exists()  # the folder is made only for valid settings
