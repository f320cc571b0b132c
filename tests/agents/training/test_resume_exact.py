"""How many transitions a resumed SAC run's replay buffer holds (issue 33).

A finished run's final save holds every transition; a checkpoint (what a killed run
resumes from) is written by stable-baselines3's callback before the last env step's
``n_envs`` transitions are added, so it holds ``N - n_envs``: the count documented in
:mod:`tether_gym_agents.training.resume` and printed by ``train.py --resume``.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import yaml

from tether_gym_agents.cli.train import main
from tether_gym_agents.files import run_folder as rf

N_ENVS = 2
FAST = ["--algo", "sac", "--n-envs", str(N_ENVS), "--no-progress", "--eval-episodes", "1",
        "--env-kwargs", "orbits_per_episode=0.05", "--eval-freq", "256",
        "--checkpoint-freq", "256"]


@pytest.fixture
def sac_run(tmp_path):
    config = tmp_path / "sac.yml"
    config.write_text(yaml.safe_dump({"tether_gym/TetherLibration-v2": {
        "learning_starts": 64, "buffer_size": 2048, "batch_size": 32,
        "policy_kwargs": {"net_arch": [16, 16]}}}))
    out = tmp_path / "run"
    assert main([*FAST, "--config", str(config), "--out", str(out), "--timesteps", "512"]) == 0
    return out


def _resumed_count(out, capsys) -> tuple[int, int]:
    """(step, transitions) that ``train.py --resume`` says it resumed with."""
    capsys.readouterr()
    assert main([*FAST, "--out", str(out), "--timesteps", "256", "--resume"]) == 0
    printed = capsys.readouterr().out
    match = re.search(r"at step (\d+) with its replay buffer \((\d+) transitions\)", printed)
    assert match, printed
    return int(match.group(1)), int(match.group(2))


def _saved_count(path) -> int:
    with np.load(path) as data:
        return int(data["pos"]) * N_ENVS if not data["full"] else -1


def test_resume_from_the_final_model_has_every_transition(sac_run, capsys):
    assert _saved_count(sac_run / "final_replay_buffer.npz") == 512
    assert _resumed_count(sac_run, capsys) == (512, 512)
    assert rf.trained_steps(sac_run) == 768


def test_resume_from_a_checkpoint_lacks_the_last_steps_transitions_as_documented(
        sac_run, capsys):
    (sac_run / rf.FINAL_MODEL_FILE).unlink()  # as a run killed after its last checkpoint
    buffer = sac_run / rf.CHECKPOINT_DIR / "model_replay_buffer_512_steps.npz"
    assert _saved_count(buffer) == 512 - N_ENVS
    assert _resumed_count(sac_run, capsys) == (512, 512 - N_ENVS)
    assert rf.trained_steps(sac_run) == 768  # the step count and budget stay exact
