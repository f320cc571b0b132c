"""The run-folder layout: each file written (atomically) and read back."""

from __future__ import annotations

import os

import numpy as np
import pytest
import yaml

from tether_gym_agents.files import run_folder as rf


def test_records_round_trip(tmp_path):
    info = {"algo": "ppo", "num_timesteps": 64, "wall_time_s": 1.5}
    rf.write_train_info(tmp_path, info)
    assert rf.read_train_info(tmp_path) == info and rf.trained_steps(tmp_path) == 64
    config = {"algo": "ppo", "env_kwargs": {"masses": (1.0, 2.0)},
              "hyperparams": {"a": [1], "b": [1]}}
    rf.write_config(tmp_path, config)
    text = (tmp_path / rf.CONFIG_FILE).read_text()
    assert "&id" not in text  # no YAML anchors for the shared list
    assert rf.read_config(tmp_path) == {**config, "env_kwargs": {"masses": [1.0, 2.0]}}
    rf.write_args(tmp_path, {"seed": 3, "env_kwargs": ("x=1",)})
    assert yaml.safe_load((tmp_path / rf.ARGS_FILE).read_text()) == {"seed": 3,
                                                                     "env_kwargs": ["x=1"]}
    rf.append_command(tmp_path, "python train.py --seed 3")
    rf.append_command(tmp_path, "python train.py --resume")
    assert (tmp_path / rf.COMMAND_FILE).read_text().splitlines() == [
        "python train.py --seed 3", "python train.py --resume"]
    assert not list(tmp_path.glob("*.tmp"))


def test_missing_and_unreadable_records(tmp_path):
    assert rf.read_train_info(tmp_path) == {} and rf.trained_steps(tmp_path) == -1
    (tmp_path / rf.TRAIN_INFO_FILE).write_text("{cut")
    assert rf.trained_steps(tmp_path) == -1
    with pytest.raises(FileNotFoundError):
        rf.read_config(tmp_path)
    assert rf.read_evaluations(tmp_path) is None


def test_a_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    rf.write_train_info(tmp_path, {"num_timesteps": 1})

    def killed(*args):
        raise OSError("killed")

    monkeypatch.setattr(os, "replace", killed)
    with pytest.raises(OSError):
        rf.write_train_info(tmp_path, {"num_timesteps": 2})
    assert rf.trained_steps(tmp_path) == 1


def test_evaluations_round_trip(tmp_path):
    arrays = {"timesteps": np.array([10, 20]), "results": np.array([[1.0], [2.0]]),
              "ep_lengths": np.array([[5], [6]])}
    rf.write_evaluations(tmp_path, arrays)
    assert rf.evaluations_path(tmp_path) == tmp_path / "eval" / "evaluations.npz"
    back = rf.read_evaluations(tmp_path)
    assert back is not None and back.keys() == arrays.keys()
    assert all(np.array_equal(back[k], arrays[k]) for k in arrays)


def test_saved_models_and_checkpoint_steps(tmp_path):
    assert rf.saved_models(tmp_path) == [] and rf.checkpoint_steps(tmp_path) == -1
    ckpt = tmp_path / rf.CHECKPOINT_DIR
    ckpt.mkdir()
    for name in ("model_32_steps.zip", "model_64_steps.zip", "model_vecnormalize_96_steps.pkl",
                 "model_x_steps.zip", "notes_128_steps.txt"):
        (ckpt / name).write_bytes(b"")
    (tmp_path / rf.FINAL_MODEL_FILE).write_bytes(b"")
    models = rf.saved_models(tmp_path)
    assert models[0] == rf.SavedModel(tmp_path / "final_model.zip",
                                      tmp_path / "vecnormalize.pkl",
                                      tmp_path / "final_replay_buffer.pkl", None)
    assert sorted(m.steps for m in models[1:]) == [32, 64]
    m64 = next(m for m in models if m.steps == 64)
    assert m64.stats == ckpt / "model_vecnormalize_64_steps.pkl"
    assert m64.buffer == ckpt / "model_replay_buffer_64_steps.pkl"
    assert rf.checkpoint_steps(tmp_path) == 96  # any saved piece of a checkpoint counts


def test_seed_runs_in_seed_order(tmp_path):
    for k in (10, 2, 0):
        rf.seed_dir(tmp_path, k).mkdir()
    (tmp_path / "seed_x").mkdir()
    (tmp_path / "seed_3").write_text("a file")
    assert [p.name for p in rf.seed_runs(tmp_path)] == ["seed_0", "seed_2", "seed_10"]
    assert rf.seed_runs(tmp_path / "none") == []


