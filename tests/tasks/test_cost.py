"""The constraint cost (tether_gym.tasks.cost) against its definition, through gym.make.

Each step's cost parts are recomputed here from the same step's ``info`` (the true
state and the smallest tensions of the step) and the thresholds, and compared with
what the env reports; episodes are driven into each failure so that every part fires.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.tasks.cost import COST_LIMIT, COST_NAMES, CostThresholds


def expected_parts(info, thresholds: CostThresholds, bounds) -> tuple[float, float, float]:
    """The docstring's indicators, from one step's info."""
    lo, hi = bounds
    f = thresholds.length_factor
    slack = float(np.min(info["tension_min"]) < thresholds.tension)
    length = float(np.any(info["length"] < f * lo) or np.any(info["length"] > hi / f))
    tumble = float(np.any(np.abs(info["theta"]) >= thresholds.tumble_fraction * math.pi / 2))
    return slack, length, tumble


def run(actions, seed=0, thresholds=None, **kwargs):
    """Steps of one episode: list of info dicts, and the reset info."""
    extra = {} if thresholds is None else {"cost_thresholds": thresholds}
    env = gym.make(tether_gym.ENV_ID, **kwargs, **extra)
    _, reset_info = env.reset(seed=seed)
    infos = []
    for action in actions:
        _, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        if terminated or truncated:
            break
    env.close()
    return reset_info, infos


@pytest.mark.parametrize("case", ["reel out", "swing", "random"])
def test_every_step_costs_what_its_definition_says(case):
    rng = np.random.default_rng(3)
    if case == "reel out":     # reel tether 1 out to the length bound
        actions, kwargs = [np.array([1.0, -1.0])] * 800, {"action_mode": "rate"}
    elif case == "swing":      # no control from a large libration: it tumbles or goes slack
        actions, kwargs = [np.zeros(2)] * 800, {"initial_theta": (1.2, -1.2)}
    else:                      # i.i.d. bang-bang commands: slack
        actions = [rng.choice([-1.0, 1.0], 2) for _ in range(800)]
        kwargs = {"action_mode": "rate"}
    thresholds = CostThresholds()
    reset_info, infos = run(actions, **kwargs)
    assert [reset_info[k] for k in COST_NAMES] == [0.0, 0.0, 0.0, 0.0]
    fired = np.zeros(3)
    for info in infos:
        parts = expected_parts(info, thresholds, (0.05, 1.5))
        assert (info["cost_slack"], info["cost_length"], info["cost_tumble"]) == parts
        assert info["cost"] == sum(parts)
        fired += parts
    assert infos[-1]["failure"] is not None
    assert infos[-1]["cost"] >= 1.0  # the failing step crossed a watched bound
    if case == "reel out":
        assert infos[-1]["failure"] == "length" and fired[1] > 0
    if case == "swing":
        assert fired[2] > 0
    if case == "random":
        assert fired[0] > 0


def test_thresholds_move_where_the_cost_starts():
    """A lower T_c costs fewer steps of the same trajectory; the parts follow their thresholds."""
    actions = [np.array([0.6, -0.6])] * 300
    counts = []
    for tension in (0.5, 1.0, 1.5):
        thresholds = {"tension": tension, "length_factor": 1.0, "tumble_fraction": 1.0}
        _, infos = run(actions, thresholds=thresholds, action_mode="rate")
        for info in infos:
            assert info["cost_slack"] == float(np.min(info["tension_min"]) < tension)
        counts.append(sum(info["cost_slack"] for info in infos))
    assert counts[0] <= counts[1] <= counts[2]
    assert counts[2] > counts[0]


def test_a_well_controlled_episode_costs_nothing():
    """The paper's case under its sliding-mode law stays far from every bound."""
    from tether_gym_agents import SlidingModeController

    env = gym.make(tether_gym.ENV_ID, action_mode="rate")
    smc = SlidingModeController.for_env(env)
    obs, _ = env.reset(seed=0)
    total = 0.0
    steps = 0
    done = False
    while not done:
        action, _ = smc.predict(obs)
        obs, _, terminated, truncated, info = env.step(action)
        total += info["cost"]
        steps += 1
        done = terminated or truncated
    assert info["failure"] is None and steps == 754
    assert total / steps <= COST_LIMIT
    assert np.min(info["tension_min"]) > 0.5


def test_bad_thresholds_are_refused_naming_the_value():
    with pytest.raises(ValueError, match=r"cost_thresholds\['tension'\]=-1"):
        gym.make(tether_gym.ENV_ID, cost_thresholds={"tension": -1})
    with pytest.raises(ValueError, match="unknown cost_thresholds keys"):
        gym.make(tether_gym.ENV_ID, cost_thresholds={"slack": 1})
    with pytest.raises(TypeError, match="must be a dict"):
        gym.make(tether_gym.ENV_ID, cost_thresholds=0.5)
