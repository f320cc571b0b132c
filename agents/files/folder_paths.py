"""Files read from an agent or run folder: regular files that stay inside the folder.

An agent folder may come from someone else (a download, shared storage). A symlink in it
(``command.txt -> /etc/passwd``, ``policy.safetensors -> ~/secret``) would make loading or
exporting read a file outside the folder and copy or interpret its contents. Every file
that :mod:`.safe_format`, :mod:`.pickled` and :mod:`.export` read goes through
:func:`file_inside`: a regular file, or a symlink whose resolved target is a regular file
inside the same folder; anything else (a symlink leading out, a device, a FIFO, a folder)
is an :class:`~.safe_format.AgentLoadError` naming the file. Nothing is skipped silently.
"""

from __future__ import annotations

import stat
from pathlib import Path

__all__ = ["FolderFileError", "file_inside"]


class FolderFileError(ValueError):
    """A file of an agent or run folder is not a regular file inside the folder."""


def file_inside(root, path) -> Path:
    """``path``, checked to be a regular file whose resolved location is inside ``root``.

    Parameters
    ----------
    root : path-like
        The folder the file must stay in (itself resolved: the folder may be a symlink).
    path : path-like
        The file (may be a symlink whose target stays inside ``root``).

    Returns
    -------
    Path
        ``path`` unchanged (callers name the file the user knows).

    Raises
    ------
    FolderFileError
        If ``path`` resolves outside ``root`` or is not a regular file (a device, FIFO,
        socket or folder), or cannot be read (a dangling symlink).
    """
    root, path = Path(root), Path(path)
    real_root = root.resolve()
    target = path.resolve()
    if not target.is_relative_to(real_root):
        raise FolderFileError(f"{path} leads outside {root} (to {target}); agent and run "
                              "folders are read only from regular files inside them")
    try:
        mode = target.stat().st_mode
    except OSError as exc:
        raise FolderFileError(f"{path} cannot be read ({exc.strerror}; a dangling "
                              "symlink?)") from None
    if not stat.S_ISREG(mode):
        raise FolderFileError(f"{path} is not a regular file; agent and run folders are read "
                              "only from regular files inside them")
    return path