def test_earlier_run_names_what_a_new_run_would_mix_with(tmp_path):
    assert rf.earlier_run(tmp_path / "new") == "" and rf.earlier_run(tmp_path) == ""
    # a call killed before its first checkpoint leaves records only: nothing to mix with
    for name in (rf.CONFIG_FILE, rf.COMMAND_FILE, rf.TRAIN_INFO_FILE):
        (tmp_path / name).write_text("x")
    (tmp_path / rf.CHECKPOINT_DIR).mkdir()
    (tmp_path / rf.CHECKPOINT_DIR / "notes.txt").write_text("x")
    assert rf.earlier_run(tmp_path) == ""
    (tmp_path / rf.CHECKPOINT_DIR / "agent_8192_steps").mkdir()
    assert rf.earlier_run(tmp_path) == "checkpoints/agent_8192_steps"
    for name in ("model_64_steps.zip", "model_vecnormalize_64_steps.npz"):
        (tmp_path / rf.CHECKPOINT_DIR / name).write_bytes(b"")
    (tmp_path / rf.FINAL_MODEL_FILE).write_bytes(b"")
    assert rf.earlier_run(tmp_path) == ("checkpoints/agent_8192_steps, checkpoints/"
                                        "model_64_steps.zip, checkpoints/model_vecnormalize_"
                                        "64_steps.npz and 1 more")
    killed = tmp_path / "killed"
    killed.mkdir()
    (killed / "agent.json").write_text("{}")  # a best agent, before the first checkpoint
    assert rf.earlier_run(killed) == ""
    (killed / rf.FINAL_AGENT_DIR).mkdir()     # a finished SB3 run
    assert rf.earlier_run(killed) == "final_agent"


def test_check_writable_folder(tmp_path):
    rf.check_writable_folder(tmp_path / "a" / "b", ["train_info.json"])
    assert (tmp_path / "a" / "b").is_dir() and not any((tmp_path / "a" / "b").iterdir())
    (tmp_path / "file").write_text("x")
    with pytest.raises(rf.FolderFileError, match="is a file; give a folder"):
        rf.check_writable_folder(tmp_path / "file", [])
    with pytest.raises(rf.FolderFileError, match="cannot write there"):
        rf.check_writable_folder(tmp_path / "file" / "sub", [])
    (tmp_path / "c" / "train_info.json").mkdir(parents=True)
    with pytest.raises(rf.FolderFileError, match="train_info.json is a folder"):
        rf.check_writable_folder(tmp_path / "c", ["config.yml", "train_info.json"])


@pytest.mark.parametrize("kind", ["symlink", "fifo"])
def test_a_link_or_fifo_at_a_written_name_is_refused(tmp_path, kind):
    """Before: a symlinked command.txt was a FolderFileError traceback after the run had
    written config.yml and args.yml; a FIFO in a written file's place would block."""
    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    out = tmp_path / "run"
    out.mkdir()
    if kind == "symlink":
        (out / "config.yml").symlink_to(precious)
        what = f"leads outside {out} \\(to {precious}\\);"
    else:
        os.mkfifo(out / "config.yml")
        what = "is not a regular file;"
    with pytest.raises(rf.FolderFileError, match=f"config.yml {what}.*the run writes a file "
                                                 "there"):
        rf.check_fresh_run_folder(out, ["train_info.json", "config.yml"], "give another")
    assert precious.read_text() == "keep"
    (out / "config.yml").unlink()
    (out / "config.yml").symlink_to(out / "elsewhere.yml")  # a link inside the folder
    (out / "elsewhere.yml").write_text("a: 1\n")
    rf.check_fresh_run_folder(out, ["train_info.json", "config.yml"], "give another")


def test_atomic_writes_replace_a_link_instead_of_writing_through_it(tmp_path):
    """Before: write_text_atomic wrote through a planted NAME.tmp symlink, and the
    folder check's .write_test probe through a planted link of that name."""
    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    for name in ("results.json", "results.json.tmp", ".write_test"):
        (tmp_path / name).symlink_to(precious)
    rf.write_text_atomic(tmp_path / "results.json", "{}\n")
    rf.check_writable_folder(tmp_path, [])
    assert precious.read_text() == "keep"
    assert (tmp_path / "results.json").read_text() == "{}\n"
    assert not (tmp_path / "results.json").is_symlink()
    assert not list(tmp_path.glob(".tmp-*"))
