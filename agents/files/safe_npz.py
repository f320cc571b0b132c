"""The one reader of ``.npz`` files of plain arrays that a run or a user hands us.

``np.load(..., allow_pickle=False)`` runs no code, but it allocates each array at the
size its header declares before reading the data: a file of 1 kB declaring a
(10**10, 1) float64 array was ``Unable to allocate 74.5 GiB`` (a ``MemoryError``
traceback) from ``train.py --seeds``, which reads ``eval/evaluations.npz``.
:func:`read_npz` reads every header first: the size it declares must fit the archive
member that holds it (the member's uncompressed size, which the zip reader enforces),
and all of them together ``max_bytes``; an object array (a pickle) is refused too.
Anything else a damaged or forged archive raises (a bad zip, a garbled header, a cut
member) becomes the same :class:`NpzFileError`, naming the file.
"""

from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["NpzFileError", "read_npz", "after_path"]


class NpzFileError(ValueError):
    """An ``.npz`` that is not a readable archive of plain arrays of bounded size."""


def read_npz(path, *, max_bytes: int, required: tuple[str, ...] = (),
             what: str = "an .npz") -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` at ``path``, each header checked before its data.

    Parameters
    ----------
    path : path-like
        The file (the caller has checked it is a regular file it may read).
    max_bytes : int
        Largest total size [bytes] of the arrays the headers declare.
    required : tuple of str
        Arrays that must be present; a missing one is named with the list.
    what : str
        What the file is, for the message of a missing array.

    Raises
    ------
    NpzFileError
        Naming ``path``: not a zip of ``.npy`` members, a garbled header, an object
        array, a declared size beyond its member or ``max_bytes``, a missing array.
    """
    path = Path(path)
    try:  # one open archive: the arrays read are those whose headers were checked
        with zipfile.ZipFile(path) as archive:
            members = _checked_members(archive, path, max_bytes)
            missing = [k for k in required if k not in members]
            if missing:
                raise NpzFileError(f"{path} holds no {missing[0]!r}; {what} holds "
                                   f"{list(required)}")
            arrays = {}
            for name in members:
                with archive.open(f"{name}.npy") as fh:
                    arrays[name] = np.lib.format.read_array(fh, allow_pickle=False)
            return arrays
    except NpzFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - a forged archive raises many kinds
        raise NpzFileError(f"{path} is not a readable .npz of plain arrays "
                           f"({type(exc).__name__}: {exc})") from None


def _checked_members(archive: zipfile.ZipFile, path: Path, max_bytes: int) -> list[str]:
    """The arrays' names, after checking each declared size against its member."""
    names, total = [], 0
    for member in archive.infolist():
        if not member.filename.endswith(".npy"):
            continue
        with archive.open(member) as fh:
            version = np.lib.format.read_magic(fh)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, _, dtype = read_header(fh)
        declared = math.prod(shape) * dtype.itemsize
        total += declared
        name = member.filename[:-len(".npy")]
        if dtype.hasobject or declared > member.file_size or total > max_bytes:
            raise NpzFileError(f"{path}: {name!r} declares {shape} x {dtype} ({declared} "
                               f"bytes) in a member of {member.file_size} bytes; allowed: "
                               f"plain arrays that fit their member, {max_bytes} bytes in "
                               "all")
        names.append(name)
    return names


def after_path(exc: Exception, path) -> str:
    """The message of ``exc`` without the leading ``path`` (for a caller that names it)."""
    return str(exc).removeprefix(str(path)).lstrip(": ").strip()
