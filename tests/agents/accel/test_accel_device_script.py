"""bench/gpu_session*.sh, the prepared device calls: every command in them is one this
tree accepts (a typo there would cost a device session, which CI cannot run)."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[3]
SCRIPTS = ("gpu_session3.sh", "gpu_session4.sh")


def _flags(text: str) -> str:
    """The script's ``FLAGS="..."`` value ("" where it sets none)."""
    found = re.search(r'^FLAGS="([^"]*)"', text, re.M)
    return found.group(1) if found else ""


def _commands(script: str) -> list[list[str]]:
    """The script's python3 command lines (continuations joined, ``$FLAGS`` and the
    script's one-word assignments such as ``CFG=<path>`` expanded, the shell's other
    variables as placeholders), split into words."""
    text = (ROOT / "bench" / script).read_text().replace("\\\n", " ")
    flags = _flags(text)
    paths = dict(re.findall(r"^([A-Z]+)=([\w./-]+)$", text, re.M))  # e.g. CFG=<a path>
    out = []
    command = re.compile(r"^\s*(?:\w+=\S+\s+)*(?:timeout\s+\S+\s+)?python3\s")
    for line in text.splitlines():
        if not command.match(line):  # comments, and python3 inside an echo
            continue
        line = line.replace("$FLAGS", flags)
        for name, value in paths.items():
            line = line.replace(f"${name}", value)
        line = re.sub(r"\$\{?(\w+)\}?", r"VAR_\1", line)
        words = shlex.split(line.split("python3 ", 1)[1].split("|")[0])
        out.append(words)
    return out


def _tries(script: str) -> list[tuple[str, list[str]]]:
    """The script's ``TRIES`` entries, ``"backend|flags"`` ($FLAGS expanded), in order."""
    text = (ROOT / "bench" / script).read_text()
    flags = _flags(text)
    block = re.search(r"^TRIES=\((.*?)^\)", text, re.M | re.S)
    if block is None:
        return []
    entries = re.findall(r'^\s*"([^"|]*)\|([^"]*)"', block.group(1), re.M)
    return [(b, f.replace("$FLAGS", flags).split()) for b, f in entries]


def _help_flags(argv: list[str]) -> set[str]:
    done = subprocess.run([sys.executable, *argv, "--help"], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return set(re.findall(r"--[a-z][a-z0-9-]*", done.stdout))


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_flag_is_one_its_script_takes(script):
    """Each ``train.py gpu`` and ``bench/*.py`` command's flags are in its ``--help``,
    each backend named is one the env has, each ``--config`` a file, and each ``-k``
    expression of a pytest command selects tests in its file."""
    from tether_gym_agents.accel.vec_env import BACKENDS

    commands = _commands(script)
    kinds = {tuple(w[:2]) if w[0] == "train.py" else (w[0],) for w in commands}
    assert ("train.py", "gpu") in kinds and ("bench/gpu_throughput.py",) in kinds
    assert any(w[:2] == ["-m", "pytest"] for w in commands)
    helps: dict[tuple, set[str]] = {}
    for words in commands:
        if words[:2] == ["-m", "pytest"]:
            files = [w for w in words if w.endswith(".py")]
            assert files and all((ROOT / f).is_file() for f in files), files
            if "-k" not in words:
                continue
            k = words[words.index("-k") + 1]
            done = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q",
                                   "-p", "no:cacheprovider", *files, "-k", k],
                                  capture_output=True, text=True, cwd=ROOT, timeout=300)
            assert re.search(r"\d+/\d+ tests collected|\d+ tests? collected",
                             done.stdout), (k, done.stdout[-1000:])
            assert " 0 selected" not in done.stdout and "no tests ran" not in done.stdout, k
            continue
        if words[0] == "-c":
            continue
        key = tuple(words[:2]) if words[0] == "train.py" else (words[0],)
        if key not in helps:
            helps[key] = _help_flags(list(key))
        for i, word in enumerate(words):
            if word.startswith("--"):
                assert word in helps[key], (key, word)
            if word == "--config":
                assert (ROOT / words[i + 1]).is_file(), words[i + 1]
            if word == "--backend":
                for value in words[i + 1:]:
                    if value.startswith("--"):
                        break
                    assert value in BACKENDS or value.startswith("VAR_"), value


def test_the_training_tries_are_commands_train_py_takes():
    """gpu_session4.sh's fallbacks (``TRIES``): each backend is one the env has, each
    flag one ``train.py gpu`` takes, no two alike, and the first is the fastest path:
    numba-cuda with the five flags of ``$FLAGS``."""
    from tether_gym_agents.accel.vec_env import BACKENDS

    tries = _tries("gpu_session4.sh")
    assert len(tries) >= 3, tries
    assert tries[0] == ("numba-cuda", ["--cuda-graphs", "--sync-free", "--compile",
                                       "--compile-update", "--compile-rollout"])
    assert len({(b, tuple(f)) for b, f in tries}) == len(tries), tries
    flags = _help_flags(["train.py", "gpu"])
    for backend, words in tries:
        assert backend in BACKENDS, backend
        assert words and all(w in flags for w in words), (backend, words)
