"""Atomic writes replace what is at the target (a symlink, a FIFO) instead of writing
through it, and leave the old file when the write fails."""

from __future__ import annotations

import os

import pytest

from tether_gym_agents.common.atomic_write import atomic_target, write_text_atomic


def test_a_fifo_or_link_at_the_target_is_replaced(tmp_path):
    precious = tmp_path / "precious.txt"
    precious.write_text("keep")
    (tmp_path / "link.json").symlink_to(precious)
    os.mkfifo(tmp_path / "fifo.json")  # opening it for writing would wait for a reader
    for name in ("link.json", "fifo.json"):
        write_text_atomic(tmp_path / name, "{}\n")
        assert (tmp_path / name).read_text() == "{}\n"
        assert (tmp_path / name).is_file() and not (tmp_path / name).is_symlink()
    assert precious.read_text() == "keep"


def test_the_temporary_file_is_new_hidden_and_keeps_the_suffix(tmp_path):
    with atomic_target(tmp_path / "plot.png") as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".tmp-")
        assert tmp.suffix == ".png" and tmp.is_file() and tmp.stat().st_size == 0
        tmp.write_bytes(b"png")
    assert (tmp_path / "plot.png").read_bytes() == b"png"
    assert [p.name for p in tmp_path.iterdir()] == ["plot.png"]


def test_a_failed_write_keeps_the_old_file(tmp_path):
    (tmp_path / "a.txt").write_text("old")
    with pytest.raises(RuntimeError), atomic_target(tmp_path / "a.txt") as tmp:
        tmp.write_text("half")
        raise RuntimeError("cut")
    assert (tmp_path / "a.txt").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]
