"""Saved models read without running code: the model zip's tensors, arrays and JSON.

A stable-baselines3 model zip holds ``data`` (JSON, whose non-JSON entries are
cloudpickled: reading those can run code), the networks' and optimizers' state dicts
(``policy.pth``, ``policy.optimizer.pth``, ...) and ``pytorch_variables.pth``.
:func:`load_zip_weights` reads only the state dicts (``torch.load(weights_only=True)``)
and the plain counters of ``data`` (``num_timesteps``, ``_n_updates``, ``_episode_num``)
into a model rebuilt from the run's ``config.yml``; nothing is unpickled.

The ``VecNormalize`` statistics and the replay buffer are written beside the pickled
files as ``.npz`` arrays (:func:`save_stats_npz`, :func:`save_buffer_npz`; read with
``allow_pickle=False``). Every file is written atomically. Every file is read only when it is
a regular file under its size cap (:func:`~tether_gym_agents.files.folder_paths.file_inside`,
checked before it is opened; :mod:`.resume` also checks that it lies inside the run folder).

**Replay buffer of a checkpoint.** stable-baselines3 calls the checkpoint callback after
the env step that reaches step N and before it adds that step's ``n_envs`` transitions
to the buffer, so :func:`save_buffer_npz` at a checkpoint writes ``N - n_envs``
transitions (the final save, after training, writes all of them); see :mod:`.resume`.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ..common.jsonio import loads_json
from ..files.agent_values import check_running_stats
from ..files.folder_paths import FolderFileError, file_inside, size_cap
from ..files.run_folder import atomic_target
from ..files.safe_npz import NpzFileError, after_path, read_npz

__all__ = ["save_stats_npz", "load_stats_npz", "save_buffer_npz", "load_buffer_npz",
           "load_zip_weights", "safe_companion", "check_unpacked_size"]


def safe_companion(path: Path) -> Path:
    """The ``.npz`` written beside a pickled ``.pkl`` (statistics or replay buffer)."""
    return Path(path).with_suffix(".npz")


def save_stats_npz(vec_normalize, path: Path) -> None:
    """Write a ``VecNormalize``'s running statistics as arrays to ``path``."""
    _save_npz(path, _stats_arrays(vec_normalize))


def load_stats_npz(envs, path: Path) -> None:
    """Set the running statistics of each ``VecNormalize`` in ``envs`` from ``path``.

    Raises
    ------
    ValueError
        When the file is damaged, its shapes do not fit the env or a statistic is out
        of the bounds an agent file's ``obs_normalization`` has
        (:func:`~tether_gym_agents.files.agent_values.check_running_stats`: NaN, inf,
        a negative variance...); the path is in the message.
    """
    arrays = _load_npz(path)
    missing = [k for k in ("obs_mean", "obs_var", "obs_count", "ret_mean", "ret_var",
                           "ret_count") if k not in arrays]
    if missing:
        raise ValueError(f"{path}: damaged (no {', '.join(missing)})")
    for name in ("obs", "ret"):  # NaN here failed in torch's Normal updates later
        try:
            check_running_stats(name, arrays[f"{name}_mean"], arrays[f"{name}_var"],
                                arrays[f"{name}_count"])
        except (TypeError, ValueError) as exc:  # ValueProblem among them
            raise ValueError(f"{path}: {exc}") from None
    for env in envs:
        _set_stats(env, arrays, path)


def save_buffer_npz(model, path: Path) -> None:
    """Write ``model``'s replay buffer as arrays to ``path``."""
    _save_npz(path, _buffer_arrays(model.replay_buffer))


def load_buffer_npz(model, path: Path) -> None:
    """Fill ``model``'s replay buffer from ``path`` (shapes must fit; path in errors)."""
    arrays = _load_npz(path)
    if "pos" not in arrays or "full" not in arrays:
        raise ValueError(f"{path}: damaged (no pos or full)")
    _set_buffer(model.replay_buffer, arrays, path)


