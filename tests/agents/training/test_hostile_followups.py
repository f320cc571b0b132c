"""Follow-ups of issue 33 on train.py's side, each tried through ``train.py``'s ``main``.

Before: ``--n-envs 1000000000`` on the command line asked for 74.5 GiB (the config's
``n_envs`` was bounded, the option was not), and a rollout or batch that only the
option's ``n_envs`` made too large was accepted.
"""

from __future__ import annotations

import pytest

from tether_gym_agents.cli.train import main

ENV = "tether_gym/TetherLibration-v1"


@pytest.fixture
def no_training(monkeypatch):
    def refuse(settings):
        raise AssertionError("a hostile input reached training")
    monkeypatch.setattr("tether_gym_agents.cli.train.train", refuse)


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_n_envs_option_is_bounded(tmp_path, capsys, no_training, algo):
    out = tmp_path / "run"
    assert main(["--algo", algo, "--n-envs", "1000000000", "--timesteps", "64",
                 "--out", str(out), "--no-progress"]) == 2
    assert _one_line(capsys).startswith(
        "train.py: error: --n-envs: 1000000000 must be a whole number in [1, 1024]")
    assert not out.exists()


@pytest.mark.parametrize("lines, args, message", [
    ("n_steps: 100000", ["--n-envs", "1024", "--timesteps", "1000000000"],
     "n_steps x n_envs: 100000 x 1024 = 102400000 must be <= 10000000"),
    ("n_envs: 8\n  n_steps: 8\n  batch_size: 64", ["--n-envs", "2", "--timesteps", "64"],
     "batch_size: 64 must be <= n_steps x n_envs = 8 x 2 = 16"),
])
def test_rollout_of_the_option_n_envs_is_bounded(tmp_path, capsys, no_training, lines, args,
                                                 message):
    config = tmp_path / "ppo.yml"
    config.write_text(f"{ENV}:\n  {lines}\n")
    out = tmp_path / "run"
    assert main(["--config", str(config), "--out", str(out), "--no-progress", *args]) == 2
    assert _one_line(capsys).startswith(f"train.py: error: {config}: {message}")
    assert not out.exists()
