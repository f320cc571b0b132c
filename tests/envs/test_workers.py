"""Tests of the polling worker threads of the threaded step (tether_gym.envs.workers).

The vector-env tests show that threaded steps give the serial results bit for bit;
these pin the hand-over itself: a posted chunk is stepped exactly once, a serving step
gives up after its polls instead of spinning for ever, a worker that fails reports the
error to the caller, and ``stop`` ends the thread.
"""

from __future__ import annotations

import numpy as np
import pytest

from tether_gym.envs import EnvConfig
from tether_gym.envs.batch import CAN_THREAD, GIVE_UP, ChainBatch
from tether_gym.envs.step_kernel import new_row_work, step_rows
from tether_gym.envs.workers import DONE, GEN, HI, LO, SLOTS, STOP, Relay, SpinWorker, wait_done

pytestmark = pytest.mark.skipif(not CAN_THREAD, reason="no sched_yield on this platform")

NUM = 6


def started_batch() -> ChainBatch:
    batch = ChainBatch(EnvConfig.from_kwargs(), NUM)
    batch.reset_rows(np.arange(NUM), [np.random.default_rng(b) for b in range(NUM)])
    return batch


def buffers(action: np.ndarray):
    """The row-index and action buffers a worker reads its chunks from."""
    return np.arange(NUM, dtype=np.int64), np.ascontiguousarray(action, dtype=np.float64)


def test_a_serving_step_steps_a_posted_chunk_once_and_returns_when_idle():
    batch = started_batch()
    reference = started_batch()
    action = np.linspace(-1.0, 1.0, NUM * 2).reshape(NUM, 2)
    index, act = buffers(action)
    ctl = np.zeros(SLOTS, dtype=np.int64)
    ctl[LO], ctl[HI], ctl[GEN] = 2, 5, 1  # job 1: rows 2, 3, 4
    serving = Relay(ctl, GIVE_UP, 50)
    work = new_row_work(batch.n)
    assert step_rows(index, act, batch.rows, batch.cfg, work, False, serving) == -1
    assert ctl[DONE] == 1
    reference.step(act, None, np.array([2, 3, 4], dtype=np.int64))
    for name, value in batch.rows._asdict().items():
        assert np.array_equal(value, reference.rows._asdict()[name]), name
    # nothing posted: it polls 50 times and returns, stepping nothing
    before = batch.rows.y.copy()
    step_rows(index, act, batch.rows, batch.cfg, work, False, serving)
    assert ctl[DONE] == 1 and np.array_equal(batch.rows.y, before)
    assert wait_done(ctl, 1, GIVE_UP) == 0  # done already: no poll
    # a stop posted as a job: it returns at once, stepping nothing
    ctl[STOP], ctl[GEN] = 1, 2
    step_rows(index, act, batch.rows, batch.cfg, work, False, serving)
    assert ctl[DONE] == 1 and np.array_equal(batch.rows.y, before)


def test_a_worker_steps_chunks_and_stops():
    batch = started_batch()
    reference = started_batch()
    action = np.full((NUM, 2), 0.3)
    index, act = buffers(action)
    worker = SpinWorker(step_rows, (index, act, batch.rows, batch.cfg,
                                    new_row_work(batch.n), False), GIVE_UP)
    for _ in range(3):
        worker.wait(worker.start(0, NUM))
        reference.step(act, None)
    assert worker.ctl[DONE] == 3
    assert np.array_equal(batch.rows.y, reference.rows.y)
    worker.stop()
    assert not worker._thread.is_alive()


def test_a_failing_worker_reports_its_error_to_the_caller():
    batch = started_batch()
    index, act = buffers(np.zeros((NUM, 2)))
    # rows=None cannot be typed: the worker's call of the step raises
    worker = SpinWorker(step_rows, (index, act, None, batch.cfg, new_row_work(batch.n),
                                    False), GIVE_UP)
    with pytest.raises(RuntimeError, match="worker thread") as err:
        worker.wait(worker.start(0, NUM))
    assert err.value.__cause__ is not None
    worker.stop()


def _step_in_child(env, action, out):
    obs, *_ = env.step(action)
    out.put(obs)


def test_a_forked_child_steps_on_threads_of_its_own():
    """A child forked after threaded steps has the workers' objects but not their
    threads: it starts its own instead of waiting for ever."""
    import multiprocessing

    from tether_gym.envs.vector import TetherLibrationVectorEnv

    try:
        ctx = multiprocessing.get_context("fork")
    except ValueError:
        pytest.skip("no fork on this platform")
    env = TetherLibrationVectorEnv(8, parallel=True)
    twin = TetherLibrationVectorEnv(8, parallel=False)
    env.reset(seed=1)
    twin.reset(seed=1)
    action = np.full((8, 2), 0.2)
    env.step(action)
    twin.step(action)
    queue = ctx.Queue()
    child = ctx.Process(target=_step_in_child, args=(env, action, queue))
    child.start()
    child.join(timeout=60)
    if child.is_alive():
        child.terminate()
    assert child.exitcode == 0
    expected, *_ = twin.step(action)
    assert np.array_equal(queue.get(timeout=5), expected)
