"""bench/gpu_throughput.py --graphed: the env's sync-free steps replayed as one graph."""

import json

import pytest

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def bench(load_bench):
    return load_bench("gpu_throughput")


def test_the_graph_replays_the_steps_it_times(bench):
    """Three replays of a 4-step graph (``RecordingCapture`` on the CPU; the warm-up
    calls and the capture first) leave the env where 28 eager steps of the same parts
    leave an env of the same seed: state, observation, step counts and generator,
    bitwise. With 6-step episodes (in ``ENV_KWARGS`` of the bench, episodes are long),
    rows end and are reset inside the replays."""
    from tether_gym_agents.accel.graphs import WARMUP_STEPS

    short = {**bench.ENV_KWARGS, "orbits_per_episode": 0.02}
    real = bench.ENV_KWARGS
    bench.ENV_KWARGS = short
    try:
        env, graph = bench.graphed_env(6, "cpu", "torch", per_graph=4)
        calls = WARMUP_STEPS + 1 + 3
        for _ in range(calls):
            graph()
        eager, _ = bench.graphed_env(6, "cpu", "torch", per_graph=1)
    finally:
        bench.ENV_KWARGS = real
    ended = 0
    for _ in range(4 * calls):
        eager.step_in_place()
        ended += int(eager.outputs.ended.sum())
    assert graph.captured and ended >= 6
    for name in ("y", "nu", "u", "obs", "steps", "par", "noise"):
        assert torch.equal(getattr(env, name), getattr(eager, name)), name
    assert torch.equal(env.generator.get_state(), eager.generator.get_state())


def test_main_times_the_graphed_steps_where_one_graph_holds_them(bench, capsys):
    """``--graphed 2`` prints a graphed row for the torch backend (2 steps per graph)
    and says the CPU's numba backend has none; ``--graphed -1`` is refused."""
    assert bench.main(["--device", "cpu", "--envs", "8", "--steps", "4", "--backend",
                       "torch", "numba", "--graphed", "2"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    graphed = [r for r in rows if "per CUDA graph" in r.get("what", "")]
    assert len(graphed) == 1 and graphed[0]["graph_steps"] == 2
    assert graphed[0]["env_steps_per_s"] > 0 and graphed[0]["envs"] == 8
    assert any("backend=numba: no whole-step graph" in r.get("what", "") for r in rows)
    with pytest.raises(SystemExit):
        bench.main(["--graphed", "-1"])
    assert "--graphed must be >= 1" in capsys.readouterr().err
