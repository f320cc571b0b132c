"""Follow-ups of issue 33 on train.py's side, each tried through ``train.py``'s ``main``.

Before: ``--n-envs 1000000000`` on the command line asked for 74.5 GiB (the config's
``n_envs`` was bounded, the option was not), and a rollout or batch that only the
option's ``n_envs`` made too large was accepted.
"""

from __future__ import annotations

import pytest

from tether_gym_agents.cli.train import main

ENV = "tether_gym/TetherLibration-v2"


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


@pytest.mark.parametrize("line, value", [("n_envs: .nan", "nan"), ("n_envs: .inf", "inf"),
                                         ("n_timesteps: .nan", "nan"),
                                         ("eval_freq: -.inf", "-inf")])
def test_non_finite_counts_in_a_config_are_one_line(tmp_path, capsys, no_training, line,
                                                    value):
    """Before: ``ValueError: cannot convert float NaN to integer`` / ``OverflowError``."""
    config = tmp_path / "nan.yml"
    config.write_text(f"{ENV}:\n  {line}\n")
    assert main(["--config", str(config), "--out", str(tmp_path / "run"), "--timesteps", "64",
                 "--no-progress"]) == 2
    key = line.split(":")[0]
    assert _one_line(capsys) == (f"train.py: error: {config}: {key}: {value} must be a whole "
                                 "number >= 1")


