"""bench/accel_update.py: one minibatch step's kernels and time, eager and fused."""

import json

import pytest

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("accel_update")


def test_the_fused_step_runs_a_fraction_of_the_eager_kernels(bench, tiny, capsys):
    """On the tiny config (128 samples per seed in minibatches of 48: 3 steps, the last
    32 rows), the eager step's count is about bench/accel_ops.py's, the fused step's is
    Inductor's kernels and the matrix products, several times fewer."""
    assert bench.main(["--config", str(tiny), "--seeds", "2", "--repeats", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["samples_per_seed"] == 128 and out["minibatch_steps_per_update"] == 3
    eager, fused = out["eager"], out["fused"]
    assert 300 <= eager["kernels_per_minibatch_step"] <= 450  # accel_ops: about 365
    names = dict(fused["most_frequent"])
    assert names["inductor"] >= 1 and names["bmm"] >= 1 and "mul" not in names
    assert fused["kernels_per_minibatch_step"] <= eager["kernels_per_minibatch_step"] / 4
    assert out["kernels_ratio"] == round(eager["kernels_per_minibatch_step"]
                                         / fused["kernels_per_minibatch_step"], 1)
    assert eager["ms_per_minibatch_step"] > 0 and fused["ms_per_minibatch_step"] > 0


@pytest.mark.parametrize("name", ["accel_update", "accel_rollout"])
@pytest.mark.parametrize("argv", [["--seeds", "0"], ["--repeats", "0"],
                                  ["--device", "cuda:99"]])
def test_bad_arguments_are_refused(load_bench, tiny, name, argv):
    """The command line of accel_update.py, which accel_rollout.py shares (``cli``)."""
    with pytest.raises(SystemExit) as exc:
        load_bench(name).main(["--config", str(tiny), *argv])
    assert exc.value.code == 2
