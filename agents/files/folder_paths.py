"""Files read from an agent or run folder: regular files that stay inside the folder.

An agent or run folder may come from someone else (a download, shared storage). A
symlink in it (``command.txt -> /etc/passwd``, ``policy.safetensors -> ~/secret``,
``model_9999_steps.zip -> /dev/zero``) or a FIFO named like a checkpoint would make a
command read a file outside the folder, copy or interpret its contents, block forever
or fill the memory. Every file that a command reads from such a folder goes through
:func:`file_inside` before it is opened: a regular file, or a symlink whose resolved
target is a regular file inside the same folder, no larger than the cap of its kind
(:func:`size_cap`, checked with ``os.stat`` of the resolved target, so nothing is
opened to find out); anything else (a symlink leading out, a device, a FIFO, a folder,
a file over its cap) is a :class:`FolderFileError` naming the file. Nothing is skipped
silently.

Folders inside such a folder (``final_agent/``, ``seed_K/``, ``checkpoints/agent_N_steps/``)
go through :func:`folder_inside`: a symlinked one must lead to a folder inside the
folder too. :func:`copy_files_checked` copies named files of an agent folder only when
they are checked regular files (no link out, device or FIFO is followed or copied), and
:func:`real_folder` makes the folders a command writes into, refusing an existing
symlink among them (nothing is written through a link).

Size caps [bytes] (the largest file shipped in ``agents/pretrained`` is a 139 kB plot,
its largest weights 48 kB):

=====================================================  ==========================
``agent.json``, ``config.yml``, ``args.yml``,          :data:`TEXT_FILE_CAP`, 1 MiB
``command.txt``, ``train_info.json``
other ``.json`` / ``.yml`` / ``.yaml`` / ``.txt``      :data:`DOC_FILE_CAP`, 16 MiB
replay buffers (``*replay_buffer*``)                   :data:`BUFFER_FILE_CAP`, 16 GiB
everything else (weights, model zips, statistics,      :data:`DATA_FILE_CAP`, 512 MiB
evaluations, TensorBoard events, plots)
=====================================================  ==========================

A hard link (a regular file with more than one name) is read like any regular file: its
contents are interpreted, never copied elsewhere, except by an export, which refuses it
(:mod:`.export`).

The replay buffer's cap is large because SAC with ``buffer_size`` 1M and 16 envs saves
about 180 MB per copy; the others are thousands of times what this project writes.
"""

from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

__all__ = ["FolderFileError", "file_inside", "folder_inside", "copy_files_checked",
           "real_folder", "size_cap", "TEXT_FILE_CAP", "DOC_FILE_CAP", "DATA_FILE_CAP",
           "BUFFER_FILE_CAP"]

_MIB = 1 << 20
TEXT_FILE_CAP = 1 * _MIB
"""Largest ``agent.json``, ``config.yml``, ``args.yml``, ``command.txt``,
``train_info.json`` read [bytes]."""
DOC_FILE_CAP = 16 * _MIB
"""Largest other JSON/YAML/text file read (``curves.json``, ...) [bytes]."""
DATA_FILE_CAP = 512 * _MIB
"""Largest weights, model zip, statistics, evaluations or other data file read [bytes]."""
BUFFER_FILE_CAP = 16 * 1024 * _MIB
"""Largest replay buffer read [bytes]."""

_TEXT_NAMES = frozenset({"agent.json", "config.yml", "args.yml", "command.txt",
                         "train_info.json"})
_DOC_SUFFIXES = frozenset({".json", ".yml", ".yaml", ".txt", ".md", ".log"})


class FolderFileError(ValueError):
    """A file of an agent or run folder is not a regular file inside the folder."""


def size_cap(path) -> int:
    """The largest size [bytes] read of a file named like ``path`` (module table)."""
    name = Path(path).name
    if name in _TEXT_NAMES:
        return TEXT_FILE_CAP
    if "replay_buffer" in name:
        return BUFFER_FILE_CAP
    if Path(name).suffix.lower() in _DOC_SUFFIXES:
        return DOC_FILE_CAP
    return DATA_FILE_CAP


