"""bench/accel_iteration.py: its timing of an iteration of ``train.py gpu``, part by part."""

import importlib.util
import json
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[3]

TINY = """tether_gym/TetherLibration-v2:
  n_envs: 8
  n_steps: 16
  batch_size: 64
  n_epochs: 2
  n_timesteps: 4096
"""


@pytest.fixture(scope="module")
def bench():
    path = ROOT / "bench" / "accel_iteration.py"
    spec = importlib.util.spec_from_file_location("accel_iteration", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "tiny.yml"
    path.write_text(TINY)
    return path


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_the_parts_are_timed_inside_their_iterations(bench, tiny, backend, capsys):
    """Every part is timed (the numba backend's kernel and end only with it), the parts
    of an iteration add up to no more than its wall time, the config's training time is
    its iterations times run 1's, and the trainer is left as it was."""
    from tether_gym_agents.accel import trainer

    real = (trainer._update, trainer.GraphedCall, trainer.RolloutStep,
            trainer.evaluate_on_device, trainer.Rollout.finish)
    assert bench.main(["--config", str(tiny), "--device", "cpu", "--backend", backend,
                       "--iterations", "5"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert (trainer._update, trainer.GraphedCall, trainer.RolloutStep,
            trainer.evaluate_on_device, trainer.Rollout.finish) == real
    parts = out["parts_ms_per_iteration"]
    assert set(parts) == set(bench.PARTS)
    numba = backend == "numba"
    for name, ms in parts.items():
        assert ms > 0 or (name in ("kernel", "end") and not numba), name
    assert (parts["end"] == 0) != numba
    assert sum(parts.values()) <= out["parts_run_ms_per_iteration"] + 1e-3 * len(parts)
    assert out["ms_per_iteration"] > 0 and out["timed_iterations"] == 1
    assert out["config_iterations"] == 4096 // (8 * 16)
    assert out["config_training_s"] == round(out["ms_per_iteration"] * 32 / 1e3, 1)


def test_bad_arguments_are_refused(bench, tiny):
    for argv in (["--iterations", "4"], ["--device", "cpu", "--cuda-graphs"],
                 ["--device", "cpu", "--backend", "numba-cuda"],
                 ["--config", str(tiny.parent / "missing.yml")]):
        with pytest.raises(SystemExit) as exc:
            bench.main(["--config", str(tiny), *argv] if argv[0] != "--config" else argv)
        assert exc.value.code == 2
