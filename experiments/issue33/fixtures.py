"""Crafted files for the sweep: the tiny run folders it copies, and the file builders.

:func:`build_fixtures` trains a tiny PPO and SAC run with ``train.py`` itself (64 env
steps each) into a cache folder once per sweep; every input that needs an agent or a run
folder copies one and mutates the copy in its own temporary folder (the helpers below).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
TINY_TRAIN = ["--timesteps", "64", "--n-envs", "1", "--no-progress", "--eval-episodes", "1",
              "--eval-freq", "64"]
"""train.py options that make a valid run end in a few seconds."""
SECRET = "SECRET-TOKEN-issue33"


def build_fixtures(fix: Path, env: dict) -> None:
    """``fix/run_ppo`` (checkpoints at 32 and 64 steps) and ``fix/run_sac``, by train.py."""
    fix.mkdir(parents=True, exist_ok=True)
    for algo in ("ppo", "sac"):
        out = fix / f"run_{algo}"
        if (out / "final_agent" / "agent.json").is_file():
            continue
        cmd = [sys.executable, str(REPO / "train.py"), "--algo", algo, *TINY_TRAIN,
               "--checkpoint-freq", "32", "--out", str(out)]
        done = subprocess.run(cmd, cwd=fix, env=env, capture_output=True, text=True,
                              timeout=300, check=False)
        if done.returncode != 0:
            raise SystemExit(f"fixture {out} failed (exit {done.returncode}):\n"
                             f"{done.stderr[-3000:]}")


# --------------------------------------------------------------------------- #
# file helpers, each called in an input's setup with its temporary folder
def copy_tree(src: Path, dest: Path) -> Path:
    shutil.copytree(src, dest, symlinks=True)
    return dest


def write(path: Path, text: str | bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def replace_with_link(path: Path, target: str | Path) -> None:
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(target, path)


def replace_with_fifo(path: Path) -> None:
    if path.is_symlink() or path.exists():
        path.unlink()
    path.parent.mkdir(parents=True, exist_ok=True)
    os.mkfifo(path)


def secret(tmp: Path) -> Path:
    """``tmp/outside/secret.txt``, a file outside every folder a command is given."""
    return write(tmp / "outside" / "secret.txt", SECRET + "\n")


def snapshot(root: Path) -> dict:
    """{relative path: (size, mtime_ns)} of everything under ``root`` (links not followed)."""
    out = {}
    if root.exists():
        for dirpath, dirs, files in os.walk(root):
            for name in dirs + files:
                p = Path(dirpath) / name
                st = p.lstat()
                out[str(p.relative_to(root))] = [st.st_size, st.st_mtime_ns]
    return out


def load_json(path: Path):
    return json.loads(path.read_text())


def dump_json(path: Path, data) -> None:
    path.write_text(json.dumps(data, indent=1))  # NaN/Infinity written as JSON extensions


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def load_weights(path: Path) -> dict:
    from safetensors.numpy import load_file

    return load_file(str(path))


def save_weights(path: Path, tensors: dict) -> None:
    from safetensors.numpy import save_file

    save_file(tensors, str(path))


def restamp(agent: Path) -> None:
    """Write the weights file's sha256 into agent.json (as a crafter of the folder would)."""
    data = load_json(agent / "agent.json")
    if isinstance(data.get("weights"), dict):
        data["weights"]["sha256"] = sha256(agent / "policy.safetensors")
        dump_json(agent / "agent.json", data)


def tree_contains(root: Path, needle: str, but: Path | None = None) -> list[str]:
    """Regular files under ``root`` (not followed through links) whose bytes hold ``needle``.

    Hard links of ``but`` (the same inode) are not counted: the input put them there.
    """
    hits: list[str] = []
    if not root.exists():
        return hits
    skip = os.stat(but).st_ino if but is not None and but.exists() else None
    for dirpath, _dirs, files in os.walk(root):
        for name in files:
            p = Path(dirpath) / name
            if p.is_symlink() or not p.is_file() or os.stat(p).st_ino == skip:
                continue
            try:
                if needle.encode() in p.read_bytes():
                    hits.append(str(p.relative_to(root)))
            except OSError:
                pass
    return hits
