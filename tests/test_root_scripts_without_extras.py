"""The root scripts after the environment-only install (``pip install -e .``).

Without the extras, ``train.py``, ``evaluate.py`` and ``evaluate.py mpc`` must end in one
``error:`` line naming the install command and exit code 2, not in a traceback. A
missing package is simulated in a fresh interpreter by an import hook that refuses it
(as Python does when it is not installed), then the script runs as ``python SCRIPT``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

RUNNER = """
import runpy, sys
missing = set(sys.argv[1].split(","))
class Refuse:
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in missing:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Refuse())
sys.argv = sys.argv[2:]
runpy.run_path(sys.argv[0], run_name="__main__")
"""
TRAIN_EXTRA = 'pip install torch==2.13.0 && pip install -e ".[train]"'


def _run_without(missing: str, *argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", RUNNER, missing, *argv], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def _one_error_line(proc: subprocess.CompletedProcess, script: str) -> str:
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.returncode == 2, proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith(f"{script}: error: "), proc.stderr
    return last


def test_evaluate_without_torch_names_the_install_command(tmp_path):
    proc = _run_without("torch", "evaluate.py", "ppo", "--seeds", "1", "--suite", "paper",
                        "--out", str(tmp_path / "eval"))
    line = _one_error_line(proc, "evaluate.py")
    assert "torch" in line and TRAIN_EXTRA in line


@pytest.mark.parametrize("missing", ["yaml", "torch,yaml,stable_baselines3,safetensors"])
def test_train_without_the_train_extra_names_the_install_command(tmp_path, missing):
    proc = _run_without(missing, "train.py", "--timesteps", "64", "--out", str(tmp_path / "r"))
    line = _one_error_line(proc, "train.py")
    assert 'pip install -e ".[train]"' in line
    assert not (tmp_path / "r" / "final_agent").exists()


def test_evaluate_mpc_without_casadi_names_the_mpc_extra(tmp_path):
    proc = _run_without("casadi", "evaluate.py", "mpc", "--seeds", "1", "--suite", "paper",
                        "--out", str(tmp_path / "eval"))
    line = _one_error_line(proc, "evaluate.py")
    assert 'pip install -e ".[mpc]"' in line


def test_a_missing_module_of_the_package_itself_is_not_hidden():
    proc = _run_without("tether_gym_agents", "train.py", "--help")
    assert proc.returncode == 1 and "ModuleNotFoundError" in proc.stderr