def test_config_file_is_read_with_the_yaml_limits(tmp_path, capsys, no_training):
    """Before: an alias was expanded (and a FIFO was reported as 'does not exist')."""
    import os

    config = tmp_path / "alias.yml"
    config.write_text(f"default: &d {{n_envs: 1}}\n{ENV}: *d\n")
    args = ["--out", str(tmp_path / "run"), "--timesteps", "64", "--no-progress"]
    assert main(["--config", str(config), *args]) == 2
    err = _one_line(capsys)
    assert f"config file {config}" in err and "anchors and aliases" in err, err
    fifo = tmp_path / "fifo.yml"
    os.mkfifo(fifo)
    assert main(["--config", str(fifo), *args]) == 2
    assert _one_line(capsys) == (f"train.py: error: config file {fifo} is not a regular file "
                                 "(a FIFO)")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A finished 64-step PPO run folder (copy it before changing it)."""
    out = tmp_path_factory.mktemp("tiny") / "run"
    assert main(["--timesteps", "64", "--n-envs", "1", "--eval-episodes", "1",
                 "--out", str(out), "--no-progress"]) == 0
    return out


def _copy(run, tmp_path):
    import shutil

    out = tmp_path / "run"
    shutil.copytree(run, out, symlinks=True)
    return out


def _edit_config(out, old: str, new: str) -> None:
    path = out / "config.yml"
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_resume_with_non_finite_count_in_config_yml_is_one_line(tiny_run, tmp_path, capsys,
                                                                no_training):
    """Before: ``ValueError: cannot convert float NaN to integer``."""
    out = _copy(tiny_run, tmp_path)
    _edit_config(out, "  n_timesteps: 3000000\n", "  n_timesteps: .nan\n")
    assert main(["--resume", "--out", str(out), "--timesteps", "64", "--no-progress"]) == 2
    assert _one_line(capsys) == (f"train.py: error: {out / 'config.yml'}: n_timesteps: nan "
                                 "must be a whole number >= 1")


def test_resume_of_a_run_whose_algo_is_not_a_name_is_one_line(tiny_run, tmp_path, capsys,
                                                              no_training):
    """Before: ``AttributeError: 'list' object has no attribute 'upper'``."""
    out = _copy(tiny_run, tmp_path)
    _edit_config(out, "algo: ppo\n", "algo: [td3]\n")
    assert main(["--resume", "--out", str(out), "--timesteps", "64", "--no-progress"]) == 2
    assert _one_line(capsys) == (f"train.py: error: --resume: {out / 'config.yml'}: algo: "
                                 "['td3'] must be one of ['ppo', 'ppo_lag', 'sac', 'td3', 'tqc']")


@pytest.mark.parametrize("kind", ["fifo", "folder", "dev-zero link"])
def test_resume_names_a_config_yml_that_is_not_a_regular_file(tiny_run, tmp_path, capsys,
                                                              no_training, kind):
    """Before: every one was "config.yml not found (is RUN a run folder?)"."""
    import os

    out = _copy(tiny_run, tmp_path)
    path = out / "config.yml"
    path.unlink()
    {"fifo": os.mkfifo, "folder": os.mkdir,
     "dev-zero link": lambda p: os.symlink("/dev/zero", p)}[kind](path)
    assert main(["--resume", "--out", str(out), "--timesteps", "64", "--no-progress"]) == 2
    err = _one_line(capsys)
    assert err.startswith(f"train.py: error: --resume: {path} cannot be read: "), err
    assert "not found" not in err
    assert ("leads outside" if kind == "dev-zero link" else "not a regular file") in err, err


def test_resume_refuses_before_writing_anything(tiny_run, tmp_path, capsys):
    """A FIFO checkpoint is refused; before, train_info.json had been rewritten first."""
    import os

    out = _copy(tiny_run, tmp_path)
    os.mkfifo(out / "checkpoints" / "model_9999_steps.zip")
    info = (out / "train_info.json").read_bytes()
    assert main(["--resume", "--out", str(out), "--timesteps", "64", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("train.py: error: --resume: ") and "model_9999_steps.zip" in err, err
    assert (out / "train_info.json").read_bytes() == info


def test_resume_refuses_a_train_info_json_linked_out(tiny_run, tmp_path, capsys):
    """Before: the link was replaced by a regular file and the run trained on."""
    out = _copy(tiny_run, tmp_path)
    outside = tmp_path / "elsewhere.json"
    outside.write_text("{}")
    (out / "train_info.json").unlink()
    (out / "train_info.json").symlink_to(outside)
    assert main(["--resume", "--out", str(out), "--timesteps", "64", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith(f"train.py: error: --resume: {out / 'train_info.json'} leads "
                          "outside"), err
    assert (out / "train_info.json").is_symlink() and outside.read_text() == "{}"


@pytest.mark.parametrize("resume", [False, True])
def test_train_info_json_that_is_a_folder_is_one_line(tiny_run, tmp_path, capsys, resume):
    """Before: ``IsADirectoryError`` traceback (os.replace onto the folder)."""
    out = _copy(tiny_run, tmp_path)
    (out / "train_info.json").unlink()
    (out / "train_info.json").mkdir()
    args = ["--resume", "--timesteps", "64"] if resume else ["--timesteps", "64"]
    assert main([*args, "--out", str(out), "--no-progress"]) == 2
    assert _one_line(capsys) == (f"train.py: error: --out {str(out)!r}: "
                                 f"{out / 'train_info.json'} is a folder; the run writes a "
                                 "file there (remove or rename it)")


class _Stop(Exception):
    """Stops a run right after its first checkpoint (as a kill would, at that moment)."""


def test_train_info_json_counts_the_steps_of_the_newest_checkpoint(tmp_path, monkeypatch):
    """Before: ``"num_timesteps": 0`` while checkpoints existed (rewritten every 30 s only)."""
    import json

    from tether_gym_agents.training.callbacks import RunCheckpointCallback

    step = RunCheckpointCallback._on_step

    def checkpoint_then_stop(self):
        result = step(self)
        if self.n_calls % self.save_freq == 0:
            raise _Stop
        return result

    monkeypatch.setattr(RunCheckpointCallback, "_on_step", checkpoint_then_stop)
    out = tmp_path / "run"
    with pytest.raises(_Stop):
        main(["--timesteps", "64", "--n-envs", "1", "--checkpoint-freq", "16",
              "--eval-freq", "1000", "--eval-episodes", "1", "--out", str(out),
              "--no-progress"])
    assert (out / "checkpoints" / "model_16_steps.zip").is_file()
    info = json.loads((out / "train_info.json").read_text())
    assert info["num_timesteps"] == 16 and info["status"] == "running"


def test_resume_without_buffer_names_the_runs_algorithm(tmp_path, capsys):
    """Before: a TD3 run was told "SAC continues with an empty buffer"."""
    out = tmp_path / "td3"
    args = ["--algo", "td3", "--timesteps", "32", "--n-envs", "1", "--eval-episodes", "1",
            "--out", str(out), "--no-progress"]
    assert main(args) == 0
    for name in ("final_replay_buffer.npz", "final_replay_buffer.pkl"):
        (out / name).unlink(missing_ok=True)
    capsys.readouterr()
    assert main([*args, "--resume"]) == 0
    printed = capsys.readouterr().out
    assert "TD3 continues with an empty buffer" in printed and "SAC" not in printed, printed


@pytest.mark.parametrize("inside", [False, True])
def test_fanout_refuses_a_seed_folder_that_is_a_symlink(tmp_path, capsys, monkeypatch,
                                                        inside):
    """Before: ``--seeds`` trained into (and resumed) whatever ``seed_K`` linked to."""
    def refuse(settings):
        raise AssertionError("a linked seed folder reached training")
    monkeypatch.setattr("tether_gym_agents.training.fanout.train", refuse)
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    out = tmp_path / "seeds"
    out.mkdir()
    elsewhere = (out / "other") if inside else (tmp_path / "elsewhere")
    elsewhere.mkdir()
    (out / "seed_0").symlink_to(elsewhere)
    assert main(["--seeds", "1", "--timesteps", "64", "--out", str(out), "--no-progress"]) == 2
    assert _one_line(capsys) == (f"train.py: error: --out {out}: {out / 'seed_0'} is a symlink "
                                 f"(to {elsewhere}); each seed trains into a folder of its own "
                                 "inside --out")
    assert not any(elsewhere.iterdir())


def test_seeds_help_says_it_is_not_evaluate_pys_seeds(capsys):
    """train.py's --seeds counts training runs; evaluate.py's counts episodes per scenario."""
    with pytest.raises(SystemExit) as stop:
        main(["--help"])
    assert stop.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "train N runs, training seeds --seed ... --seed+N-1, into <out>/seed_K/ (not " \
           "evaluate.py's --seeds, which counts episodes per scenario)" in text, text


def test_no_training_docstring_names_only_some_algorithms():
    """The algorithms are the table's rows; "PPO or SAC" went stale when TQC and TD3 came."""
    from pathlib import Path

    import tether_gym_agents

    root = Path(tether_gym_agents.__file__).parent
    stale = [str(p.relative_to(root)) for p in [root / "cli" / "train.py",
                                                *sorted((root / "training").glob("*.py"))]
             if any(s in p.read_text() for s in ("PPO or SAC", '``"ppo"``, ``"sac"`` or'))]
    assert not stale


