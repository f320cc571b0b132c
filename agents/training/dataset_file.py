"""The arrays of a ``dagger_data.npz`` (``train.py distill --data``, ``bc_term``), checked.

A DAgger run writes its (observation, expert action) pairs as one ``.npz`` of plain
arrays (:meth:`~.dagger.Dataset.save`); runs and studies read such files back as shared
data. :func:`read_dataset_arrays` reads one without trusting it:

- the path must be a regular file of at most :data:`MAX_DATASET_BYTES` (a FIFO is never
  opened, so nothing waits for a writer);
- no pickle, and every array's header is read before its data
  (:func:`~tether_gym_agents.files.safe_npz.read_npz`): the sizes the headers declare
  must fit in the archive's members and, together, in :data:`MAX_DATASET_BYTES`, so a
  small file cannot make the reader allocate gigabytes;
- every key of :data:`DATA_KEYS` is present, with its shape and kind: ``obs`` (N, d) and
  ``labels`` (N, n) finite reals with N >= 1, the labels in [-1, 1] (the rate-mode
  action range mpc's labels are clipped to); ``iteration``, ``episode`` (N,) integers
  >= 0, each episode number below E; ``expert_acted`` (N,) booleans; and per episode
  (E,) ``episode_env_seed``, ``episode_eccentricity``, ``episode_beta``,
  ``episode_mixture_seed`` and (E, n) ``episode_masses`` (the env's ``masses``, one
  per tether's end body).

Anything else is one ``ValueError`` naming the file and the key.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np

from ..files.safe_npz import read_npz

__all__ = ["DATA_KEYS", "MAX_DATASET_BYTES", "read_dataset_arrays"]

MAX_DATASET_BYTES = 1 << 32
"""The largest dataset read [bytes], 4 GiB, on disk and as arrays in memory (two million
labels of mpc, the largest shared set of the studies, are about 250 MB as arrays)."""

_PAIR_KEYS = ("obs", "labels", "iteration", "episode", "expert_acted")
_EPISODE_KEYS = ("episode_env_seed", "episode_eccentricity", "episode_masses",
                 "episode_beta", "episode_mixture_seed")
DATA_KEYS = _PAIR_KEYS + _EPISODE_KEYS
"""The arrays of a dataset file: per pair, then per episode."""


def read_dataset_arrays(path) -> dict[str, np.ndarray]:
    """The checked arrays of the dataset file ``path`` (see the module docstring).

    Raises
    ------
    ValueError
        Naming ``path``: not a regular file, too large, not an ``.npz`` of plain arrays,
        a key missing, or an array of the wrong shape, kind or values.
    """
    path = Path(path)
    try:
        info = os.stat(path)
    except OSError as exc:
        raise ValueError(f"{path} cannot be read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(info.st_mode):
        raise ValueError(f"{path} is not a regular file (a folder, FIFO or device is never "
                         "read)")
    if info.st_size > MAX_DATASET_BYTES:
        raise ValueError(f"{path} is {info.st_size} bytes; at most {MAX_DATASET_BYTES}")
    arrays = read_npz(path, max_bytes=MAX_DATASET_BYTES, required=DATA_KEYS,
                      what="a dataset file")
    _check_arrays(arrays, path)
    return arrays


def _check_arrays(a: dict[str, np.ndarray], path: Path) -> None:
    """Shapes, kinds and values of the arrays (see the module docstring)."""
    def bad(key: str, allowed: str) -> ValueError:
        arr = a[key]
        return ValueError(f"{path}: {key!r} has shape {arr.shape} and dtype {arr.dtype}; "
                          f"allowed: {allowed}")

    obs, labels = a["obs"], a["labels"]
    for key in ("obs", "labels"):
        if a[key].ndim != 2 or a[key].dtype.kind not in "fiu" or a[key].shape[1] < 1:
            raise bad(key, "a 2-D array of real numbers")
    n = len(obs)
    if n < 1:
        raise ValueError(f"{path} holds no pairs (obs has shape {obs.shape}); allowed: >= 1")
    if len(labels) != n:
        raise bad("labels", f"one row per observation ({n})")
    if not np.isfinite(obs).all():
        raise ValueError(f"{path}: 'obs' holds NaN or inf; allowed: finite numbers")
    if not (np.isfinite(labels).all() and np.abs(labels).max() <= 1.0):
        raise ValueError(f"{path}: 'labels' hold values outside [-1, 1] (or NaN); allowed: "
                         "actions in [-1, 1]")
    for key in ("iteration", "episode"):
        if a[key].shape != (n,) or a[key].dtype.kind not in "iu" or (a[key] < 0).any():
            raise bad(key, f"({n},) integers >= 0")
    if a["expert_acted"].shape != (n,) or a["expert_acted"].dtype != np.bool_:
        raise bad("expert_acted", f"({n},) booleans")
    n_episodes, n_masses = len(a["episode_env_seed"]), labels.shape[1]
    for key in _EPISODE_KEYS:
        arr = a[key]
        masses = key == "episode_masses"
        shape_ok = arr.shape == ((n_episodes, n_masses) if masses else (n_episodes,))
        if not shape_ok or arr.dtype.kind not in "fiu" or not np.isfinite(arr).all():
            raise bad(key, f"finite numbers, one per episode ({n_episodes}"
                           + (f", each a row of {n_masses} masses: one per tether, as "
                              "the labels)" if masses else ")"))
    if (a["episode"] >= n_episodes).any():
        raise ValueError(f"{path}: 'episode' numbers reach {int(a['episode'].max())}; "
                         f"allowed: below the {n_episodes} episodes recorded")
