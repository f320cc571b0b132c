"""The hostile-input sweep of experiments/issue33: its classifier and its runner (< 5 s)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parents[1] / "experiments" / "issue33"


@pytest.fixture(scope="module")
def sweep():
    sys.path.insert(0, str(HERE))
    try:
        yield importlib.import_module("sweep")
    finally:
        sys.path.remove(str(HERE))


def test_classify_outcomes(sweep):
    c = sweep.classify
    assert c("invalid", 2, "", "train.py: error: n_envs 0 < 1\n", False) == \
        ("clear", "train.py: error: n_envs 0 < 1")
    assert c("invalid", 1, "", "Traceback (most recent call last):\n  File x\nKeyError: 'td3'\n",
             False) == ("traceback", "KeyError: 'td3'")
    assert c("invalid", 0, "done\n", "", False)[0] == "accepted"
    assert c("invalid", None, "", "", True)[0] == "hang"
    assert c("invalid", -9, "", "", False) == ("hang", "killed by signal SIGKILL")
    assert c("invalid", 1, "", "numpy._core._exceptions._ArrayMemoryError: Unable to "
             "allocate 74.5 GiB\n", False)[0] == "hang"
    assert c("invalid", 2, "", "a\nb\nc\nd\n", False)[0] == "unclear"
    assert c("invalid", 2, "", "", False) == ("unclear", "(no message)")
    warned = "/x/y.py:3: UserWarning: careful\n  warnings.warn(\nevaluate.py: error: bad\n"
    assert c("invalid", 2, "", warned, False) == ("clear", "evaluate.py: error: bad")
    assert c("valid", 0, "ok\n", "", False)[0] == "ran"
    assert c("valid", 2, "", "error: no\n", False)[0] == "refused"
    assert c("warn", 0, "", "", False)[0] == "silent"
    assert c("warn", 0, "", "/a.py:1: UserWarning: beyond reach\n", False)[0] == "ran"
    assert c("any", 2, "", "error: refused\n", False)[0] == "clear"
    assert c("any", 0, "", "", False, harm="secret copied")[0] == "accepted"


def test_run_one_in_a_subprocess(sweep, tmp_path):
    Input = sweep.hostile_inputs.Input
    py = ["{py}", "-c"]
    cases = {
        "exit0": (Input("t.exit0", "t", [*py, "print('fine')"], "invalid", ""), "accepted"),
        "refuse": (Input("t.refuse", "t", [*py, "import sys; sys.exit('x: error: no')"],
                         "invalid", ""), "clear"),
        "raise": (Input("t.raise", "t", [*py, "raise KeyError('k')"], "invalid", ""),
                  "traceback"),
        "sleep": (Input("t.sleep", "t", [*py, "import time; time.sleep(30)"], "invalid", ""),
                  "hang"),
        "alloc": (Input("t.alloc", "t", [*py, "b = bytearray(8 << 30)"], "invalid", ""),
                  "hang"),
    }
    for name, (inp, want) in cases.items():
        row = sweep.run_one(inp, tmp_path, timeout=0.5 if name == "sleep" else 20.0,
                            memory_bytes=2 << 30)
        assert row["class"] == want, (name, row)


def test_inputs_cover_every_surface(sweep):
    inputs = sweep.hostile_inputs.all_inputs()
    assert len(inputs) >= 300
    assert len({x.id for x in inputs}) == len(inputs)
    surfaces = {x.surface for x in inputs}
    assert {"train_cli", "train_config", "evaluate_cli", "suite_yaml", "agent_folder",
            "weights_file", "run_resume", "run_export", "gym_make", "mpc"} <= surfaces
    assert {x.expect for x in inputs} == {"invalid", "valid", "warn", "any"}