@pytest.mark.parametrize("args, message", [
    (["--timesteps", "1" + "0" * 30],
     "--timesteps 1" + "0" * 30 + ": must be an integer in [1, 1000000000000]"),
    (["--eval-episodes", "1000000000"], "--eval-episodes 1000000000: must be an integer in "
                                        "[1, 10000]"),
    (["--seeds", "1000000000", "--ray-address", "127.0.0.1:1"],
     "--seeds 1000000000: must be an integer in [1, 1000]"),
    (["--env-kwargs", "render_mode='human'"], "invalid env kwargs (--env-kwargs "
                                              "render_mode='human'; "),
    # before: the process died of a segmentation fault in torch.set_num_threads
    (["--torch-threads", "100000"], "--torch-threads 100000: must be an integer in [1, 256] "
                                    "(torch threads per training process)"),
])
def test_options_that_would_run_without_end_are_bounded(tmp_path, capsys, no_training, args,
                                                        message):
    """From the hostile-input sweep: before, the first three ran past a 60 s timeout (never
    ending) and render_mode='human' was a ValueError traceback from the vector env."""
    out = tmp_path / "run"
    assert main([*args, "--out", str(out), "--no-progress"]) == 2
    assert _one_line(capsys).startswith(f"train.py: error: {message}")
    assert not out.exists()


@pytest.mark.parametrize("text", ["", "null\n", "foo/Bar-v0: {n_envs: 2}\n"])
def test_a_config_without_a_block_for_the_env_is_refused(tmp_path, capsys, no_training, text):
    """Before: an empty file (or one for another env id) trained 100000 steps with SB3's
    defaults and no env kwargs."""
    config = tmp_path / "c.yml"
    config.write_text(text)
    assert main(["--config", str(config), "--out", str(tmp_path / "run"),
                 "--no-progress"]) == 2
    assert _one_line(capsys).startswith(f"train.py: error: {config} has no block for {ENV} "
                                        "and no 'default' block")


def test_resume_with_a_non_numeric_step_count_in_train_info_continues(tiny_run, tmp_path,
                                                                      capsys):
    """Before: ``ValueError: cannot convert float NaN to integer``; now the damaged record
    is reported (the wall time of earlier calls is lost) and the run continues."""
    import json

    out = _copy(tiny_run, tmp_path)
    info = json.loads((out / "train_info.json").read_text())
    (out / "train_info.json").write_text(json.dumps({**info, "num_timesteps": "abc"}))
    assert main(["--resume", "--out", str(out), "--timesteps", "64", "--no-progress"]) == 0
    assert "train_info.json is damaged (num_timesteps 'abc' is not a whole number >= 0)" \
        in capsys.readouterr().err
    assert json.loads((out / "train_info.json").read_text())["num_timesteps"] == 128
