"""Files that are not regular files, and links out of a run or agent folder (issue 33).

Each case is tried through the command a user runs (``train.py --resume``,
``evaluate.py``, ``evaluate.py curves``, ``python -m tether_gym_agents.files export``),
in-process with tiny budgets: a FIFO or a link to ``/dev/zero`` named like a checkpoint,
files and folders symlinked out of the folder, a file over its size cap, a linked
``command.txt`` (a secret), a symlinked ``DEST/eval`` and a hard link. Each must end in
one clear error (exit 2) naming the file, before anything is opened or written.
"""

from __future__ import annotations

import os
import shutil
import signal
from contextlib import contextmanager

import pytest

from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.files.cli import main as files_main
from tether_gym_agents.files.folder_paths import DATA_FILE_CAP, TEXT_FILE_CAP

FAST = ["--n-envs", "2", "--no-progress", "--eval-episodes", "1",
        "--env-kwargs", "orbits_per_episode=0.05", "--eval-freq", "256",
        "--checkpoint-freq", "256"]
EVAL = ["--suite", "paper", "--seeds", "1", "--no-plots"]


@contextmanager
def _no_hang(seconds=120):
    """Fail (instead of blocking the suite) when the command does not return in time."""
    def _alarm(signum, frame):
        raise AssertionError(f"the command hung for {seconds} s")

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture(scope="module")
def base_run(tmp_path_factory):
    """A tiny finished PPO run (normalised, two checkpoints, safe agents)."""
    out = tmp_path_factory.mktemp("base") / "run"
    assert train_main(["--out", str(out), *FAST, "--timesteps", "512"]) == 0
    return out


@pytest.fixture
def run(base_run, tmp_path):
    """A fresh copy of the base run (links copied as links)."""
    copy = tmp_path / "run"
    shutil.copytree(base_run, copy, symlinks=True)
    return copy


def _resume(run):
    with _no_hang():
        return train_main(["--out", str(run), *FAST, "--timesteps", "256", "--resume"])


def _outside(tmp_path, name, source):
    """A copy of ``source`` outside the run folder."""
    target = tmp_path / "elsewhere" / name
    target.parent.mkdir(exist_ok=True)
    shutil.copy(source, target)
    return target


def _err(capsys):
    return capsys.readouterr().err


def test_a_fifo_named_like_a_checkpoint_is_refused_unopened(run, capsys):
    fifo = run / "checkpoints" / "model_9999_steps.zip"
    os.mkfifo(fifo)
    assert _resume(run) == 2
    err = _err(capsys)
    assert f"{fifo} is not a regular file" in err and "Traceback" not in err


def test_a_link_to_dev_zero_named_like_a_checkpoint_is_not_read(run, capsys):
    link = run / "checkpoints" / "model_9999_steps.zip"
    link.symlink_to("/dev/zero")
    assert _resume(run) == 2
    assert f"{link} leads outside {run} (to /dev/zero)" in _err(capsys)


def test_a_checkpoint_over_its_size_cap_is_refused_before_it_is_opened(run, capsys):
    big = run / "checkpoints" / "model_9999_steps.zip"
    with open(big, "wb") as fh:  # sparse: no disk is used
        fh.truncate(DATA_FILE_CAP + 1)
    assert _resume(run) == 2
    assert f"{big} is {DATA_FILE_CAP + 1} bytes, larger than the {DATA_FILE_CAP}" in _err(capsys)


@pytest.mark.parametrize("name", ["final_model.zip", "vecnormalize.npz",
                                  "checkpoints/model_vecnormalize_512_steps.npz",
                                  "eval/evaluations.npz", "args.yml", "config.yml"])
def test_resume_refuses_files_linked_out_of_the_run(run, tmp_path, capsys, name):
    target = _outside(tmp_path, name.replace("/", "_"), run / name)
    (run / name).unlink()
    (run / name).symlink_to(target)
    assert _resume(run) == 2
    assert f"{run / name} leads outside {run} (to {target})" in _err(capsys)


def test_a_linked_train_info_is_refused_not_read_nor_written_through(run, tmp_path,
                                                                      capsys):
    target = _outside(tmp_path, "train_info.json", run / "train_info.json")
    before = target.read_text()
    (run / "train_info.json").unlink()
    (run / "train_info.json").symlink_to(target)
    assert _resume(run) == 2  # refused before the first write (check_run_files)
    assert f"{run / 'train_info.json'} leads outside {run}" in _err(capsys)
    assert target.read_text() == before
    assert (run / "train_info.json").is_symlink()  # left as it was


