"""The shipped hyperparameter files: keyed by the current env id, and working with
rl-baselines3-zoo as they are."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys

import pytest
import yaml

import tether_gym
from tether_gym_agents.training.config import CONFIG_DIR, RUN_KEYS, load_hyperparams

ZOO_KEYS = ("policy", "n_envs", "n_timesteps", "normalize", "env_kwargs", "noise_type",
            "noise_std")
"""The keys of RUN_KEYS that rl_zoo3 reads itself (its ExperimentManager takes them out of
the block before it passes the rest to the algorithm; the action noise's too)."""
NOISE_KEYS = ("noise_type", "noise_std")
"""Zoo's keys a block may leave out (no action noise)."""
OWN_KEYS = frozenset(RUN_KEYS) - frozenset(ZOO_KEYS)
"""train.py's own keys: zoo would pass them to the algorithm, which rejects them."""

TINY = {"ppo": ["n_envs:2", "n_steps:64", "batch_size:64"],
        "sac": ["n_envs:2", "learning_starts:64", "batch_size:32", "buffer_size:1000"],
        "td3": ["n_envs:2", "learning_starts:64", "batch_size:32", "buffer_size:1000"]}


CONFIGS = sorted(CONFIG_DIR.glob("*.yml"))


def test_the_shipped_configs_are_found():
    assert {"ppo.yml", "sac.yml"} <= {path.name for path in CONFIGS}


@pytest.mark.parametrize("path", CONFIGS, ids=lambda path: path.name)
def test_every_shipped_config_is_keyed_by_the_current_env_id(path):
    """After an env-id bump, a block still keyed by the old id is never read: training
    would silently fall back to the ``default`` block (no normalisation, no env kwargs)."""
    blocks = set(yaml.safe_load(path.read_text()))
    assert tether_gym.ENV_ID in blocks, (path.name, sorted(blocks))
    assert blocks <= {tether_gym.ENV_ID, "default"}, (path.name, sorted(blocks))


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3"])
def test_env_id_block_is_complete_for_zoo(algo):
    """rl_zoo3 reads only the env id's block (never `default`): it must hold everything."""
    doc = yaml.safe_load((CONFIG_DIR / f"{algo}.yml").read_text())
    block = doc[tether_gym.ENV_ID]
    for key in ZOO_KEYS:
        assert key in block or key in NOISE_KEYS, key
    assert all(key in block for key in NOISE_KEYS) or not any(key in block
                                                               for key in NOISE_KEYS)
    # train.py's own keys stay out of zoo's way (in the default block)
    assert not OWN_KEYS & set(block), sorted(OWN_KEYS & set(block))
    merged = load_hyperparams(CONFIG_DIR / f"{algo}.yml", algo, tether_gym.ENV_ID)
    assert merged == {**doc["default"], **block}


@pytest.mark.slow
@pytest.mark.parametrize("algo", sorted(TINY))
def test_rl_zoo3_trains_with_the_shipped_config(tmp_path, algo):
    # not imported here: importing rl_zoo3 patches gymnasium's TimeLimit for the whole process
    if importlib.util.find_spec("rl_zoo3") is None:
        pytest.skip("rl_zoo3 is not installed: pip install -e '.[test]' installs it")
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", algo, "--env", tether_gym.ENV_ID,
           "--gym-packages", "tether_gym", "--conf-file", str(CONFIG_DIR / f"{algo}.yml"),
           "-n", "256", "--eval-freq", "-1", "--save-freq", "-1", "-f", str(tmp_path),
           "--seed", "0", "--device", "cpu", "--hyperparams", *TINY[algo]]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    run = tmp_path / algo / "tether_gym-TetherLibration-v2_1"
    assert (run / "tether_gym-TetherLibration-v2.zip").is_file()
    # zoo printed the hyperparameters it read: the file's env kwargs and normalisation
    assert "Using 'default' hyperparameters" not in proc.stdout
    assert "'eccentricity_range': [0.0, 0.35]" in proc.stdout
    assert "'mass_range': 0.25" in proc.stdout and "'norm_obs': True" in proc.stdout
    if algo == "td3":  # zoo took the action noise out of the block and applied it
        assert "Applying normal noise with std 0.1" in proc.stdout
