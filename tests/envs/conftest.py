"""Shared fixtures and helpers of the environment tests."""

from __future__ import annotations

import re
import warnings
from contextlib import contextmanager

import gymnasium as gym
import numpy as np
import pytest

import tether_gym

ENV_ID = tether_gym.ENV_ID

# Reward bounds documented in TetherLibrationEnv's docstring ("Rewards"): r in [0, 1]
# for any valid RewardWeights (effort + accel + slack <= 1).
REWARD_LOW, REWARD_HIGH = 0.0, 1.0

INFO_KEYS = (
    "nu", "theta", "dtheta", "length", "dlength", "tension", "theta_ref", "dtheta_ref",
    "failure", "reward_tracking", "reward_effort", "reward_accel", "reward_slack",
    "reward_length",
)
REWARD_COMPONENTS = ("reward_tracking", "reward_effort", "reward_accel", "reward_slack",
                     "reward_length")

# Warnings that check_env may raise and that we accept; keep this list short.
ALLOWED_WARNINGS = (
    # theta' and l' have no physical bound (and obs_noise is Gaussian), so the Box is
    # truthfully infinite in those entries; gymnasium's checker flags any inf bound.
    (UserWarning, r"A Box observation space (minimum|maximum) value is -?infinity"),
    # check_env builds a render_mode='human' env; the test machines have no display
    # (and the `headless` fixture forces that case), so the renderer says frames are
    # not shown.
    (UserWarning, r"render_mode='human' but matplotlib has no interactive backend"),
)


def unexpected(caught, allowed=ALLOWED_WARNINGS):
    """The caught warnings that match no (category, regex) of ``allowed``."""
    return [w for w in caught
            if not any(issubclass(w.category, cat) and re.search(rx, str(w.message))
                       for cat, rx in allowed)]


@contextmanager
def no_unexpected_warnings(allowed=ALLOWED_WARNINGS):
    """Record every warning in the block; fail on any not on the allow-list."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught
    bad = unexpected(caught, allowed)
    assert not bad, "unexpected warnings:\n" + "\n".join(
        f"{w.category.__name__} ({w.filename}:{w.lineno}): {w.message}" for w in bad)


@pytest.fixture(autouse=True)
def headless(monkeypatch):
    """Never open a window: the 'human' renderer behaves as without a display."""
    from tether_gym.envs import rendering

    monkeypatch.setattr(rendering, "_has_display", lambda: False)


@pytest.fixture
def make_env():
    """Factory ``make_env(**kwargs)`` for gym.make'd envs, closed after the test."""
    envs = []

    def _make(**kwargs):
        env = gym.make(ENV_ID, **kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()


def assert_info_equal(a: dict, b: dict) -> None:
    """Bitwise equality of two info dicts (same keys, same values)."""
    assert a.keys() == b.keys()
    for key in a:
        va, vb = a[key], b[key]
        if isinstance(va, np.ndarray):
            assert va.dtype == vb.dtype and va.tobytes() == vb.tobytes(), key
        else:
            assert va == vb or (va != va and vb != vb), (key, va, vb)
