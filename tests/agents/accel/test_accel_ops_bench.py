"""bench/accel_ops.py: its count of torch operations per PPO iteration is sound."""

import pytest


@pytest.fixture(scope="module")
def accel_ops(load_bench):
    return load_bench("accel_ops")


@pytest.fixture(scope="module")
def counts(accel_ops, tiny):
    """(backend, iterations[, graphs[, sync_free]]) -> the script's figures for the tiny
    config."""
    return {key: accel_ops.count(tiny, *key) for key in
            (("numba", 1), ("numba", 2), ("torch", 1), ("numba", 4, True),
             ("torch", 4, True), ("numba", 1, False, True), ("numba", 4, True, True),
             ("torch", 4, True, True))}


def test_counts_are_per_iteration_and_add_up(counts):
    """Two budgets give the same counts per iteration (no episode ends in 32 steps from
    the training start), the minibatch steps are epochs x ceil(samples / batch), and
    an iteration is its rollout steps plus its minibatch steps."""
    one, two = counts["numba", 1], counts["numba", 2]
    for key in ("ops_per_rollout_step", "of_which_env_step", "ops_per_minibatch_step",
                "of_which_adam", "ops_per_iteration"):
        assert one[key] == two[key], key
    assert one["minibatches_per_iteration"] == 3 * -(-8 * 16 // 48) == 9
    total = (16 * one["ops_per_rollout_step"]
             + 9 * one["ops_per_minibatch_step"])
    assert abs(one["ops_per_iteration"] - total) <= 1
    # the CPU's Adam steps each of the 13 parameter tensors in turn: several operations
    # each (9 in a fresh process; what torch has loaded before can add a couple)
    assert 13 <= one["of_which_adam"] < one["ops_per_minibatch_step"]
    # the minibatch step reads nothing back to the host (what a CUDA graph needs,
    # agents/accel/graphs.py); a rollout step does, in the env's autoreset
    assert one["host_syncs_per_minibatch_step"] == 0
    assert one["host_syncs_per_rollout_step"] > 0


def test_the_numba_backends_step_is_a_few_torch_operations(counts):
    """The torch port's step is a thousand-odd operations; the numba backend's, the
    copies around one numba call."""
    torch_port, numba = counts["torch", 1], counts["numba", 1]
    assert torch_port["of_which_env_step"] > 1000
    assert numba["of_which_env_step"] < torch_port["of_which_env_step"] / 10
    assert numba["ops_per_minibatch_step"] == torch_port["ops_per_minibatch_step"]


def test_with_cuda_graphs_the_host_launches_replays_a_kernel_and_a_sync(counts):
    """``--cuda-graphs`` (RecordingCapture on the CPU): an update is its minibatch orders'
    draws (a rand and a sort per epoch, and their stack), their copy and one replay of
    all its minibatch steps; a rollout
    step is three replays (two with the torch backend; the advantages' replay shared
    out over the rollout's 16 steps) around the env's eager parts: the numba kernel
    and the autoreset's one read of whether any sub-env ended (its reduction is in a
    graph) while no episode ends, a few more in a step where one does."""
    eager, graphed = counts["numba", 1], counts["numba", 4, True]
    torch_graphed = counts["torch", 4, True]
    assert graphed["minibatches_per_iteration"] == eager["minibatches_per_iteration"]
    assert graphed["of_which_adam"] == 0
    update = graphed["ops_per_minibatch_step"] * graphed["minibatches_per_iteration"]
    assert round(update) == 2 * 3 + 1 + 2  # 3 epochs
    # (the figures are rounded to 0.1)
    assert abs(graphed["ops_per_rollout_step"] - graphed["of_which_env_step"] - 3.0625) < 0.1
    assert abs(torch_graphed["ops_per_rollout_step"] - torch_graphed["of_which_env_step"]
               - 2.0625) < 0.1
    assert 2 <= graphed["of_which_env_step"] < 3 and 1 <= torch_graphed["of_which_env_step"] < 2
    assert 1 <= graphed["host_syncs_per_rollout_step"] < 1.5
    assert graphed["ops_per_iteration"] < eager["ops_per_iteration"] / 20


def test_sync_free_rollout_steps_read_nothing_back(counts):
    """``--sync-free``: no host sync in a rollout step, eager or graphed. Graphed, the
    env's eager part of a step is then the numba kernel and a reset attempt in every
    step (its two replays around its kernel), the rollout's own part as without the
    flag; on the torch backend the whole rollout of 16 steps and its advantages are one
    replay (1/16 of a launch per step). Eager, the attempt in every step costs more
    operations than the default's attempts in the steps where an episode ended."""
    eager = counts["numba", 1, False, True]
    graphed, torch_graphed = counts["numba", 4, True, True], counts["torch", 4, True, True]
    for c in (eager, graphed, torch_graphed):
        assert c["sync_free"] and c["host_syncs_per_rollout_step"] == 0
    assert counts["numba", 1]["host_syncs_per_rollout_step"] > 0
    assert graphed["of_which_env_step"] == 4.0 and torch_graphed["of_which_env_step"] == 0.0
    assert abs(graphed["ops_per_rollout_step"] - 4.0 - 3.0625) < 0.1
    # per iteration: the rollout's replay and the learning rate's fill, then the update's
    # orders (3 epochs: 3 draws, 3 sorts, their stack and copy) and its replay
    assert torch_graphed["n_steps"] == 16 and torch_graphed["ops_per_rollout_step"] == 0.1
    assert torch_graphed["ops_per_iteration"] == 11
    assert ["rollout:graph_replay", 1] in torch_graphed["per_iteration_most_frequent"]
    assert eager["of_which_env_step"] > counts["numba", 1]["of_which_env_step"]
    assert eager["ops_per_minibatch_step"] == counts["numba", 1]["ops_per_minibatch_step"]