def _resolved_inside(root: Path, path: Path) -> Path:
    """``path`` resolved, checked to stay inside ``root`` (itself resolved)."""
    target = path.resolve()
    if not target.is_relative_to(root.resolve()):
        raise FolderFileError(f"{path} leads outside {root} (to {target}); agent and run "
                              "folders are read only from files and folders inside them")
    return target


def file_inside(root, path, *, max_bytes: int | None = None) -> Path:
    """``path``, checked to be a regular file inside ``root`` of at most ``max_bytes``.

    Parameters
    ----------
    root : path-like
        The folder the file must stay in (itself resolved: the folder may be a symlink).
    path : path-like
        The file (may be a symlink whose target stays inside ``root``).
    max_bytes : int or None
        Largest size accepted [bytes]; None: the cap of its kind (:func:`size_cap`).

    Returns
    -------
    Path
        ``path`` unchanged (callers name the file the user knows).

    Raises
    ------
    FolderFileError
        If ``path`` resolves outside ``root``, is not a regular file (a device, FIFO,
        socket or folder), cannot be read (a dangling symlink) or is larger than the cap
        (its size and the cap are in the message). Nothing is opened.
    """
    root, path = Path(root), Path(path)
    target = _resolved_inside(root, path)
    try:
        info = os.stat(target)
    except OSError as exc:
        raise FolderFileError(f"{path} cannot be read ({exc.strerror}; a dangling "
                              "symlink?)") from None
    if not stat.S_ISREG(info.st_mode):
        raise FolderFileError(f"{path} is not a regular file; agent and run folders are read "
                              "only from regular files inside them")
    cap = size_cap(path) if max_bytes is None else int(max_bytes)
    if info.st_size > cap:
        raise FolderFileError(f"{path} is {info.st_size} bytes, larger than the {cap} bytes "
                              f"accepted for a file of its kind ({path.name})")
    return path


def folder_inside(root, path) -> Path:
    """``path``, checked to be a folder whose resolved location is inside ``root``.

    A symlinked ``final_agent/`` or ``seed_K/`` leading to another folder would make a
    command evaluate or copy an agent that is not the one in the folder given.

    Raises
    ------
    FolderFileError
        If ``path`` resolves outside ``root`` or is not a folder.
    """
    root, path = Path(root), Path(path)
    target = _resolved_inside(root, path)
    if not target.is_dir():
        raise FolderFileError(f"{path} is not a folder")
    return path


def copy_files_checked(src, dst, names) -> None:
    """Copy the files ``names`` of the folder ``src`` into the new folder ``dst``, checked.

    Each one must be a regular file inside ``src`` under its cap (:func:`file_inside`; a
    symlink whose target stays inside is copied as that file); all are checked before
    anything is written, and only their contents are copied. Nothing else of ``src`` is
    read (a temporary file or folder a killed save left stays behind).

    Raises
    ------
    FolderFileError
        Naming the first file that is missing, leads outside ``src``, is not a regular
        file (a FIFO, a device, a link to ``/dev/zero``, a folder) or is over its cap.
    """
    src, dst = Path(src), Path(dst)
    files = [file_inside(src, src / name) for name in names]
    dst.mkdir(parents=True)
    for path in files:
        shutil.copyfile(path, dst / path.name)


def real_folder(dest, relative=".") -> Path:
    """``dest / relative``, made where missing; no part below ``dest`` may be a symlink.

    Writing into ``DEST/eval`` when ``eval`` is a symlink to another folder would write
    there. ``dest`` itself is the user's choice and may be a link.

    Raises
    ------
    FolderFileError
        If a part of the path below ``dest`` exists as a symlink or as something other
        than a folder.
    """
    dest = Path(dest)
    folder = dest
    for part in Path(relative).parts:
        if part in (".", ""):
            continue
        folder = folder / part
        if folder.is_symlink() or (folder.exists() and not folder.is_dir()):
            raise FolderFileError(f"{folder} is a symlink or not a folder; files are written "
                                  "only into real folders")
    folder.mkdir(parents=True, exist_ok=True)
    return folder
