"""``train.py gpu --max-seconds``: the wall-time budget of agents/accel/trainer.py, and the
linear learning-rate schedule that falls to 0 at it, counted from the end of the first
update (which holds the start-up's compiles and captures)."""

from __future__ import annotations

import math
import types

import pytest

pytest.importorskip("torch")

import torch  # noqa: E402

from tether_gym_agents.accel import trainer  # noqa: E402
from tether_gym_agents.accel.ppo import PPOSettings  # noqa: E402
from tether_gym_agents.accel.trainer import GpuRun, progress_remaining, train_seeds  # noqa: E402


def test_without_a_time_budget_the_schedule_is_sb3s():
    for fraction in (0.0, 0.25, 0.999):
        for startup in (math.nan, 3.0):
            assert progress_remaining(fraction, 1e6, math.inf, startup) == 1.0 - fraction


def test_the_time_budget_counts_from_the_end_of_the_first_update():
    # before the first update ends, nothing of the time budget is spent
    assert progress_remaining(0.0, 30.0, 45.0, math.nan) == 1.0
    # the first update took 15 s of a 45 s budget: the schedule spans the other 30 s
    assert progress_remaining(0.0, 15.0, 45.0, 15.0) == 1.0
    assert progress_remaining(0.0, 30.0, 45.0, 15.0) == pytest.approx(0.5)
    assert progress_remaining(0.0, 45.0, 45.0, 15.0) == 0.0
    assert progress_remaining(0.0, 50.0, 45.0, 15.0) == 0.0  # clamped
    # the step budget still ends the schedule if it comes first
    assert progress_remaining(0.75, 30.0, 45.0, 15.0) == pytest.approx(0.25)
    # a start-up past the whole budget leaves nothing
    assert progress_remaining(0.0, 50.0, 45.0, 50.0) == 0.0


def test_a_run_with_a_slow_first_update_keeps_its_schedule(tmp_path, monkeypatch):
    """A clock that the first update moves by 10 s (a compile) and each later one by 1 s,
    with a 15 s budget: the schedule spans the 5 s after the first update (the rate at
    1, 1, 0.8, ..., 0.2, then 0), the run stops after the update that ends past 15 s,
    and records the steps and wall time it reached."""
    clock = {"t": 100.0}
    monkeypatch.setattr(trainer, "time", types.SimpleNamespace(perf_counter=lambda: clock["t"]))
    real_update, seen = trainer._update, []

    def timed_update(*args, **kwargs):
        real_update(*args, **kwargs)
        clock["t"] += 10.0 if not seen else 1.0
        seen.append(clock["t"])

    progress: list[float] = []
    real_rate = trainer.learning_rate_at

    def recorded_rate(settings, remaining):
        progress.append(remaining)
        return real_rate(settings, remaining)

    monkeypatch.setattr(trainer, "_update", timed_update)
    monkeypatch.setattr(trainer, "learning_rate_at", recorded_rate)
    settings = PPOSettings(n_envs=2, n_steps=4, batch_size=8, n_epochs=1, net_arch=(8, 8))
    run = GpuRun([0], 10**6, {"increment_gain": 0.5}, tmp_path, torch.device("cpu"),
                 checkpoints=1, eval_episodes=1, clock_start=100.0, max_seconds=15.0)
    summary = train_seeds(settings, run, log=None)
    step_fraction = [k * 8 / (math.ceil(10**6 / 8) * 8) for k in range(7)]
    time_fraction = [0.0, 0.0, 0.2, 0.4, 0.6, 0.8, 1.0]
    assert progress == pytest.approx([1.0 - max(f, t) for f, t in
                                      zip(step_fraction, time_fraction, strict=True)])
    assert len(seen) == 7  # the 7th update ends at 16 s, past the budget
    assert summary["history"][-1]["steps"] == 7 * 8
    assert summary["history"][-1]["wall_time_s"] == 16.0