def load_zip_weights(model, path: Path) -> None:
    """Load a model zip's state dicts and counters into ``model``; nothing is unpickled.

    Raises
    ------
    ValueError
        When the zip is damaged or does not fit the model (the path is in the message).
    """
    import torch
    from stable_baselines3.common.save_util import recursive_setattr

    try:
        _regular(path)
        with zipfile.ZipFile(path) as zf:
            check_unpacked_size(zf, path)
            data = loads_json(zf.read("data"), f"{path}: data")
            tensors = {name[: -len(".pth")]: torch.load(io.BytesIO(zf.read(name)),
                                                        map_location="cpu", weights_only=True)
                       for name in zf.namelist() if name.endswith(".pth")}
        variables = tensors.pop("pytorch_variables", {})
        model.set_parameters(tensors, exact_match=True, device="cpu")
        for name, value in variables.items():
            recursive_setattr(model, f"{name}.data", value.data)
        model.num_timesteps = int(data["num_timesteps"])
        model._n_updates = int(data.get("_n_updates", 0))
        model._episode_num = int(data.get("_episode_num", 0))
    except FolderFileError:
        raise
    except (zipfile.BadZipFile, OSError, EOFError, KeyError, TypeError, RuntimeError,
            ValueError) as exc:
        raise ValueError(f"{path}: {type(exc).__name__}: {exc}") from None


def check_unpacked_size(zf: zipfile.ZipFile, path: Path) -> None:
    """Refuse a zip whose members unpack to more than its kind's size cap (ValueError).

    ``ZipFile.read`` unpacks a whole member into memory, and deflate packs zeros about
    1000 to 1: a model zip under its 512 MiB cap could unpack to hundreds of GB. The
    sizes are the archive's own records, which the reader enforces while unpacking.
    """
    unpacked = sum(member.file_size for member in zf.infolist())
    if unpacked > size_cap(path):
        raise ValueError(f"{path}: its members unpack to {unpacked} bytes, more than the "
                         f"{size_cap(path)} bytes accepted for a file of its kind")


def _regular(path: Path) -> Path:
    """``path`` if it is (or links to) a regular file under its size cap; nothing opened."""
    path = Path(path)
    return file_inside(path.resolve().parent, path)


def _save_npz(path: Path, arrays: dict[str, Any]) -> None:
    with atomic_target(Path(path)) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    _regular(path)
    try:  # each array's declared size checked before it is allocated
        return read_npz(path, max_bytes=size_cap(path))
    except NpzFileError as exc:  # its message starts with the path
        raise ValueError(f"{path}: damaged ({after_path(exc, path)})") from None
    except OSError as exc:
        raise ValueError(f"{path}: damaged ({type(exc).__name__}: {exc})") from None


def _stats_arrays(vec_normalize) -> dict[str, np.ndarray]:
    obs, ret = vec_normalize.obs_rms, vec_normalize.ret_rms
    if not hasattr(obs, "mean"):
        raise TypeError("dict observation spaces are not supported by the safe checkpoints")
    return {"obs_mean": obs.mean, "obs_var": obs.var, "obs_count": np.float64(obs.count),
            "ret_mean": ret.mean, "ret_var": ret.var, "ret_count": np.float64(ret.count)}


def _set_stats(env, arrays: dict[str, np.ndarray], path: Path) -> None:
    for name, rms in (("obs", env.obs_rms), ("ret", env.ret_rms)):
        mean, var = arrays[f"{name}_mean"], arrays[f"{name}_var"]
        if np.shape(mean) != np.shape(rms.mean) or np.shape(var) != np.shape(rms.var):
            raise ValueError(f"{path}: {name} statistics of shape {np.shape(mean)}, the env's "
                             f"are {np.shape(rms.mean)}")
        rms.mean, rms.var = mean.astype(np.float64), var.astype(np.float64)
        rms.count = float(arrays[f"{name}_count"])


_BUFFER_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones",
                  "timeouts")


def _buffer_arrays(buffer) -> dict[str, Any]:
    arrays = {k: getattr(buffer, k) for k in _BUFFER_ARRAYS
              if getattr(buffer, k, None) is not None}
    return {**arrays, "pos": np.int64(buffer.pos), "full": np.bool_(buffer.full)}


def _set_buffer(buffer, arrays: dict[str, np.ndarray], path: Path) -> None:
    for key in _BUFFER_ARRAYS:
        current = getattr(buffer, key, None)
        if current is None:
            continue
        if key not in arrays or arrays[key].shape != current.shape:
            raise ValueError(f"{path}: {key} of shape "
                             f"{arrays[key].shape if key in arrays else 'absent'}, the "
                             f"buffer's is {current.shape}")
        setattr(buffer, key, arrays[key].astype(current.dtype))
    buffer.pos, buffer.full = int(arrays["pos"]), bool(arrays["full"])
