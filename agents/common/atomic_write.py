"""Writes that replace a file whole, never through what is in its place.

:func:`atomic_target` gives a new temporary file beside the target (created with
``O_EXCL`` under a random hidden name, so never a link or FIFO someone put there) and
renames it onto the target when the write succeeds. The rename replaces whatever was at
the target, a symlink or FIFO included, instead of writing through it: before, a
``results.json`` symlinked to a file outside ``--out`` had that file overwritten, and a
FIFO of that name made ``evaluate.py`` wait for ever. A write cut short leaves the old
file (and at most a hidden ``.tmp-*`` file, which the training calls remove).
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

__all__ = ["atomic_target", "write_text_atomic", "save_figure", "new_temporary_file"]


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a new temporary file and ``os.replace``."""
    with atomic_target(path) as tmp:
        tmp.write_text(text)


def save_figure(fig, path: Path, **savefig_kwargs) -> Path:
    """``fig.savefig`` onto ``path`` through :func:`atomic_target`; returns ``path``."""
    with atomic_target(path) as tmp:
        fig.savefig(tmp, **savefig_kwargs)
    return Path(path)


def new_temporary_file(path: Path) -> Path:
    """A new empty file beside ``path``: ``.tmp-<pid>-<random>-<name>``, made ``O_EXCL``.

    The name is hidden and keeps ``path``'s suffix (writers that add a suffix leave it
    alone, and the checkpoint globs do not see it). ``O_EXCL`` makes it a new regular
    file, never a link or FIFO someone put at that name.
    """
    path = Path(path)
    while True:
        tmp = path.with_name(f".tmp-{os.getpid()}-{secrets.token_hex(4)}-{path.name}")
        try:
            os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            return tmp
        except FileExistsError:
            continue


@contextmanager
def atomic_target(path: Path) -> Iterator[Path]:
    """A temporary path to write ``path``'s content to; renamed onto ``path`` on success.

    The temporary file is :func:`new_temporary_file`'s; it is removed when the write
    fails (see the module docstring).
    """
    path = Path(path)
    tmp = new_temporary_file(path)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
