"""``kill -9`` of a ``train.py`` run during a checkpoint save and during an evaluation,
then ``--resume``: no lost or doubled step, the step count right (issue 24).

Each run is a subprocess that sends itself SIGKILL at the chosen moment (a hook
installed before ``train.py``'s main), so nothing of the killed process runs after.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from tether_gym_agents.cli.train import main

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs SIGKILL")

ARGV = ["--n-envs", "2", "--no-progress", "--eval-episodes", "1", "--eval-freq", "256",
        "--checkpoint-freq", "256", "--env-kwargs", "orbits_per_episode=0.05"]

HOOKS = {
    # the model zip of the checkpoint at 512 is half written when the process dies
    "save": """
        from stable_baselines3.common.base_class import BaseAlgorithm
        original = BaseAlgorithm.save
        def save(self, path, *args, **kwargs):
            original(self, path, *args, **kwargs)
            if "512_steps" in str(path):
                with open(path, "r+b") as fh:
                    fh.truncate(200)
                os.kill(os.getpid(), signal.SIGKILL)
        BaseAlgorithm.save = save
    """,
    # the evaluation at 768 is under way when the process dies
    "evaluation": """
        import stable_baselines3.common.callbacks as cb
        import stable_baselines3.common.evaluation as ev
        original = ev.evaluate_policy
        def evaluate_policy(model, *args, **kwargs):
            if model.num_timesteps >= 768:
                os.kill(os.getpid(), signal.SIGKILL)
            return original(model, *args, **kwargs)
        ev.evaluate_policy = cb.evaluate_policy = evaluate_policy
    """,
}


def _killed_run(out, hook):
    code = "import os, signal, sys\n" + textwrap.dedent(HOOKS[hook]) + textwrap.dedent("""
        from tether_gym_agents.cli.train import main
        sys.exit(main(sys.argv[1:]))
    """)
    proc = subprocess.run([sys.executable, "-c", code, "--out", str(out), *ARGV,
                           "--timesteps", "2048"], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == -signal.SIGKILL, proc.stderr[-2000:]


@pytest.mark.parametrize("hook, resumed_from", [("save", 256), ("evaluation", 512)])
def test_kill_9_then_resume_loses_and_doubles_no_step(tmp_path, capsys, hook, resumed_from):
    out = tmp_path / "run"
    _killed_run(out, hook)
    info = json.loads((out / "train_info.json").read_text())
    assert info["status"] == "running"
    capsys.readouterr()
    # rollouts of 2 x 512 steps: the resumed call trains one
    assert main(["--out", str(out), *ARGV, "--timesteps", "1024", "--resume"]) == 0
    printed = capsys.readouterr()
    assert f"at step {resumed_from}" in printed.out and "Traceback" not in printed.err
    info = json.loads((out / "train_info.json").read_text())
    assert info["status"] == "finished" and info["num_timesteps"] == resumed_from + 1024
    with np.load(out / "eval" / "evaluations.npz") as data:
        steps = list(data["timesteps"])
    assert steps == list(range(256, resumed_from + 1024 + 1, 256))  # each step once
    assert not list(out.rglob(".tmp-*"))