def test_a_linked_command_txt_is_not_rewritten_nor_exported(run, tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET-TOKEN\n")
    (run / "command.txt").unlink()
    (run / "command.txt").symlink_to(secret)
    assert _resume(run) == 2
    assert f"{run / 'command.txt'} is a symlink" in _err(capsys)
    assert (run / "command.txt").is_symlink()  # not replaced by a file holding the secret
    dest = tmp_path / "shared"
    assert files_main(["export", str(run), str(dest)]) == 2
    assert "command.txt leads outside" in _err(capsys)
    shipped = [p for p in dest.rglob("*") if p.is_file()] if dest.exists() else []
    assert not any(b"TOPSECRET" in p.read_bytes() for p in shipped)


def test_a_hard_linked_command_txt_is_not_rewritten(run, tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET-TOKEN\n")
    (run / "command.txt").unlink()
    os.link(secret, run / "command.txt")
    assert _resume(run) == 2
    assert f"{run / 'command.txt'} is a hard link (2 names for one file)" in _err(capsys)
    assert secret.read_text() == "TOPSECRET-TOKEN\n"


def test_evaluate_refuses_a_final_agent_linked_to_another_folder(run, base_run, tmp_path,
                                                                 capsys):
    other = tmp_path / "other_agent"
    shutil.copytree(base_run / "final_agent", other)
    for path in list(run.iterdir()):  # a run folder whose only agent is final_agent/
        if path.name != "config.yml":
            shutil.rmtree(path) if path.is_dir() else path.unlink()
    (run / "final_agent").symlink_to(other)
    assert evaluate_main([str(run), *EVAL, "--out", str(tmp_path / "ev")]) == 2
    assert f"{run / 'final_agent'} leads outside {run} (to {other})" in _err(capsys)
    assert not (tmp_path / "ev" / "results.json").exists()


def test_evaluate_refuses_a_seed_run_linked_to_another_folder(base_run, tmp_path, capsys):
    folder = tmp_path / "seeds"
    shutil.copytree(base_run, folder / "seed_1")
    (folder / "seed_0").symlink_to(base_run)
    assert evaluate_main([str(folder), *EVAL, "--out", str(tmp_path / "ev")]) == 2
    assert f"{folder / 'seed_0'} leads outside {folder} (to {base_run})" in _err(capsys)


@pytest.mark.parametrize("hostile", ["fifo", "dev_zero"])
def test_evaluate_names_an_agent_json_that_is_not_a_regular_file(run, tmp_path, capsys,
                                                                 hostile):
    meta = run / "final_agent" / "agent.json"
    meta.unlink()
    os.mkfifo(meta) if hostile == "fifo" else meta.symlink_to("/dev/zero")
    with _no_hang():
        code = evaluate_main([str(run / "final_agent"), *EVAL, "--out", str(tmp_path / "e")])
    assert code == 2
    err = _err(capsys)
    assert f"{meta} is not a regular file" in err or f"{meta} leads outside" in err


def test_evaluate_refuses_an_agent_json_over_its_cap(run, tmp_path, capsys):
    meta = run / "final_agent" / "agent.json"
    with open(meta, "r+b") as fh:
        fh.truncate(TEXT_FILE_CAP + 1)
    assert evaluate_main([str(run / "final_agent"), *EVAL, "--out", str(tmp_path / "e")]) == 2
    assert f"{meta} is {TEXT_FILE_CAP + 1} bytes" in _err(capsys)


@pytest.mark.parametrize("hostile", ["dev_zero", "outside", "fifo", "folder"])
def test_curves_copy_only_regular_files_inside_the_agent_folder(run, tmp_path, capsys,
                                                                hostile):
    agent = run / "checkpoints" / "agent_256_steps"
    weights = agent / "policy.safetensors"
    target = _outside(tmp_path, "policy.safetensors", weights)
    weights.unlink()
    if hostile == "fifo":
        os.mkfifo(weights)
    elif hostile == "folder":
        weights.mkdir()
    else:
        weights.symlink_to("/dev/zero" if hostile == "dev_zero" else target)
    with _no_hang():
        code = evaluate_main(["curves", str(run), "--suite", "paper", "--seeds", "1",
                              "--out", str(tmp_path / "curves")])
    assert code == 2
    err = _err(capsys)
    assert str(weights) in err and ("leads outside" in err or "not a regular file" in err)
    assert not (tmp_path / "curves" / "curves.json").exists()


def test_curves_refuse_a_checkpoint_folder_linked_out(run, tmp_path, capsys):
    agent = run / "checkpoints" / "agent_256_steps"
    other = tmp_path / "other"
    shutil.move(agent, other)
    agent.symlink_to(other)
    assert evaluate_main(["curves", str(run), "--suite", "paper", "--seeds", "1",
                          "--out", str(tmp_path / "curves")]) == 2
    assert f"{agent} leads outside {run}" in _err(capsys)


def test_export_does_not_write_through_a_symlinked_folder(run, tmp_path, capsys):
    dest, elsewhere = tmp_path / "dest", tmp_path / "elsewhere"
    dest.mkdir()
    elsewhere.mkdir()
    (dest / "eval").symlink_to(elsewhere)
    assert files_main(["export", str(run), str(dest)]) == 2
    assert f"{dest / 'eval'} is a symlink or not a folder" in _err(capsys)
    assert list(elsewhere.iterdir()) == []
    assert not (dest / "agent.json").exists()  # checked before anything is written


def test_export_refuses_a_hard_link(run, tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET-TOKEN\n")
    (run / "command.txt").unlink()
    os.link(secret, run / "command.txt")
    dest = tmp_path / "dest"
    assert files_main(["export", str(run), str(dest)]) == 2
    assert f"{run / 'command.txt'} is a hard link" in _err(capsys)
    assert not dest.exists() or not any(dest.rglob("*"))


@pytest.mark.parametrize("name", ["agent.json", "policy.safetensors"])
def test_export_names_an_agent_file_that_is_a_fifo(run, tmp_path, capsys, name):
    (run / name).unlink()
    os.mkfifo(run / name)
    with _no_hang():
        assert files_main(["export", str(run), str(tmp_path / "dest")]) == 2
    assert f"{run / name} is not a regular file" in _err(capsys)
    assert not (tmp_path / "dest").exists()


def test_export_of_a_clean_run_still_copies_its_files(run, tmp_path):
    dest = tmp_path / "dest"
    assert files_main(["export", str(run), str(dest)]) == 0
    assert (dest / "agent.json").is_file() and (dest / "eval" / "evaluations.npz").is_file()
    assert (dest / "command.txt").read_text() == (run / "command.txt").read_text()


# ---------------------------------------------------------------- YAML of run folders
BOMB = ('a: &a ["x", "x", "x", "x", "x", "x", "x", "x", "x"]\n'
        + "".join(f"{b}: &{b} [{', '.join(['*' + a] * 9)}]\n"
                  for a, b in zip("abcdefgh", "bcdefghi", strict=True)))
"""Nine levels of nine aliases: 9**9 strings from 500 bytes ("billion laughs")."""


def test_resume_refuses_an_alias_bomb_in_config_yml(run, capsys):
    (run / "config.yml").write_text(BOMB)
    assert _resume(run) == 2
    err = _err(capsys)
    assert f"{run / 'config.yml'}" in err and "aliases" in err and "Traceback" not in err


def test_evaluate_allow_pickle_refuses_an_alias_bomb_in_config_yml(run, tmp_path, capsys):
    for name in ("agent.json", "policy.safetensors", "final_agent", "checkpoints"):
        path = run / name
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    (run / "config.yml").write_text(BOMB)
    with _no_hang():
        code = evaluate_main([str(run), *EVAL, "--allow-pickle", "--out", str(tmp_path / "e")])
    assert code == 2
    err = _err(capsys)
    assert f"{run / 'config.yml'}" in err and "aliases" in err


def test_convert_refuses_an_alias_bomb_in_a_zoo_config(base_run, tmp_path, capsys):
    name = "tether_gym-TetherLibration-v2"
    zoo = tmp_path / "logs" / "ppo" / f"{name}_1"
    (zoo / name).mkdir(parents=True)
    shutil.copy(base_run / "final_model.zip", zoo / f"{name}.zip")
    (zoo / name / "config.yml").write_text(BOMB)
    (zoo / name / "args.yml").write_text("algo: ppo\n")
    with _no_hang():
        code = files_main(["convert", str(zoo), "--allow-pickle", "--out", str(tmp_path / "o")])
    assert code == 2
    err = _err(capsys)
    assert f"{zoo / name / 'config.yml'}" in err and "aliases" in err
    assert len(err.strip().splitlines()) == 1
