"""The .npz reader reads every array header before its data: a small file declaring a
huge array, an object array or a garbled archive is one NpzFileError naming the file
(before: np.load allocated what the header declared; a 1 kB evaluations.npz declaring
(10**10, 1) float64 was a MemoryError traceback from ``train.py --seeds``)."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from tether_gym_agents.files.run_folder import (
    DamagedFileError,
    read_evaluations,
    write_evaluations,
)
from tether_gym_agents.files.safe_npz import NpzFileError, after_path, read_npz
from tether_gym_agents.training.curves import plot_seed_learning_curves

ARRAYS = {"timesteps": np.array([64, 128]), "results": np.ones((2, 3)),
          "ep_lengths": np.full((2, 3), 5)}


def _npz(path, members: dict[str, bytes]):
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return path


def _npy(array) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


def _lying(shape, descr="<f8") -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False,
                                               "shape": shape})
    return buf.getvalue() + bytes(64)


def test_plain_arrays_read_back(tmp_path):
    path = tmp_path / "a.npz"
    np.savez(path, **ARRAYS)
    back = read_npz(path, max_bytes=1 << 20, required=("results",))
    assert set(back) == set(ARRAYS)
    for key, value in ARRAYS.items():
        np.testing.assert_array_equal(back[key], value)


@pytest.mark.parametrize("member, message", [
    (_lying((10**10, 1)), r"'results' declares \(10000000000, 1\) x float64 "
                          r"\(80000000000 bytes\) in a member of \d+ bytes"),
    (_npy(np.array([object()])), r"'results' declares \(1,\) x object"),
    (b"\x93NUMPY garbled", r"is not a readable .npz of plain arrays"),
])
def test_a_forged_member_is_refused_before_it_is_allocated(tmp_path, member, message):
    path = _npz(tmp_path / "f.npz", {"timesteps.npy": _npy(ARRAYS["timesteps"]),
                                     "results.npy": member})
    with pytest.raises(NpzFileError, match=message) as info:
        read_npz(path, max_bytes=1 << 30)
    assert str(info.value).startswith(str(path))


def test_the_total_is_bounded(tmp_path):
    path = tmp_path / "big.npz"
    np.savez(path, a=np.zeros(1000), b=np.zeros(1000))  # 8000 bytes each
    read_npz(path, max_bytes=16_000)
    with pytest.raises(NpzFileError, match=r"'b' declares .* 15999 bytes in all"):
        read_npz(path, max_bytes=15_999)


def test_a_required_array_is_named(tmp_path):
    path = tmp_path / "a.npz"
    np.savez(path, x=np.zeros(2))
    with pytest.raises(NpzFileError, match=r"holds no 'results'; a run file holds "
                                           r"\['results'\]"):
        read_npz(path, max_bytes=1 << 20, required=("results",), what="a run file")
    assert after_path(NpzFileError(f"{path}: 'x' is bad"), path) == "'x' is bad"


def test_a_forged_evaluations_file_is_damaged_not_a_memory_error(tmp_path, capsys):
    """The fan-out's seed plot leaves a damaged seed out and says so."""
    runs = tmp_path / "runs"
    for k in (0, 1, 2):
        write_evaluations(runs / f"seed_{k}", ARRAYS)
    path = runs / "seed_0" / "eval" / "evaluations.npz"
    _npz(path, {"timesteps.npy": _npy(ARRAYS["timesteps"]),
                "results.npy": _lying((10**10, 1)),
                "ep_lengths.npy": _npy(ARRAYS["ep_lengths"])})
    with pytest.raises(DamagedFileError, match=rf"{path}: damaged \('results' declares"):
        read_evaluations(runs / "seed_0")
    pytest.importorskip("matplotlib")
    assert plot_seed_learning_curves(runs) == runs / "learning_curves.png"
    assert f"learning curves: seed_0 left out: {path}: damaged" in capsys.readouterr().err
