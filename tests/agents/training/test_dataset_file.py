"""A dagger_data.npz read without trusting it: a FIFO, a lying array header, a missing key,
a wrong shape or a non-finite value is one ValueError naming the file and the key
(before: a hang, tracebacks from numpy's reader or from np.concatenate, or a fit to NaN
labels written as an agent)."""

from __future__ import annotations

import io
import os
import re
import zipfile

import numpy as np
import pytest

from tether_gym_agents.cli.train import main as train_main
from tether_gym_agents.training.dagger import Dataset
from tether_gym_agents.training.dataset_file import (
    DATA_KEYS,
    MAX_DATASET_BYTES,
    read_dataset_arrays,
)

N, OBS, ACT = 8, 20, 2  # the training env's observation and action widths (N = 3)


def _dataset(**over) -> Dataset:
    rng = np.random.default_rng(0)
    fields = {"obs": rng.normal(size=(N, OBS)).astype(np.float32),
              "labels": rng.uniform(-1, 1, size=(N, ACT)),
              "iteration": np.zeros(N, np.int32), "episode": np.array([0] * 4 + [1] * 4),
              "expert_acted": np.ones(N, bool),
              "episodes": [{"env_seed": k, "eccentricity": 0.2, "masses": [1.1, 0.9],
                            "beta": 1.0, "mixture_seed": 7} for k in range(2)]}
    fields.update(over)
    return Dataset(**fields)


def _saved(tmp_path, name="data.npz", **over):
    path = tmp_path / name
    _dataset(**over).save(path)
    return path


def _with_member(tmp_path, key, payload: bytes):
    """A saved dataset with member ``key.npy`` replaced by ``payload``."""
    good = _saved(tmp_path, "good.npz")
    path = tmp_path / "edited.npz"
    with zipfile.ZipFile(good) as src, zipfile.ZipFile(path, "w") as dst:
        for name in src.namelist():
            dst.writestr(name, payload if name == f"{key}.npy" else src.read(name))
    return path


def test_a_saved_dataset_reads_back_equal(tmp_path):
    data = _dataset()
    data.save(tmp_path / "d.npz")
    back = Dataset.load(tmp_path / "d.npz")
    for key in ("obs", "labels", "iteration", "episode", "expert_acted"):
        np.testing.assert_array_equal(getattr(back, key), getattr(data, key))
    assert back.episodes == data.episodes
    assert set(read_dataset_arrays(tmp_path / "d.npz")) == set(DATA_KEYS)


def test_a_fifo_is_refused_without_being_opened(tmp_path):
    fifo = tmp_path / "fifo.npz"
    os.mkfifo(fifo)  # opening it would wait for a writer
    with pytest.raises(ValueError, match=r"fifo.npz is not a regular file"):
        Dataset.load(fifo)


def test_a_header_declaring_more_than_its_member_is_refused_before_allocating(tmp_path):
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f4", "fortran_order": False, "shape": (10**9, OBS)})
    path = _with_member(tmp_path, "obs", buf.getvalue() + bytes(640))
    with pytest.raises(ValueError, match=r"'obs' declares \(1000000000, 20\) x float32 "
                                         r"\(80000000000 bytes\) in a member of \d+ bytes"):
        Dataset.load(path)
    assert MAX_DATASET_BYTES < 80_000_000_000


@pytest.mark.parametrize("payload, message", [
    (b"not an npy", r"is not a readable .npz of plain arrays"),
    (b"\x93NUMPY\x01\x00" + b"\x10\x00" + b"{'descr': '<f4'" + b" " * 0 + b"\n",
     r"is not a readable .npz of plain arrays"),
])
def test_a_garbled_member_is_one_error(tmp_path, payload, message):
    with pytest.raises(ValueError, match=message):
        Dataset.load(_with_member(tmp_path, "labels", payload))


def test_object_arrays_are_refused(tmp_path):
    buf = io.BytesIO()
    np.save(buf, np.array([object()] * N, dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match=r"'expert_acted' declares .* object"):
        Dataset.load(_with_member(tmp_path, "expert_acted", buf.getvalue()))


def test_a_missing_key_is_named(tmp_path):
    path = tmp_path / "partial.npz"
    np.savez(path, obs=np.zeros((N, OBS), np.float32))
    with pytest.raises(ValueError, match=r"holds no 'labels'; a dataset file holds \["):
        Dataset.load(path)


BAD = {
    "nan obs": ({"obs": np.full((N, OBS), np.nan, np.float32)}, r"'obs' holds NaN or inf"),
    "inf label": ({"labels": np.full((N, ACT), np.inf)}, r"'labels' hold values outside"),
    "label 1e30": ({"labels": np.full((N, ACT), 1e30)}, r"'labels' hold values outside"),
    "3-D obs": ({"obs": np.zeros((N, OBS, 2), np.float32)}, r"'obs' has shape \(8, 20, 2\)"),
    "short labels": ({"labels": np.zeros((3, ACT))},
                     r"'labels' has shape \(3, 2\).*one row per observation \(8\)"),
    "no pairs": ({"obs": np.zeros((0, OBS), np.float32), "labels": np.zeros((0, ACT)),
                  "iteration": np.zeros(0, np.int32), "episode": np.zeros(0, np.int32),
                  "expert_acted": np.zeros(0, bool)}, r"holds no pairs"),
    "episode out of range": ({"episode": np.full(N, 99)},
                             r"'episode' numbers reach 99; allowed: below the 2 episodes"),
    "negative iteration": ({"iteration": np.full(N, -1, np.int32)},
                           r"'iteration' has shape \(8,\).*integers >= 0"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_each_bad_array_is_one_error_naming_the_key(tmp_path, case):
    over, message = BAD[case]
    path = _saved(tmp_path, **over)
    with pytest.raises(ValueError) as info:
        Dataset.load(path)
    assert str(path) in str(info.value) and re.search(message, str(info.value)), info.value


@pytest.mark.parametrize("over, got", [
    ({"obs": np.zeros((N, 7), np.float32)}, "observations of 7 entries and labels of 2"),
    ({"labels": np.zeros((N, 5)),  # a six-body chain's labels, consistent in the file
      "episodes": [{"env_seed": k, "eccentricity": 0.2, "masses": [1.0] * 5, "beta": 1.0,
                    "mixture_seed": 7} for k in range(2)]},
     "observations of 20 entries and labels of 5"),
])
def test_distill_refuses_data_that_does_not_fit_the_env_in_one_line(tmp_path, capsys,
                                                                    over, got):
    """Before: a ValueError traceback from np.concatenate."""
    pytest.importorskip("casadi")
    path = _saved(tmp_path, **over)
    out = tmp_path / "never"
    assert train_main(["distill", "--data", str(path), "--iterations", "0", "--epochs", "1",
                       "--check-episodes", "0", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == (f"train.py distill: error: --data {path}: {got}; the training "
                           "env gives 20 and takes 2 (n_bodies 3)"), err
    assert not out.exists()


def test_each_episode_records_one_mass_per_tether(tmp_path):
    eps = [{"env_seed": 0, "eccentricity": 0.2, "masses": [1.0], "beta": 1.0,
            "mixture_seed": 7}] * 2
    with pytest.raises(ValueError, match=r"'episode_masses' has shape \(2, 1\).*each a row "
                                         r"of 2 masses"):
        Dataset.load(_saved(tmp_path, episodes=eps))
