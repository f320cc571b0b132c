"""``train.py --resume`` runs no code from the run folder (issue 24): the model zip's
tensors and counters, the statistics and the replay buffer are read as arrays; pickled
files are read only with ``--allow-pickle``, with a warning. Tiny budgets, in-process."""

from __future__ import annotations

import base64
import json
import os
import pickle
import zipfile

import pytest
import yaml

from tether_gym_agents.cli.train import main
from tether_gym_agents.files import run_folder as rf

FAST = ["--n-envs", "2", "--no-progress", "--eval-episodes", "1",
        "--env-kwargs", "orbits_per_episode=0.05", "--eval-freq", "256",
        "--checkpoint-freq", "256"]


class _Evil:
    """Unpickling this runs a shell command that writes the marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _poison_zip(path, marker):
    """Put a cloudpickled payload into a model zip's ``data`` (SB3's load unpickles it)."""
    with zipfile.ZipFile(path) as zf:
        entries = {name: zf.read(name) for name in zf.namelist()}
    data = json.loads(entries["data"])
    payload = base64.b64encode(pickle.dumps(_Evil(marker))).decode()
    data["policy_class"] = {":type:": "<class 'abc.ABCMeta'>", ":serialized:": payload}
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as zf:
        for name, blob in entries.items():
            zf.writestr(name, blob)


def _sac_config(tmp_path):
    path = tmp_path / "sac.yml"
    path.write_text(yaml.safe_dump({"tether_gym/TetherLibration-v2": {
        "learning_starts": 64, "buffer_size": 2048, "batch_size": 32,
        "policy_kwargs": {"net_arch": [16, 16]}}}))
    return path


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_resume_runs_no_code_from_the_run_folder(tmp_path, capsys, algo):
    out, marker = tmp_path / "run", tmp_path / "marker"
    extra = ["--config", str(_sac_config(tmp_path))] if algo == "sac" else []
    argv = ["--algo", algo, "--out", str(out), *FAST]
    assert main([*argv, *extra, "--timesteps", "512"]) == 0
    pickles = [p for p in out.rglob("*.pkl")]
    expected = "final_replay_buffer.pkl" if algo == "sac" else "vecnormalize.pkl"
    assert out / expected in pickles
    for path in pickles:  # every pickle of the folder runs code when unpickled
        path.write_bytes(pickle.dumps(_Evil(marker)))
    for path in [out / "final_model.zip", *(out / "checkpoints").glob("*.zip")]:
        _poison_zip(path, marker)
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256", "--resume"]) == 0
    printed = capsys.readouterr()
    assert not marker.exists()
    assert f"resuming from {out / 'final_model.zip'} at step 512" in printed.out
    if algo == "sac":
        assert "with its replay buffer (512 transitions)" in printed.out
    assert rf.trained_steps(out) > 512


def test_pickled_statistics_need_allow_pickle(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST]
    assert main([*argv, "--timesteps", "512"]) == 0
    for path in out.rglob("*vecnormalize*.npz"):  # a run saved before the arrays existed
        path.unlink()
    capsys.readouterr()
    assert main([*argv, "--timesteps", "256", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "pass --allow-pickle if you made them or trust them" in err
    assert str(out / "vecnormalize.pkl") in err
    assert main([*argv, "--timesteps", "256", "--resume", "--allow-pickle"]) == 0
    printed = capsys.readouterr()
    assert "--allow-pickle: unpickling" in printed.err and "can run any code" in printed.err
    assert f"resuming from {out / 'final_model.zip'} at step 512" in printed.out


def _padded_data(path, pad_bytes: int):
    """Rewrite a model zip with its ``data`` padded by ``pad_bytes`` spaces (valid JSON)."""
    with zipfile.ZipFile(path) as zf:
        entries = {name: zf.read(name) for name in zf.namelist()}
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, blob in entries.items():
            zf.writestr(name, blob + b" " * pad_bytes if name == "data" else blob)


def test_a_model_zip_that_unpacks_past_its_cap_is_skipped(tmp_path, capsys, monkeypatch):
    """Before: ZipFile.read unpacked the whole member: a 2.2 MB final_model.zip whose
    data unpacks to 2 GiB resumed after 81 s at 4.6 GB peak memory (unpacking to more
    would run out of memory); now it is refused by the sizes the zip records, and
    --resume takes the next saved model, as for any damaged one."""
    from tether_gym_agents.training import checkpoint

    out = tmp_path / "run"
    argv = ["--out", str(out), *FAST]
    assert main([*argv, "--timesteps", "512"]) == 0
    _padded_data(out / "final_model.zip", 4096)
    monkeypatch.setattr(checkpoint, "size_cap", lambda path: 4096)  # the cap, scaled down
    capsys.readouterr()
    with pytest.raises(ValueError, match=r"final_model.zip: its members unpack to \d+ bytes, "
                                         r"more than the 4096 bytes accepted"):
        checkpoint.check_unpacked_size(zipfile.ZipFile(out / "final_model.zip"),
                                       out / "final_model.zip")
    monkeypatch.undo()
    monkeypatch.setattr(checkpoint, "size_cap",
                        lambda path: 4096 if path.name == "final_model.zip" else 1 << 29)
    assert main([*argv, "--timesteps", "256", "--resume"]) == 0
    printed = capsys.readouterr()
    # its steps unread, the final model ranks after the checkpoint of the same step
    assert f"resuming from {out / 'checkpoints' / 'model_512_steps.zip'}" in printed.out, \
        printed.out
    assert rf.trained_steps(out) > 512
