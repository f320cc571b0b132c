"""bench/accel_iteration.py: its timing of an iteration of ``train.py gpu``, part by part."""

import json

import pytest

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("accel_iteration")


@pytest.mark.parametrize(("backend", "compiled"), [("numba", False), ("torch", False),
                                                  ("numba", True)])
def test_the_parts_are_timed_inside_their_iterations(bench, tiny, backend, compiled, capsys):
    """Every part is timed (the numba backend's kernel and end only with it), the parts
    of an iteration add up to no more than its wall time, the config's training time is
    its iterations times run 1's, and the trainer is left as it was; the same with the
    update, the rollout and the env's torch parts compiled (``--compile-update
    --compile-rollout --compile``, numba backend)."""
    from tether_gym_agents.accel import trainer

    real = (trainer._update, trainer.GraphedCall, trainer.RolloutStep,
            trainer.evaluate_on_device, trainer.Rollout.finish)
    fused = ["--compile-update", "--compile-rollout", "--compile"] if compiled else []
    assert bench.main(["--config", str(tiny), "--device", "cpu", "--backend", backend,
                       "--iterations", "5", *fused]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["compile_update"] is out["compile_rollout"] is out["compile"] is compiled
    assert (trainer._update, trainer.GraphedCall, trainer.RolloutStep,
            trainer.evaluate_on_device, trainer.Rollout.finish) == real
    parts = out["parts_ms_per_iteration"]
    assert set(parts) == set(bench.PARTS)
    numba = backend == "numba"
    for name, ms in parts.items():  # no graphs on the CPU: no whole rollout's replay
        assert ms > 0 or (name in ("kernel", "end") and not numba) or name == "rollout", name
    assert parts["rollout"] == 0
    assert (parts["end"] == 0) != numba
    assert sum(parts.values()) <= out["parts_run_ms_per_iteration"] + 1e-3 * len(parts)
    assert out["ms_per_iteration"] > 0 and out["timed_iterations"] == 1
    assert out["config_iterations"] == -(-1000 // (8 * 16)) == 8
    assert out["config_training_s"] == round(out["ms_per_iteration"] * 8 / 1e3, 1)


def test_bad_arguments_are_refused(bench, tiny):
    for argv in (["--iterations", "4"], ["--device", "cpu", "--cuda-graphs"],
                 ["--device", "cpu", "--backend", "numba-cuda"],
                 ["--config", str(tiny.parent / "missing.yml")]):
        with pytest.raises(SystemExit) as exc:
            bench.main(["--config", str(tiny), *argv] if argv[0] != "--config" else argv)
        assert exc.value.code == 2
