"""ThreadPolicy: serial or threaded steps, chosen from (here: fake) timings."""

from __future__ import annotations

import pytest

from tether_gym.envs.threads import ThreadPolicy, chunks_for

ROWS = 256


def no_pool():
    raise AssertionError("the thread count was asked for below the threshold")


def run(policy: ThreadPolicy, cost, steps: int, start: int = 0) -> dict:
    """Drive ``policy`` for ``steps`` steps; ``cost(step, threaded)`` is the time per row.

    Returns the modes used and the total (fake) time.
    """
    modes, total = [], 0.0
    for k in range(start, start + steps):
        threaded = policy.chunks(ROWS) > 0
        seconds = cost(k, threaded) * ROWS
        policy.record(ROWS, seconds)
        modes.append(threaded)
        total += seconds
    return {"modes": modes, "time": total}


def fixed(serial: float, threaded: float):
    return lambda k, t: threaded if t else serial


def test_chunks_for_is_one_per_thread_and_at_most_one_per_row():
    assert chunks_for(2, 256) == 2
    assert chunks_for(8, 5) == 5


def test_forced_and_small_batches_do_not_measure():
    serial = ThreadPolicy(False, 128, num_threads=no_pool)
    assert [serial.chunks(ROWS) for _ in range(5)] == [0] * 5
    small = ThreadPolicy("auto", 128, num_threads=no_pool)
    assert small.chunks(127) == 0 and small.chunks(1) == 0
    small.record(127, 1.0)
    assert small.summary()["serial_steps"] == 0  # not a measured step
    forced = ThreadPolicy(True, 128, num_threads=lambda: 2)
    out = run(forced, fixed(1.0, 100.0), 50)  # threads forced even when far slower
    assert all(out["modes"])
    assert forced.chunks(1) == 0  # nothing to split
    one = ThreadPolicy("auto", 128, num_threads=lambda: 1)
    assert not any(run(one, fixed(1.0, 0.1), 50)["modes"])


def test_first_step_of_each_mode_is_not_timed():
    """A compile or pool start on the first threaded step must not decide anything."""
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2, probe_steps=3)
    # 1000x slower on the first threaded and first serial step only, then threads win
    seen = {True: 0, False: 0}

    def cost(k, threaded):
        seen[threaded] += 1
        return (1000.0 if seen[threaded] == 1 else 1.0) * (0.5 if threaded else 1.0)

    out = run(policy, cost, 8)
    assert out["modes"] == [True, False, False, False, False, True, True, True]
    assert policy.summary()["choice"] == "threads"
    assert policy.summary()["threaded/serial time"] == 0.5


@pytest.mark.parametrize("ratio", [0.5, 0.8])
def test_threads_that_pay_are_used_almost_always(ratio):
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2)
    out = run(policy, fixed(1.0, ratio), 20000)
    serial_share = 1 - sum(out["modes"]) / len(out["modes"])
    assert serial_share < 0.01
    assert out["time"] < 1.01 * ratio * ROWS * 20000


@pytest.mark.parametrize("ratio", [0.95, 1.5, 18.0, 150.0])
def test_threads_that_do_not_pay_cost_little(ratio):
    """Threads 5 % faster (inside the margin), 1.5x, 18x or 150x slower (measured under
    load): serial wins; the probes cost a few percent of the all-serial time."""
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2)
    steps = 20000
    out = run(policy, fixed(1.0, ratio), steps)
    serial_time = 1.0 * ROWS * steps
    assert policy.summary()["choice"] == "serial"
    assert out["time"] < 1.05 * serial_time


def test_probe_intervals_double_while_the_choice_holds():
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2, probe_steps=1,
                          first_interval=4, max_interval=32, budget=1.0)
    modes = run(policy, fixed(1.0, 0.5), 106)["modes"]
    # untimed T (0), S (1); then probes (S, T) followed by 4, 8, 16, 32, 32 threaded steps
    serial_at = [i for i, threaded in enumerate(modes) if not threaded]
    assert serial_at == [1, 2, 8, 18, 36, 70, 104]


def test_a_second_job_is_noticed_within_a_few_steps():
    """Threads win on an idle machine; from step 3000 a threaded step is 15x slower (a
    second process): the alarm ends the long interval, the next probe picks serial."""
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2, alarm_steps=3, probe_steps=3)

    def cost(k, threaded):
        if k < 3000:
            return 0.6 if threaded else 1.0
        return 9.0 if threaded else 2.0  # loaded: serial on a shared core, threads stall

    out = run(policy, cost, 6000)
    after = out["modes"][3000:]
    assert after[:3] == [True] * 3  # the three strikes
    # the probe: 3 serial steps, then one threaded step 4.5x slower ends it
    assert after[3:8] == [False] * 3 + [True] + [False]
    # later probes: that step cost 3.5 serial steps too many; with a 2 % budget the
    # next probe comes 175 steps later, then the interval doubles
    assert [i for i, t in enumerate(after) if t] == [0, 1, 2, 6, 185, 539, 1243, 2647]
    loaded_serial_time = 2.0 * ROWS * 3000
    time_after = sum((9.0 if t else 2.0) * ROWS for t in after)
    assert time_after < 1.02 * loaded_serial_time
    assert policy.summary()["choice"] == "serial"


def test_an_idle_machine_brings_the_threads_back():
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2, max_interval=256)

    def cost(k, threaded):
        if k < 2000:
            return 9.0 if threaded else 2.0
        return 0.6 if threaded else 1.0

    out = run(policy, cost, 4000)
    assert policy.summary()["choice"] == "threads"
    first_threads_run = next(i for i in range(2000, 4000)
                             if all(out["modes"][i:i + 20]))
    assert first_threads_run < 2000 + 256 + 2 * 3 + 1


def test_a_step_without_record_restarts_the_probe():
    policy = ThreadPolicy("auto", 128, num_threads=lambda: 2, probe_steps=1)
    run(policy, fixed(1.0, 0.5), 2)  # the untimed steps
    policy.chunks(ROWS)  # the probe's serial step, never recorded
    policy.chunks(ROWS)  # the probe's threaded step
    policy.record(ROWS, 0.5 * ROWS)
    out = run(policy, fixed(1.0, 0.5), 40)
    assert policy.summary()["choice"] == "threads"
    assert sum(out["modes"]) >= 35


@pytest.mark.parametrize("kwargs, match", [
    ({"min_rows": 0}, "min_rows"), ({"probe_steps": 0}, "probe_steps"),
    ({"first_interval": 8, "max_interval": 4}, "max_interval"), ({"margin": 1.5}, "margin"),
    ({"alarm": 1.0}, "alarm"), ({"alarm_steps": 0}, "alarm_steps"), ({"budget": 0}, "budget"),
])
def test_bad_settings_are_rejected(kwargs, match):
    args = {"min_rows": 128, **kwargs}
    with pytest.raises(ValueError, match=match):
        ThreadPolicy("auto", **args)
    with pytest.raises(TypeError, match="parallel"):
        ThreadPolicy("yes", 128)
