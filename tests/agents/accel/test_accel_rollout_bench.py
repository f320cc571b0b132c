"""bench/accel_rollout.py: the rollout's own kernels and time per step, eager and fused."""

import json

import pytest

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("accel_rollout")


def test_the_fused_rollout_runs_a_fraction_of_the_eager_kernels(bench, tiny, capsys):
    """On the tiny config (2 seeds x 8 envs, 16 steps), the eager rollout step is about
    140 operations, the fused one Inductor's kernels, the policy's and value net's
    matrix products (3 layers each: the actions and values, and the bootstrap's values;
    the advantages' last values once per iteration), the take's copies and the eager
    draw: several times fewer."""
    assert bench.main(["--config", str(tiny), "--seeds", "2", "--repeats", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rollout_steps_per_iteration"] == 16 and out["envs_per_seed"] == 8
    eager, fused = out["eager"], out["fused"]
    assert 100 <= eager["kernels_per_rollout_step"] <= 200
    names = dict(fused["most_frequent"])
    assert names["inductor"] >= 1 and names["randn"] == 1
    assert names["baddbmm"] == round(9 + 3 / 16, 1)
    assert "mul" not in names and "add" not in names
    assert fused["kernels_per_rollout_step"] <= eager["kernels_per_rollout_step"] / 3
    assert out["kernels_ratio"] == round(eager["kernels_per_rollout_step"]
                                         / fused["kernels_per_rollout_step"], 1)
    assert eager["ms_per_rollout_step"] > 0 and fused["ms_per_rollout_step"] > 0



def test_the_whole_rollout_step_with_a_numba_env(bench, tiny, capsys):
    """``--env numba``: the learner's whole rollout step on a real env of the numba
    backend, fused with the env's ``compile=True`` too: more kernels than the rollout's
    own (the env's draws, masks and resets), and several times fewer fused. The rollout
    reads the env's step where the env leaves it and writes its actions where the env
    reads them (no copies either way): fused, a step's eager operations are the
    actions' draw and the matrix products (the tiny config's env draws no disturbance
    and no noise), besides the resets' draws and the autoreset's host reads."""
    assert bench.main(["--config", str(tiny), "--repeats", "1", "--env", "numba"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["env"] == "numba"
    eager, fused = out["eager"], out["fused"]
    assert eager["kernels_per_rollout_step"] >= 150
    names = dict(fused["most_frequent"])
    assert names["inductor"] >= 1
    assert names["randn"] >= 1
    # copies and masks only in the resets (a fraction of the steps), none per step
    assert all(names.get(op, 0) < 1 for op in ("copy", "where", "logical_not"))
    assert fused["kernels_per_rollout_step"] <= eager["kernels_per_rollout_step"] / 3


@pytest.mark.parametrize("env", ["jax", "numba-cuda"])
def test_a_bad_env_backend_is_refused(bench, tiny, env):
    with pytest.raises(SystemExit) as exc:
        bench.main(["--config", str(tiny), "--env", env])
    assert exc.value.code == 2


def test_a_sync_free_env_and_its_refusal(bench, tiny, capsys):
    """``--env numba --sync-free``: the env's autoreset without host syncs (a reset attempt
    every step): recorded in the line, fused still several times fewer kernels and no
    host read (``item``) among them; ``--sync-free`` without ``--env`` is refused."""
    assert bench.main(["--config", str(tiny), "--repeats", "1", "--env", "numba",
                       "--sync-free"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["env"] == "numba" and out["sync_free"] is True
    eager, fused = out["eager"], out["fused"]
    assert "item" not in dict(fused["most_frequent"]) and "item" not in dict(
        eager["most_frequent"])
    assert fused["kernels_per_rollout_step"] <= eager["kernels_per_rollout_step"] / 3
    with pytest.raises(SystemExit) as exc:
        bench.main(["--config", str(tiny), "--sync-free"])
    assert exc.value.code == 2
